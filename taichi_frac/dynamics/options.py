"""Capacities and solver options of the rigid-body world (plain data, SI units)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import ClassVar

from ..options import RigidBodyOptions, check_range


class CapacityError(RuntimeError):
    """A fixed capacity of the world is exhausted. The message names it and how to raise it."""


@dataclass(frozen=True, kw_only=True)
class WorldCapacity:
    """Sizes of the Taichi fields, allocated once when the World is built.

    Attributes:
        max_bodies: body slots (removed bodies free their slot for reuse).
        max_boundary_particles: collision particle slots over all bodies (boundary layer,
            or surface particles for single-scale bodies); a body's particles take one
            contiguous range, freed ranges are reused (first fit).
        max_contacts: particle contacts per substep; more are counted in
            ``stats.contact_overflows`` and reported, never silently dropped.
        max_impacts: impact rows kept per ``advance`` (one per body pair per substep above
            ``record_force_threshold``); more are counted in ``stats.impact_overflows``.
        max_static_boxes: static boxes (walls, inclines).
        max_planes: ground planes.
        max_surface_points: contact-patch points over all bodies (``surface_contact``:
            ~6 per boundary sphere at n = 4, ~3 per surface particle single-scale); None:
            8 x max_boundary_particles. Freed ranges are reused (first fit).
    """

    max_bodies: int = 1024
    max_boundary_particles: int = 65536
    max_contacts: int = 131072
    max_impacts: int = 16384
    max_static_boxes: int = 64
    max_planes: int = 4
    max_surface_points: int | None = None

    def __post_init__(self):
        if self.max_surface_points is None:
            object.__setattr__(self, "max_surface_points", 8 * self.max_boundary_particles)
        check_range("capacity", "max_surface_points", self.max_surface_points, 1, 1_000_000_000)
        check_range("capacity", "max_bodies", self.max_bodies, 1, 10_000_000)
        check_range("capacity", "max_boundary_particles", self.max_boundary_particles, 1, 100_000_000)
        check_range("capacity", "max_contacts", self.max_contacts, 1, 100_000_000)
        check_range("capacity", "max_impacts", self.max_impacts, 1, 100_000_000)
        check_range("capacity", "max_static_boxes", self.max_static_boxes, 1, 100_000)
        check_range("capacity", "max_planes", self.max_planes, 1, 1000)


@dataclass(frozen=True, kw_only=True)
class DynamicsOptions(RigidBodyOptions):
    """The rigid-body solver's settings: those a scene's ``[simulation]`` table also holds
    (:class:`~taichi_frac.options.RigidBodyOptions`: iterations, gravity, substep
    refinement, contact mode, sleeping, rolling resistance) and the solver's own.

    Attributes:
        restitution_iterations: extra sweeps that only apply restitution (after the main
            sweeps, Box2D v3 style), so a bounce is the asked fraction of the approach.
        max_rotation_per_substep: a body's rotation over a substep is integrated in pieces
            of at most this angle [rad] (a fast-spinning body turns accurately without
            shortening the substep of every body).
        contact_margin: contact distance as a fraction of the mean radius of the two spheres
            [-], on top of the speculative distance (how far the two bodies can move in the
            substep); contacts are made this far before touching.
        position_correction_rate: split impulse: penetration is removed through
            pseudo-velocities (which add no kinetic energy) at this rate [1/s], i.e. a
            fraction 1 - exp(-rate dt) of it per substep, so the correction per second does
            not depend on the substep length (110/s is Baumgarte's 0.2 per 2 ms substep;
            with a fixed 0.2 per substep, a 10 ms substep left 5x more of a penetration
            standing for a frame).
        allowed_penetration: penetration left alone (slop), fraction of particle radius [-].
        max_correction_speed: cap on the split-impulse push-out speed [m/s], per contact
            and at every point of a body (deeply overlapped bodies separate gently instead
            of exploding; a piece overlapped from all sides is not pumped faster).
        restitution_threshold: approach speeds below this do not bounce [m/s].
        record_force_threshold: impact rows are kept when their force exceeds this [N].
        impact_speed: contacts approaching faster than this [m/s] are impacts, whose force
            is the Hertz peak of their impulse (see dynamics/impacts.py); slower ones are
            sustained, with force impulse / dt.
        warm_start: fraction of each contact's impulses from the last substep applied
            before the sweeps [-] (1: full warm starting, 0: none).
        stage_timing: synchronise the device after each stage so ``stats.seconds`` is exact.
    """

    OWNER: ClassVar[str] = "dynamics"

    restitution_iterations: int = 4
    max_rotation_per_substep: float = 0.1
    contact_margin: float = 0.25
    position_correction_rate: float = 110.0
    allowed_penetration: float = 0.005
    max_correction_speed: float = 1.0
    restitution_threshold: float = 0.2
    record_force_threshold: float = 0.0
    impact_speed: float = 0.05
    warm_start: float = 1.0
    stage_timing: bool = True

    def __post_init__(self):
        super().__post_init__()
        check_range("dynamics", "restitution_iterations", self.restitution_iterations, 0, 1000)
        check_range("dynamics", "max_rotation_per_substep", self.max_rotation_per_substep, 0.0, 10.0, low_open=True)
        check_range("dynamics", "contact_margin", self.contact_margin, 0.0, 4.0)
        check_range("dynamics", "position_correction_rate", self.position_correction_rate, 0.0, 1e6)
        check_range("dynamics", "allowed_penetration", self.allowed_penetration, 0.0, 1.0)
        check_range("dynamics", "max_correction_speed", self.max_correction_speed, 0.0, None, low_open=True)
        check_range("dynamics", "restitution_threshold", self.restitution_threshold, 0.0, None)
        check_range("dynamics", "record_force_threshold", self.record_force_threshold, 0.0, None)
        check_range("dynamics", "impact_speed", self.impact_speed, 0.0, None)
        check_range("dynamics", "warm_start", self.warm_start, 0.0, 1.0)

    @classmethod
    def from_simulation(cls, sim: RigidBodyOptions, **overrides) -> "DynamicsOptions":
        """The solver settings a scene's ``SimulationOptions`` implies (its
        ``RigidBodyOptions`` fields), plus ``overrides``."""
        values = {f.name: getattr(sim, f.name) for f in fields(RigidBodyOptions)}
        values["gravity"] = tuple(sim.gravity)
        values.update(overrides)
        return cls(**values)
