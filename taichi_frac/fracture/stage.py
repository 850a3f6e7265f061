"""The fracture stage of a frame: impacts and poses in, births and deaths out.

It reads the World's impact rows, keeps each breakable body's strongest touch per other
body, analyses them (``cracks.analyze_impact``: the stress near the contacts, the whole
field only where a split needs it), splits the bodies that crack (``fragments``) and puts
the pieces in the World in their parent's place, lifted out of the ground. Each split is
returned as a :class:`Fracture`; what is drawn and written of it is the job of the stages after it
(``surfaces/stage.py``, ``io/recorder.py``), when to run the stage the simulation's loop
(``simulation.py``).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from ..kinematics.quaternion import quaternion_matrix
from ..model import BodyModel
from ..options import FractureOptions, Material, ParticleOptions
from .cracks import analyze_impact
from .crack_types import ImpactAnalysis, RingCrack
from .fragments import Fragment, FractureResult, fragment_peak_stress, make_fragments, split_body
from .peaks import PeakTracker


@dataclass
class BodyRecord:
    """What the simulation knows of a live (or ended) body beyond the World's fields: its
    model and options (the fracture stage reads them and makes its pieces')."""

    name: str
    model: BodyModel
    root: BodyModel
    material: Material
    fracture: FractureOptions
    particles: ParticleOptions
    breakable: bool
    generation: int = 0
    parent: int | None = None
    birth_frame: int = 0
    friction: float = 0.5
    restitution: float = 0.2


@dataclass(frozen=True, eq=False)
class Fracture:
    """One body split by the stage: the parent left the World, its pieces entered it.

    Attributes:
        frame: the output frame it happened in.
        parent: the parent's body id (the World may already have given its slot to a piece).
        parent_record: the parent's record (the records map may hold a piece under ``parent``).
        analysis: the impact analysis that cracked it (full field when ``field_stress``).
        split: the cut (``fragments.split_body``).
        pieces: the pieces as placed in the World (lifted out of the ground).
        children: (len(pieces),) their body ids; children_records: their records.
        event: the split as the run's record lists it (:func:`impact_event`).
    """

    frame: int
    parent: int
    parent_record: BodyRecord
    analysis: ImpactAnalysis
    split: FractureResult
    pieces: list[Fragment]
    children: list[int]
    children_records: list[BodyRecord]
    event: dict = dataclasses.field(default_factory=dict)

    @property
    def born(self) -> list[int]:
        return list(self.children)


def strongest_per_pair(impacts: dict, bodies: np.ndarray) -> dict[int, np.ndarray]:
    """For each body in ``bodies``: row indices of its strongest impact per other body.

    Several substeps of one frame usually hold the same touch; the strongest (largest
    contact force, see dynamics/impacts.py) stands for it. Distinct others (the ground,
    another body, a wall) stay distinct: a body hit at several points in one frame is
    analysed with all of them at once.
    """
    force = np.linalg.norm(impacts["force"], axis=1)
    rows = np.nonzero(np.isin(impacts["body"], bodies))[0]
    if len(rows) == 0:
        return {}
    body = impacts["body"][rows].astype(np.int64)
    other = impacts["other"][rows].astype(np.int64)
    # Sort by (body, other, -force): the first row of each (body, other) run is its strongest.
    order = np.lexsort((-force[rows], other, body))
    body, other, rows = body[order], other[order], rows[order]
    first = np.ones(len(rows), dtype=bool)
    first[1:] = (body[1:] != body[:-1]) | (other[1:] != other[:-1])
    body, rows = body[first], rows[first]
    return {int(b): np.sort(rows[body == b]) for b in np.unique(body)}


def lift_out_of_ground(piece: Fragment, ground_heights, allowed_penetration: float) -> Fragment:
    """``piece`` moved up out of the ground planes z = ``ground_heights`` [m] if its
    collision spheres start inside one. A fragment's boundary layer is built afresh (its
    crack faces are new surface), so its spheres need not match the parent's, which the
    solver had kept out of the ground; without this a piece born at the moment of impact
    can start up to a few millimetres deep and be shot out by the position correction.
    The shift is vertical and leaves ``allowed_penetration`` (a fraction of the mean
    boundary radius, as the solver's) in place; velocities are untouched."""
    if not ground_heights:
        return piece
    m = piece.model
    rot = quaternion_matrix(piece.orientation)
    lowest = np.min(piece.position[2] + m.collision_position @ rot[2] - m.boundary_radius)
    depth = max(ground_heights) - lowest
    allowed = allowed_penetration * float(m.boundary_radius.mean())
    if depth > allowed:
        piece = dataclasses.replace(piece, position=piece.position + np.array([0.0, 0.0, depth - allowed]))
    return piece


class FractureStage:
    """Cracks and splits the breakable bodies of a World.

    Args:
        world: the World whose impacts are read and whose bodies are replaced.
        records: body id -> :class:`BodyRecord`, the simulation's registry (the stage adds
            the pieces' records; a parent's record stays in the :class:`Fracture`).
        ground_heights: z [m] of the scene's ground planes (pieces are lifted out of them).
        field_stress: when a local analysis splits a body, analyse it again over the whole
            field, for the pieces' peak stress (only the cache reads it).
        skip_repeats: within a frame (:meth:`begin_frame`), a (body, other) touch no stronger
            than one already analysed without a crack is not analysed again (the stage runs
            after every substep when fractures are resimulated).
        times: an object with ``fracture_analysis`` and ``fragment_split`` seconds, added to.

    Counters: ``fracture_events`` (bodies split), ``mass_dropped`` [kg] (the "drop" policy);
    ``peaks``: each scene body's most stressed impact (``peaks.py``, why a body did not break).
    """

    def __init__(self, world, records: dict, *, ground_heights=(), field_stress: bool = False,
                 skip_repeats: bool = False, times=None):
        self.world = world
        self.records = records
        self.ground_heights = list(ground_heights)
        self.field_stress = bool(field_stress)
        self.skip_repeats = bool(skip_repeats)
        self.times = times
        self.fracture_events = 0
        self.first_analysis_seconds = None  # [s] the first impact analysis of the run
        self.mass_dropped = 0.0
        self.peaks = PeakTracker()
        # (body, other) -> largest force [N] analysed in this frame without a crack.
        self._analysed: dict | None = {} if skip_repeats else None

    def begin_frame(self) -> None:
        """Forget the touches analysed in the previous frame."""
        if self.skip_repeats:
            self._analysed = {}

    def run(self, frame: int, first: int = 0, start=None) -> list[Fracture]:
        """Analyse the impacts recorded since row ``first`` of this frame and split the
        bodies that crack; returns the splits. ``start``: a World checkpoint from before those
        impacts; the pieces are then put where their parent was then (the substep is run
        again, see ``simulation.py``); None: where the parent is now."""
        world = self.world
        if world.impact_count() <= first:  # (most frames: no impact, nothing to look at)
            return []
        live = set(world.body_ids)
        breakable = np.array([b for b, r in self.records.items() if r.breakable and b in live])
        if len(breakable) == 0:
            return []
        impacts = world.impacts(first)
        if len(impacts["body"]) == 0:
            return []
        fractures = []
        masses = {b: r.model.mass for b, r in self.records.items() if b in live}  # (before any slot is reused)
        for body, rows in strongest_per_pair(impacts, breakable).items():
            self.peaks.touched(self.records[body], impacts, rows)
            rows = self._rows_to_analyse(body, rows, impacts)
            if rows is None:
                continue
            found = self._analyse(body, rows, impacts, frame, touch_energies(masses, body, rows, impacts),
                                  bending_shares(masses, body, rows, impacts))
            if found is None:
                continue
            analysis, split = found
            fracture = self._replace(frame, body, analysis, split, start)
            fracture.event.update(impact_event(masses, rows, impacts, fracture))
            fractures.append(fracture)
        return fractures

    def _rows_to_analyse(self, body: int, rows: np.ndarray, impacts: dict) -> np.ndarray | None:
        """The rows of ``body``'s touches over its force threshold, or None when there are
        none (or, with ``skip_repeats``, when each is no stronger than one already analysed
        this frame without a crack)."""
        rec = self.records[body]
        force = impacts["force"][rows]
        strong = np.linalg.norm(force, axis=1) >= max(rec.fracture.impact_force_threshold, 1e-12)
        if not np.any(strong):
            return None
        rows = rows[strong]
        if self._analysed is not None:
            size = np.linalg.norm(force[strong], axis=1)
            pairs = [(body, int(o)) for o in impacts["other"][rows]]
            if all(size[i] <= self._analysed.get(p, -1.0) for i, p in enumerate(pairs)):
                return None  # the same touch, no stronger than one that cracked nothing
        return rows

    def _remember_uncracked(self, body: int, rows: np.ndarray, impacts: dict) -> None:
        if self._analysed is None:
            return
        size = np.linalg.norm(impacts["force"][rows], axis=1)
        for i, o in enumerate(impacts["other"][rows]):
            p = (body, int(o))
            self._analysed[p] = max(self._analysed.get(p, 0.0), float(size[i]))

    def _analyse(self, body: int, rows: np.ndarray, impacts: dict, frame: int, energies: np.ndarray,
                 shares: np.ndarray):
        """(analysis, split) of ``body``'s touches ``rows`` when they break it in two or
        more, else None. The stress is computed near the contacts only; the whole field
        only when the cracks do split the body and ``field_stress`` asks for it (in the 13
        rings, 20 of 33 cracking impacts split nothing and skip it). The cracks, hence the
        split, are the same either way."""
        rec = self.records[body]
        times = self.times
        t = time.perf_counter()
        # In the body's frame at the impact's substep: a struck body may move far by the
        # frame's end.
        points_b, normals_b = impacts["point_body"][rows], impacts["normal_body"][rows]
        force_b = impacts["force_body"][rows]
        analysis = analyze_impact(rec.model, points_b, normals_b, force_b, rec.material, rec.fracture,
                                  full_field=False, energy=energies, bending_share=shares)
        if self.first_analysis_seconds is None:  # (in a new process: its kernels' first launch)
            self.first_analysis_seconds = time.perf_counter() - t
        times.fracture_analysis += time.perf_counter() - t
        self.peaks.analysed(rec, analysis, impacts, rows, frame,
                            lambda: self.world.body_state([body])["orientation"][0])
        if not analysis.any_crack:
            self._remember_uncracked(body, rows, impacts)
            return None
        t = time.perf_counter()
        split = split_body(rec.model, analysis, rec.fracture)
        times.fragment_split += time.perf_counter() - t
        if split.fragment_count + (1 if split.dropped_mass > 0 else 0) <= 1:
            return None
        if analysis.field_particles is not None and self.field_stress:
            t = time.perf_counter()
            analysis = analyze_impact(rec.model, points_b, normals_b, force_b, rec.material, rec.fracture,
                                      full_field=True, energy=energies, bending_share=shares)
            split = dataclasses.replace(split, fragment_peak_stress=fragment_peak_stress(
                split.fragment_tets, analysis.particle_principal_stress))
            times.fracture_analysis += time.perf_counter() - t
        return analysis, split

    def _replace(self, frame: int, body: int, analysis: ImpactAnalysis, split: FractureResult, start) -> Fracture:
        """Put ``split``'s pieces in the World in place of ``body``."""
        world, rec = self.world, self.records[body]
        t = time.perf_counter()
        # The pieces start where the body is now, or was before the substep run again.
        state = world.body_state([body]) if start is None else world.checkpoint_state(start, [body])
        pieces = make_fragments(
            rec.model, split, state["position"][0], state["orientation"][0], state["linear_velocity"][0],
            state["angular_velocity"][0],
            rec.material, rec.particles, options=rec.fracture, analysis=analysis, birth_frame=frame,
            parent=body, parent_generation=rec.generation,
        )
        world.remove_body(body)
        if self._analysed is not None:  # its slot may go to a piece: forget what it went through
            for key in [key for key in self._analysed if body in key]:
                del self._analysed[key]
        self.mass_dropped += split.dropped_mass
        self.fracture_events += 1
        pieces = [lift_out_of_ground(p, self.ground_heights, world.options.allowed_penetration) for p in pieces]
        children = world.add_bodies(
            [p.model for p in pieces], [p.position for p in pieces], [p.orientation for p in pieces],
            [p.linear_velocity for p in pieces], [p.angular_velocity for p in pieces], friction=rec.friction,
            restitution=rec.restitution, breakable=[p.breakable for p in pieces],
            young_modulus=rec.material.young_modulus, poisson_ratio=rec.material.poisson_ratio,
        )
        children_records = []
        for k, (piece, child) in enumerate(zip(pieces, children)):
            child_rec = BodyRecord(
                name=f"{rec.name}_{k}", model=piece.model, root=rec.root, material=rec.material,
                fracture=rec.fracture, particles=rec.particles, breakable=piece.breakable,
                generation=piece.generation, parent=body, birth_frame=frame, friction=rec.friction,
                restitution=rec.restitution,
            )
            # The World may hand the parent's freed slot to a piece: the parent's record
            # lives on in the Fracture.
            self.records[child] = child_rec
            children_records.append(child_rec)
        self.times.fragment_split += time.perf_counter() - t
        return Fracture(frame=frame, parent=body, parent_record=rec, analysis=analysis, split=split,
                        pieces=pieces, children=list(children), children_records=children_records)


def _other_masses(masses: dict, rows: np.ndarray, impacts: dict) -> tuple[np.ndarray, np.ndarray]:
    """(R,) [kg] each touch's other body's mass (0 for the ground or a static box, which
    are no body) and (R,) bool, which others are bodies."""
    other = np.array([masses.get(int(o), np.inf) for o in impacts["other"][rows]], dtype=np.float64)
    finite = np.isfinite(other)
    return np.where(finite, other, 0.0), finite


def touch_energies(masses: dict, body: int, rows: np.ndarray, impacts: dict) -> np.ndarray:
    """(R,) [J] the kinetic energy of each touch's approach, 1/2 m* v^2 with m* the reduced
    mass of ``body`` and the other (the body's own mass against the ground or a static box).
    ``masses``: body id -> [kg] of the bodies alive when the impacts were recorded."""
    mass = masses[body]
    speeds = np.asarray(impacts["speed"][rows], dtype=np.float64)
    other, finite = _other_masses(masses, rows, impacts)
    reduced = np.where(finite, mass * other / (mass + other), mass)
    return 0.5 * reduced * speeds**2


def bending_shares(masses: dict, body: int, rows: np.ndarray, impacts: dict) -> np.ndarray:
    """(R,) how much of ``body``'s bending each touch loads (``energy.bent_force_scale``): the
    other's share of the pair's mass, m_other / (m_body + m_other); 1 for the ground or a
    static box."""
    other, finite = _other_masses(masses, rows, impacts)
    return np.where(finite, other / (masses[body] + other), 1.0)


def impact_event(masses: dict, rows: np.ndarray, impacts: dict, fracture: Fracture) -> dict:
    """One fracture event as the run's record lists it: the frame, the body's name, its
    strongest touch's approach speed [m/s] and force [N], the kinetic energy of the touches'
    approach [J] (1/2 m v^2 of each pair's reduced mass, the body's own against the ground or
    a static box), the radial and ring cracks and the pieces. ``masses``: body id -> [kg] of
    the bodies alive when the impacts were recorded."""
    speeds = np.asarray(impacts["speed"][rows], dtype=np.float64)
    forces = np.linalg.norm(np.asarray(impacts["force"][rows], dtype=np.float64), axis=1)
    energy = float(touch_energies(masses, fracture.parent, rows, impacts).sum())
    strongest = int(np.argmax(forces))
    rings = sum(isinstance(c, RingCrack) for c in fracture.analysis.cracks)
    return dict(frame=int(fracture.frame), body=fracture.parent_record.name, speed=float(speeds[strongest]),
                energy=float(energy), force=float(forces[strongest]),
                cracks=len(fracture.analysis.cracks) - rings, ring_cracks=int(rings), pieces=len(fracture.pieces))
