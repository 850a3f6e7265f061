"""The two stage kernels of a substep: ``collide`` (broadphase and narrowphase) and
``respond`` (gravity, contact impulses, impact records, integration). Each runs its
passes (``ti.func`` loops over one index set each, defined in collision/ and dynamics/) as
successive tasks of ONE kernel: on the CPU backend a kernel launch costs ~17 us and a
parallel-for task 25-60 us, which is the whole budget of a pass over a few thousand
particles, so a substep is two launches and one parallel task (the narrowphase); the other
passes run serially on the CPU (``runtime.SERIAL_SMALL_LOOPS``). Scalars are arguments;
vectors live in fields (a vector argument costs ~50 us per launch).
"""

import taichi as ti

from ..collision import grid, narrowphase
from . import impacts, integrate, solver


@ti.kernel
def collide(bodies: ti.template(), statics: ti.template(), particles: ti.template(),
            hash_grid: ti.template(), contacts: ti.template(), margin: ti.f32, dt: ti.f32, sleep_time: ti.f32):
    grid.body_cull(bodies, statics, hash_grid, margin, dt)
    grid.particle_cells(bodies, particles, hash_grid, margin)
    grid.bucket_scan(hash_grid)
    grid.bucket_scatter(particles, hash_grid)
    narrowphase.clear_contacts(contacts)
    narrowphase.particle_contacts(bodies, particles, hash_grid, statics, contacts, margin, sleep_time, dt)


@ti.kernel
def respond(bodies: ti.template(), statics: ti.template(), particles: ti.template(), contacts: ti.template(),
            impact_buffer: ti.template(),
            dt: ti.f32, iterations: ti.i32, restitution_iterations: ti.i32, position_correction: ti.f32,
            allowed_penetration: ti.f32, max_correction_speed: ti.f32, restitution_threshold: ti.f32,
            substep: ti.i32, force_threshold: ti.f32, impact_speed: ti.f32, max_rotation: ti.f32,
            sleep_linear_speed: ti.f32,
            sleep_angular_speed: ti.f32, sleep_time: ti.f32, warm_start: ti.f32):
    integrate.integrate_velocities(bodies, statics, dt)
    solver.prepare_contacts(bodies, contacts, warm_start)
    solver.solve_contacts(bodies, contacts, iterations, restitution_iterations, dt, position_correction,
                          allowed_penetration, max_correction_speed, restitution_threshold)
    solver.store_impulses(particles, contacts)
    impacts.record_impacts(bodies, contacts, impact_buffer, dt, substep, force_threshold, impact_speed)
    integrate.integrate_positions(bodies, statics, dt, max_rotation, sleep_linear_speed, sleep_angular_speed,
                                  sleep_time)
