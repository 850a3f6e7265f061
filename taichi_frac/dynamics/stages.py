"""The two stage kernels of a substep: ``collide`` (broadphase and narrowphase) and
``respond`` (gravity, contact impulses, impact records, integration). Each runs its
passes (``ti.func`` loops over one index set each, defined in collision/ and dynamics/) as
successive tasks of ONE kernel: on the CPU backend a kernel launch costs ~17 us and a
parallel-for task 25-60 us, which is the whole budget of a pass over a few thousand
particles, so a substep is two launches and one parallel task (the narrowphase, whose
contacts ``order_contacts`` then sorts so that runs are reproducible); the other passes
run serially on the CPU (``runtime.SERIAL_SMALL_LOOPS``). Scalars are arguments; vectors
live in fields (a vector argument costs ~50 us per launch); each data-oriented container
argument costs ~8 us of Python per launch, so the kernels take ``WorldFields``.
"""

import taichi as ti

from ..collision import grid, narrowphase
from . import impacts, integrate, solver


@ti.data_oriented
class WorldFields:
    """The World's containers, passed to a stage kernel as ONE template argument: each
    data-oriented argument costs ~8 us of Python per launch (Taichi 1.7.4 checks it with
    isinstance, which goes through the class's attribute hook), and a substep launches two
    kernels."""

    def __init__(self, bodies, statics, particles, grid, contacts, impacts):
        self.bodies = bodies
        self.statics = statics
        self.particles = particles
        self.grid = grid
        self.contacts = contacts
        self.impacts = impacts


@ti.kernel
def collide(f: ti.template(), margin: ti.f32, dt: ti.f32, sleep_time: ti.f32):
    grid.body_cull(f.bodies, f.statics, f.grid, margin, dt)
    grid.particle_cells(f.bodies, f.particles, f.grid, margin)
    grid.bucket_scan(f.grid)
    grid.bucket_scatter(f.particles, f.grid)
    narrowphase.clear_contacts(f.contacts)
    narrowphase.particle_contacts(f.bodies, f.particles, f.grid, f.statics, f.contacts, margin, sleep_time, dt)
    narrowphase.order_contacts(f.particles, f.contacts)


@ti.kernel
def respond(f: ti.template(),
            dt: ti.f32, iterations: ti.i32, restitution_iterations: ti.i32, position_correction: ti.f32,
            allowed_penetration: ti.f32, max_correction_speed: ti.f32, restitution_threshold: ti.f32,
            substep: ti.i32, force_threshold: ti.f32, impact_speed: ti.f32, max_rotation: ti.f32,
            sleep_linear_speed: ti.f32,
            sleep_angular_speed: ti.f32, sleep_time: ti.f32, warm_start: ti.f32, rolling_resistance: ti.f32):
    integrate.integrate_velocities(f.bodies, f.statics, dt)
    solver.prepare_contacts(f.bodies, f.contacts, warm_start)
    solver.solve_contacts(f.bodies, f.contacts, iterations, restitution_iterations, dt, position_correction,
                          allowed_penetration, max_correction_speed, restitution_threshold, rolling_resistance)
    solver.store_impulses(f.particles, f.contacts)
    impacts.record_impacts(f.bodies, f.contacts, f.impacts, dt, substep, force_threshold, impact_speed)
    integrate.integrate_positions(f.bodies, f.statics, dt, max_rotation, sleep_linear_speed, sleep_angular_speed,
                                  sleep_time, max_correction_speed)
    integrate.hold_above_ground(f.bodies, f.particles, f.statics, dt)
