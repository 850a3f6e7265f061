"""Checkpoints of the World: a device copy of the bodies' motion state (``BodyMotion``)
and of the contact cache's parity and epoch, for a substep run again after a fracture."""

from dataclasses import dataclass

import numpy as np

from ..runtime import ti
from .. import runtime
from .state import BodyMotion


@dataclass(frozen=True)
class Checkpoint:
    """The motion state of the bodies ``ids`` (K,) at one moment, kept on the device
    (``World.checkpoint``): valid until the World's next checkpoint. ``token`` names it."""

    ids: np.ndarray
    token: int


@ti.data_oriented
class KeptState:
    """The World's state at its latest checkpoint.

    Fields:
        motion: a BodyMotion (max_bodies,), exact copies of the bodies' motion fields.
        active: i32 (max_bodies,) the slots in use then.
        cache: (2,) i32 the contact cache's parity and epoch.
    Writer: ``keep``; read by ``restore`` and ``World.checkpoint_state``.
    """

    def __init__(self, capacity: int):
        self.motion = BodyMotion(capacity)
        self.active = ti.field(ti.i32, shape=capacity)
        self.cache = ti.field(ti.i32, shape=2)


@ti.func
def _copy_motion(source: ti.template(), target: ti.template(), b):
    """Body ``b``'s motion state from one BodyMotion into another."""
    target.position[b] = source.position[b]
    target.orientation[b] = source.orientation[b]
    target.linear_velocity[b] = source.linear_velocity[b]
    target.angular_velocity[b] = source.angular_velocity[b]
    target.sleeping[b] = source.sleeping[b]
    target.sleep_timer[b] = source.sleep_timer[b]
    target.sleep_anchor[b] = source.sleep_anchor[b]
    target.sleep_anchor_orientation[b] = source.sleep_anchor_orientation[b]
    target.wake_request[b] = source.wake_request[b]


@ti.kernel
def keep(f: ti.template(), kept: ti.template()):
    """Every body slot's motion state and the contact cache's parity and epoch into
    ``kept`` (a KeptState). One serial task: a parallel one over ~100 bodies costs more to
    dispatch than the copy, and a copy to the host, with its array arguments, would be paid
    before every substep of a scene that re-runs broken substeps."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for b in range(f.bodies.slot_end[None]):
        _copy_motion(f.bodies.motion_state, kept.motion, b)
        kept.active[b] = f.bodies.active[b]
    kept.cache[0] = f.particles.parity[None]
    kept.cache[1] = f.particles.cache_epoch[None]


@ti.kernel
def restore(f: ti.template(), kept: ti.template(), ids: ti.types.ndarray(dtype=ti.i32, ndim=1)):
    """Bodies ``ids`` back to their motion state in ``kept``, and the contact cache's
    parity and epoch."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for k in range(ids.shape[0]):
        _copy_motion(kept.motion, f.bodies.motion_state, ids[k])
    f.particles.parity[None] = kept.cache[0]
    f.particles.cache_epoch[None] = kept.cache[1]
