"""Which solid an artist's mesh becomes, and its tets: the mesh itself when it is clean (or
repairs cleanly), else the solid of its generalized winding number.

With repair on (or a ``thickness``), :func:`solid_of_input` takes one of two paths:

- **clean input** (closed, manifold, consistently wound, no crossings, one shell), or input
  that ``repair.repair_surface`` turns into one closed solid of its own triangles keeping
  :data:`MIN_RENDER_KEPT` of its winding-number solid within :data:`REPAIR_TIME_SHARE` of the
  time left: that surface is meshed as it is (a copy simplified to the particle spacing, then
  TetGen), which keeps its exact volume. Meshing gets :data:`CLEAN_TIME_SHARE` of the time
  left; when it runs out, the mesher refuses, or the count misses the target by more than
  :data:`COUNT_TOLERANCE` (thin parts that force small tets), the second path meshes the
  input instead.
- **anything else**, or the fall-back: ``winding_solid.winding_solid`` samples the input's
  inside on a grid set by the target and contours it; ``lattice_tets`` fills that with tets
  calibrated to the target. Its cost is bounded by the grid, and it exists for every input
  with a volume.

The render surface stays the artist's: the clean or repaired surface, and only where there is
none (the repair failed, or a sheet given a ``thickness``) the contour of the winding-number
solid. Every path reports the share of the input's winding-number solid the tets keep
(:func:`kept_share`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import trimesh

from .bounded import StepClock
from .validate import MeshError, validate_surface
from .winding_solid import KEPT_SAMPLES, sampled_kept, usable_faces, winding_solid

#: Share of the time left the clean path gets before the winding-number path takes over.
CLEAN_TIME_SHARE = 0.15
#: Share of the time left that repairing the artist's surface (for rendering) gets.
REPAIR_TIME_SHARE = 0.2
#: The repaired artist's surface is rendered only if it keeps this share of the input's
#: winding-number solid (the tets keep all of it).
MIN_RENDER_KEPT = 0.98
#: A clean path whose particle count misses the target by more than this fraction hands over
#: to the winding-number path.
COUNT_TOLERANCE = 0.15


@dataclass
class InputSolid:
    """What :func:`solid_of_input` built.

    Attributes:
        surface: the render surface [m]: closed, manifold, outward.
        tet_surface: the surface the tets fill [m].
        tets: the ``tetra.TetMesh``.
        cache_hit: the tets came from the on-disk cache.
        steps: what was done, in order (human-readable).
        kept_fraction: share of the input's winding-number solid inside the tets [-].
        input_volume: that solid's volume [m^3] (sampled).
        input_extents: the input's bounding-box sizes (3,) [m].
        path: "clean" or "winding number".
    """

    surface: trimesh.Trimesh
    tet_surface: trimesh.Trimesh
    tets: object
    cache_hit: bool
    steps: list = field(default_factory=list)
    kept_fraction: float | None = None
    input_volume: float | None = None
    input_extents: list = field(default_factory=list)
    path: str = "clean"


def kept_share(input_mesh: trimesh.Trimesh, vertices: np.ndarray, faces: np.ndarray, clock: StepClock | None = None,
               samples: int = KEPT_SAMPLES, seed: int = 0) -> tuple[float, float]:
    """(share of the input's winding-number solid inside the closed surface (``vertices``,
    ``faces``), that solid's volume [m^3]), at ``samples`` random points of the input's box;
    (1, 0) when the input has no inside."""
    used = usable_faces(input_mesh.vertices, input_mesh.faces)
    if len(used) == 0:
        return 1.0, 0.0
    corners = np.asarray(input_mesh.vertices)[np.unique(used)]
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    size = np.maximum(hi - lo, 1e-9 * float(np.max(hi - lo)))
    points, held, volume = sampled_kept(input_mesh.vertices, used, vertices, faces, lo, size, samples=samples,
                                        seed=seed, clock=clock, step="kept share (libigl)")
    if not len(points):
        return 1.0, 0.0
    return float(held.mean()), volume


def _is_clean(mesh: trimesh.Trimesh, name: str, clock: StepClock) -> str | None:
    """None when ``mesh`` passes the checks of a clean solid, else the first check's message."""
    try:
        clock.inline("check", validate_surface, mesh, name)
    except MeshError as exc:
        if "ran out of time" in str(exc):
            raise
        return str(exc)
    return None


def _share_clock(clock: StepClock, share: float) -> StepClock:
    """A clock on ``share`` of ``clock``'s time left (its steps are added to ``clock``'s)."""
    left = clock.remaining()
    return StepClock(name=clock.name, seconds=None if left is None else share * left,
                     step_seconds=clock.step_seconds, crash_hint=clock.crash_hint)


def _lattice_mesh(solid, count: int, clock: StepClock, bounds=None):
    """(tet surface, TetMesh, False, step) of the winding-number solid from a cube lattice
    (``lattice_tets``), inside ``bounds`` ((2,3) [m], the input's box)."""
    from .lattice_tets import lattice_tets
    from .tetra import TetMesh
    from .topology import boundary_faces, dihedral_angles_deg, signed_volumes

    start = time.perf_counter()
    vertices, tets, cube = clock.inline("tets from a cube lattice", lattice_tets, solid.values, solid.origin,
                                        solid.cell, solid.surface, count, bounds)
    dihedral = dihedral_angles_deg(vertices, tets).min(axis=1)
    volume = float(signed_volumes(vertices, tets).sum())
    tm = TetMesh(vertices=vertices, tets=tets.astype(np.int32), backend="lattice", max_volume=None,
                 surface_volume=solid.volume, volume_error=volume / solid.volume - 1.0,
                 min_dihedral_deg=float(dihedral.min()), sliver_count=int(np.sum(dihedral < 5.0)), runs=1,
                 seconds=time.perf_counter() - start)
    tet_surface = trimesh.Trimesh(vertices, boundary_faces(tets)[0], process=False)
    return tet_surface, tm, False, (f"filled it with the Kuhn tets of a lattice of {cube:.3g} m cubes, boundary "
                                    f"vertices fitted to the contour: {len(tets):,} tets")


