"""The two stage kernels of a substep: ``collide`` (broadphase and narrowphase) and
``respond`` (gravity, contact impulses, impact records, integration, sleeping). Each runs its
passes (``ti.func`` loops over one index set each, defined in collision/ and dynamics/) as
successive tasks of ONE kernel: on the CPU backend a kernel launch costs ~17 us (and
~2.3 us per scalar argument: ``respond`` reads the solver options from ``StepParams``
fields) and a parallel-for task 25-60 us, which is the whole budget of a pass over a few
thousand particles, so a substep is two launches and one parallel task (the narrowphase, whose
contacts ``order_contacts`` then sorts so that runs are reproducible); the other passes
run serially on the CPU (``runtime.SERIAL_SMALL_LOOPS``). Scalars are arguments; vectors
live in fields (a vector argument costs ~50 us per launch); each data-oriented container
argument costs ~8 us of Python per launch, so the kernels take ``WorldFields``.
"""


from ..runtime import ti
from ..collision import broadphase, narrowphase, reduction
from . import impacts, integrate, solver


@ti.data_oriented
class WorldFields:
    """The World's containers, passed to a stage kernel as ONE template argument: each
    data-oriented argument costs ~8 us of Python per launch (Taichi 1.7.4 checks it with
    isinstance, which goes through the class's attribute hook), and a substep launches two
    kernels."""

    def __init__(self, bodies, statics, particles, grid, contacts, impacts, params):
        self.params = params  # StepParams: the solver options respond reads
        self.bodies = bodies
        self.grid = grid  # broadphase.BodyGrid
        self.statics = statics
        self.particles = particles
        self.contacts = contacts
        self.impacts = impacts


@ti.kernel
def collide(f: ti.template(), margin: ti.f32, dt: ti.f32, sleep_time: ti.f32, patches: ti.template()):
    """``patches`` (bool, one compiled instance each): whether any body has contact
    patches (``narrowphase.particle_contacts``)."""
    broadphase.body_cull(f.bodies, f.statics, f.grid, margin, dt)
    narrowphase.clear_contacts(f.contacts)
    wake_speed = narrowphase.WAKE_SPEED_FACTOR * f.params.sleep_linear_speed[None]
    narrowphase.particle_contacts(f.bodies, f.particles, f.statics, f.contacts, patches, margin, sleep_time,
                                  wake_speed, dt, f.params.restitution_threshold[None])
    narrowphase.order_contacts(f.particles, f.contacts)
    if ti.static(patches):
        reduction.reduce_contacts(f.bodies, f.particles, f.contacts, margin, f.params.restitution_threshold[None])


@ti.kernel
def respond(f: ti.template(), dt: ti.f32, substep: ti.i32, position_correction: ti.f32):
    """``position_correction``: fraction of the penetration removed this substep,
    1 - exp(-position_correction_rate dt) (computed by the caller in f64)."""
    p = f.params
    integrate.integrate_velocities(f.bodies, f.statics, dt)
    solver.prepare_contacts(f.bodies, f.contacts, p.warm_start[None])
    solver.solve_contacts(f.bodies, f.contacts, p.iterations[None], p.restitution_iterations[None], dt,
                          position_correction, p.allowed_penetration[None], p.max_correction_speed[None],
                          p.restitution_threshold[None], p.rolling_resistance[None])
    solver.store_impulses(f.particles, f.contacts)
    impacts.record_impacts(f.bodies, f.contacts, f.impacts, dt, substep, p.force_threshold[None],
                           p.impact_speed[None])
    integrate.integrate_positions(f.bodies, f.statics, dt, p.max_rotation[None], p.sleep_linear_speed[None],
                                  p.sleep_angular_speed[None], p.max_correction_speed[None])
    integrate.sleep_together(f.bodies, f.contacts, p.sleep_time[None])
    integrate.hold_above_ground(f.bodies, f.particles, f.statics, dt)