def _clean_path(surface, count, kwargs, clock, mesh_surface, check_count=True):
    """The clean (or repaired) ``surface`` meshed as it is, under :data:`CLEAN_TIME_SHARE` of
    the time left. Returns (InputSolid or None, why it handed over or None)."""
    share = _share_clock(clock, CLEAN_TIME_SHARE)
    # No fTetWild fallback here: the winding-number path is the fallback, and far faster.
    kwargs = dict(kwargs, notes=None)
    try:
        tet_surface, tm, hit, step = mesh_surface(surface, count, kwargs, share)
    except MeshError as exc:
        return None, f"the clean surface could not be meshed in its share of the time ({exc})"
    miss = tm.tet_count / count - 1.0
    if check_count and abs(miss) > COUNT_TOLERANCE:
        return None, (f"meshing the clean surface gave {tm.tet_count:,} particles for {count:,} "
                      f"({miss:+.0%}: parts thinner than the particle spacing)")
    steps = list(surface.metadata.get("repair", [])) + ([step] if step else [])
    return InputSolid(surface=surface, tet_surface=tet_surface, tets=tm, cache_hit=hit, steps=steps), None


def _repaired(raw, name, clock, steps):
    """The artist's surface repaired into one closed solid of its own triangles that keeps
    :data:`MIN_RENDER_KEPT` of its winding-number solid, in :data:`REPAIR_TIME_SHARE` of the
    time left; None (and a step saying why) when that fails."""
    from .meshio_in import check_or_repair

    share = _share_clock(clock, REPAIR_TIME_SHARE)
    try:
        return check_or_repair(raw, name, repair=True, clock=share, min_kept_fraction=MIN_RENDER_KEPT)
    except MeshError as exc:
        steps.append(f"could not be repaired into one closed solid of its own triangles ({str(exc)[:200]})")
        return None


def solid_of_input(raw: trimesh.Trimesh, name: str, *, count: int, kwargs: dict, clock: StepClock,
                   mesh_surface, thickness: float | None = None, check_count: bool = True) -> InputSolid:
    """The solid and tets of the input surface ``raw`` [m] for ``count`` particles (see the
    module docstring). ``mesh_surface(surface, count, kwargs, clock)`` meshes a clean surface
    (prepare's simplified copy and TetGen: (tet surface, TetMesh, cache hit, step or None));
    ``kwargs``: its mesher settings. ``check_count`` False (a volume bound was asked for, not a
    count): the clean path's count is not held to ``count``.

    Raises MeshError when the input has no volume (naming ``thickness``) or no faces.
    """
    steps: list[str] = []
    extents = raw.extents.tolist() if len(raw.faces) else [0.0, 0.0, 0.0]
    surface = None
    if thickness is None:
        problem = _is_clean(raw, name, clock)
        if problem is None:
            surface = raw
            surface.metadata["repair"], surface.metadata["repair_report"] = [], None
        else:
            steps.append(f"not a clean solid ({problem.split(';')[0]})")
            surface = _repaired(raw, name, clock, steps)
        if surface is not None:
            result, why = _clean_path(surface, count, kwargs, clock, mesh_surface, check_count)
            if result is not None:
                result.steps[:0] = steps
                result.kept_fraction, result.input_volume = kept_share(
                    raw, result.tets.vertices, _boundary(result.tets.tets), clock)
                result.input_extents = extents
                return result
            steps.append(f"meshed the solid of its winding number instead: {why}")
        else:
            steps.append("meshed the solid of its winding number")
    solid = winding_solid(raw, count, thickness=thickness, name=name, clock=clock)
    steps.extend(solid.steps)
    tet_surface, tm, hit, step = _lattice_mesh(solid, count, clock, _box(raw, thickness))
    steps.append(step)
    if surface is None:
        surface = solid.surface
        if thickness is None:
            steps.append("renders the contour of the winding-number solid")
    kept, volume = kept_share(raw, tm.vertices, _boundary(tm.tets), clock)
    return InputSolid(surface=surface, tet_surface=tet_surface, tets=tm, cache_hit=hit, steps=steps,
                      kept_fraction=kept, input_volume=volume, input_extents=extents, path="winding number")


def _box(raw: trimesh.Trimesh, thickness: float | None):
    """(2,3) [m] the box of the input's faces of positive area (grown by half of
    ``thickness``), which the winding-number solid's tets stay inside; None without faces."""
    used = usable_faces(raw.vertices, raw.faces)
    if len(used) == 0:
        return None
    corners = np.asarray(raw.vertices, dtype=np.float64)[np.unique(used)]
    grow = 0.5 * thickness if thickness else 0.0
    return np.stack([corners.min(axis=0) - grow, corners.max(axis=0) + grow])


def _boundary(tets: np.ndarray) -> np.ndarray:
    from .topology import boundary_faces

    return boundary_faces(tets)[0]
