"""Tetrahedralization of closed surfaces, behind swappable backends.

``tetrahedralize(mesh, target_tets=..., backend="tetgen")`` returns a :class:`TetMesh`.
Backends are plain functions ``(vertices, faces, max_volume, min_dihedral_deg) ->
(vertices, tets)`` registered in :data:`BACKENDS`; add one with :func:`register_backend`.

- ``tetgen`` (default; TetGen 1.6 via the ``tetgen`` package, AGPL engine): constrained
  Delaunay, keeps the input surface exactly (tet volume = mesh volume to round-off, any
  genus, sharp features kept), ~0.1 s for 5,000 tets. Its quality refinement overshoots a
  volume bound (``maxvolume`` needs ``fixedvolume=True``), so :func:`tetrahedralize`
  calibrates: it starts from an empirical ratio and, if the count misses the target by more
  than ``tolerance``, re-runs with the bound scaled by the miss (count ~ 1/max_volume), and
  where that misses too (a surface that sets part of the count), once more on the line
  count = floor + slope / max_volume the two runs fix.
- ``wildmeshing`` (fTetWild, MPL-2.0, optional): robust to dirty input, but ~50x slower
  and it approximates the surface within an envelope (volume off by ~0.2 %).
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib.util
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass

import numpy as np
import trimesh

from .bounded import StepClock
from .topology import compact_vertices, dihedral_angles_deg, orient_tets, signed_volumes
from .validate import MeshError


@dataclass(frozen=True)
class TetMesh:
    """A tet mesh of a closed surface.

    Attributes:
        vertices: (V,3) float64 [m].
        tets: (T,4) int32, positively oriented.
        backend: mesher used.
        max_volume: volume bound passed in the final run [m^3] (None: unbounded).
        surface_volume: enclosed volume of the input surface [m^3].
        volume_error: (sum of tet volumes - surface volume) / surface volume [-].
        min_dihedral_deg: smallest dihedral angle over all tets [degrees].
        sliver_count: tets with a dihedral angle below 5 degrees.
        runs: mesher runs made (calibration).
        seconds: wall time of all runs [s].
    """

    vertices: np.ndarray
    tets: np.ndarray
    backend: str
    max_volume: float | None
    surface_volume: float
    volume_error: float
    min_dihedral_deg: float
    sliver_count: int
    runs: int
    seconds: float

    @property
    def tet_count(self) -> int:
        return len(self.tets)


def _tetgen(vertices, faces, max_volume, min_dihedral_deg, minratio=1.5, optimise=True, nobisect=False):
    import tetgen

    # The optimisation settings (flips + smoothing, dihedral target 165 deg) halve the
    # slivers left by plain quality refinement at no measurable cost on primitives (tori).
    # On a surface whose short features force tiny tets under a 10 degree bound they cost
    # an order of magnitude more: ``optimise=False`` keeps TetGen's defaults.
    # ``nobisect`` (TetGen's -Y): no Steiner points on the surface. A surface triangle that
    # the quality bound finds encroached is otherwise split, and on a part thinner than the
    # tets (a blade) every split adds tets through its whole thickness.
    kwargs = dict(quality=True, minratio=minratio, mindihedral=min_dihedral_deg, verbose=0, nobisect=nobisect)
    if optimise:
        kwargs.update(opt_scheme=7, opt_max_flip_level=5, opt_iterations=20, optmaxdihedral=165.0)
    if max_volume is not None:
        kwargs.update(fixedvolume=True, maxvolume=float(max_volume))
    try:
        with _in_scratch_dir():  # (where it refuses facets it writes "_skipped.node/.face")
            out = tetgen.TetGen(vertices, faces).tetrahedralize(**kwargs)
    except RuntimeError as exc:  # tetgen reports self-intersections and bad PLCs this way
        raise MeshError(f"tetgen failed: {exc}; try repair=True or backend='wildmeshing'") from exc
    return np.asarray(out[0], dtype=np.float64), np.asarray(out[1], dtype=np.int64)


@contextlib.contextmanager
def _in_scratch_dir():
    """Work in a scratch folder: the native meshers write files into the working directory
    (TetGen the facets it skips, fTetWild its tracked surface), which is the user's."""
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory() as scratch:
        os.chdir(scratch)
        try:
            yield
        finally:
            os.chdir(cwd)


@contextlib.contextmanager
def _native_stdout_silenced_in_scratch_dir():
    """fTetWild prints every pass with std::cout (it would corrupt `info --json`) and writes
    "__tracked_surface.stl" into the working directory: point file descriptor 1 at
    /dev/null and work in a scratch folder while it runs."""
    sys.stdout.flush()
    saved_stdout = os.dup(1)
    with _in_scratch_dir(), open(os.devnull, "w") as devnull:
        os.dup2(devnull.fileno(), 1)
        try:
            yield
        finally:
            # Its log lines still in the C library's stdout buffer would reach the real
            # stdout once fd 1 is back: flushed into /dev/null first.
            ctypes.CDLL(None).fflush(None)
            os.dup2(saved_stdout, 1)
            os.close(saved_stdout)


def _wildmeshing(vertices, faces, max_volume, min_dihedral_deg):
    if importlib.util.find_spec("wildmeshing") is None:
        raise MeshError("backend 'wildmeshing' needs the wildmeshing package: pip install wildmeshing")
    # fTetWild starts TBB and OpenMP thread pools, which a forked process inherits broken:
    # run in this process, every later bounded (forked) step that runs fTetWild would stall.
    # A child of its own keeps this process free of those pools.
    clock = StepClock(name="mesh", seconds=None, crash_hint="repair the mesh in a modelling tool")
    return clock.run("fTetWild", _wildmeshing_here, vertices, faces, max_volume, min_dihedral_deg)


def _wildmeshing_here(vertices, faces, max_volume, min_dihedral_deg):
    import wildmeshing
    diag = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    # fTetWild sizes by ideal edge length relative to the bounding-box diagonal; a regular
    # tet of volume v has edge (6 sqrt(2) v)^(1/3). Its tets average ~1/2 the ideal volume.
    edge = (6.0 * math.sqrt(2.0) * 2.0 * max_volume) ** (1 / 3) if max_volume else 0.05 * diag
    with _native_stdout_silenced_in_scratch_dir():
        mesher = wildmeshing.Tetrahedralizer(stop_quality=10, max_its=80, epsilon=1e-3,
                                             edge_length_r=min(max(edge / diag, 1e-4), 1.0))
        mesher.set_log_level(6)  # spdlog "off"
        mesher.set_mesh(np.ascontiguousarray(vertices, dtype=np.float64),
                        np.ascontiguousarray(faces, dtype=np.int32))
        mesher.tetrahedralize()
        result = mesher.get_tet_mesh()  # (vertices, tets, per-tet attribute)
    return np.asarray(result[0], dtype=np.float64), np.asarray(result[1], dtype=np.int64)


BACKENDS = {"tetgen": _tetgen, "wildmeshing": _wildmeshing}

#: Tets per (volume / max_volume) that tetgen's quality refinement produces on typical
#: closed meshes (tori, boxes, spheres: benchmarks/bench_prepare.py measures it).
_TETGEN_OVERSHOOT = 2.0


#: Looser (radius-edge ratio, min dihedral [deg], surface kept unsplit) TetGen bounds tried in
#: turn when the quality bound alone overshoots the target count. The last keeps the surface
#: triangles as they are (TetGen's -Y): where parts thinner than the tets make even the
#: loosest quality bound split the surface past the target, only the volume bound is left to
#: set the count (a twisted blade 0.25 tet edges thick: +17 % at (8, 0), on target with -Y).
_TETGEN_RELAXED_QUALITY = ((2.0, 5.0, False), (4.0, 0.0, False), (8.0, 0.0, False), (2.0, 5.0, True))


#: Volume-bound calibration runs under each relaxed quality bound.
_RELAXED_CALIBRATION_RUNS = 4

#: Under ``relax_quality``, a first count over this many times the target is the quality
#: bound's floor (the surface's short features set it, not the volume bound): calibrating the
#: volume bound under that quality cannot reach the target, so the next, looser one is tried.
_FLOOR_MISS = 2.0


def _next_bound(seen: list, target: int) -> float:
    """The volume bound for ``target`` tets from the (bound, count) runs ``seen``. A count is
    the surface's floor plus volume / (k bound): with two runs that line in 1/bound is fitted
    (the floor alone can be 2/3 of the target on a coarse copy, where a proportional step
    barely moves the count); with one, or where the fit says the floor is above the target,
    a proportional step. None where the fitted floor is above the target."""
    (b1, n1) = seen[-1]
    if len(seen) >= 2:
        b0, n0 = seen[-2]
        if b0 != b1 and n0 != n1:
            slope = (n0 - n1) / (1.0 / b0 - 1.0 / b1)
            floor = n1 - slope / b1
            if floor >= target and n1 > target:
                return None  # this quality bound cannot reach the target
            if slope > 0 and floor < target:
                return min(max(slope / (target - floor), b1 / 8.0), b1 * 8.0)
    return b1 * n1 / target


def register_backend(name: str, function) -> None:
    """Add a mesher: ``function(vertices (V,3), faces (F,3), max_volume or None,
    min_dihedral_deg) -> (vertices (V',3), tets (T,4))``."""
    BACKENDS[name] = function


def regular_tet_edge(volume: float) -> float:
    """Edge length [m] of a regular tet of ``volume`` [m^3]: (6 sqrt(2) V)^(1/3)."""
    return (6.0 * math.sqrt(2.0) * volume) ** (1.0 / 3.0)


def tetrahedralize(
    mesh: trimesh.Trimesh,
    *,
    target_tets: int | None = None,
    max_volume: float | None = None,
    backend: str = "tetgen",
    min_dihedral_deg: float = 10.0,
    tolerance: float = 0.1,
    count_tolerance: float = 0.15,
    relax_quality: bool = False,
) -> TetMesh:
    """Fill the closed surface ``mesh`` [m] with tets.

    Give ``target_tets`` (calibrated to land within ``tolerance`` where two re-runs can do
    it) or ``max_volume`` [m^3] (handed to the mesher as is; tetgen's final optimisation
    may leave under 1 % of the tets up to ~15 % above it), or neither (the mesher's coarsest quality
    mesh). ``min_dihedral_deg`` is the quality bound handed to the mesher; the result
    reports the angle actually reached. With ``relax_quality``, where TetGen's quality bound
    keeps the count above ``count_tolerance`` over the target (short surface features, thin
    parts), it re-meshes with the looser bounds of :data:`_TETGEN_RELAXED_QUALITY` until the
    count fits (used for simplified copies of artists' meshes; primitives keep the bound).
    """
    if backend not in BACKENDS:
        raise MeshError(f"unknown mesher backend {backend!r}: use one of {', '.join(BACKENDS)}")
    if target_tets is not None and max_volume is not None:
        raise ValueError("give target_tets or max_volume, not both")
    run = BACKENDS[backend]
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    volume = float(mesh.volume)
    start = time.perf_counter()
    runs = 0
    # TetGen with a quality it may relax (copies of artists' surfaces): its default
    # optimisation, and a count far above the target skips to a looser quality.
    relaxed_tetgen = relax_quality and backend == "tetgen"

    def mesh_once(bound, quality=None):
        nonlocal runs
        runs += 1
        if quality is not None:
            v, t = _tetgen(vertices, faces, bound, quality[1], minratio=quality[0], optimise=False,
                           nobisect=quality[2])
        elif relaxed_tetgen:
            # Copies of artists' surfaces: the extra optimisation can grind for minutes there,
            # where TetGen's defaults take seconds.
            v, t = _tetgen(vertices, faces, bound, min_dihedral_deg, optimise=False)
        else:
            v, t = run(vertices, faces, bound, min_dihedral_deg)
        if len(t) == 0:
            raise MeshError(f"mesher {backend!r} produced no tets (is the surface closed?)")
        v, t, _ = compact_vertices(v, t)
        return v, orient_tets(v, t)

    if target_tets is None:
        bound = max_volume
        v, t = mesh_once(bound)
    else:
        overshoot = _TETGEN_OVERSHOOT if backend == "tetgen" else 1.0
        bound = overshoot * volume / target_tets
        v, t = mesh_once(bound)
        miss = len(t) / target_tets
        floor_bound = relaxed_tetgen and miss > _FLOOR_MISS
        if abs(miss - 1.0) > tolerance and not floor_bound:
            # Count ~ 1/bound away from the surface-resolution floor: one proportional step.
            retry_bound = bound * miss
            v2, t2 = mesh_once(retry_bound)
            seen = [(bound, len(t)), (retry_bound, len(t2))]
            if abs(len(t2) / target_tets - 1.0) < abs(miss - 1.0):
                v, t, bound = v2, t2, retry_bound
            # Where the surface sets part of the count (fine copies of artists' surfaces), the
            # proportional step falls short: the two counts fix the floor and the slope.
            third = _next_bound(seen, target_tets) if abs(len(t) / target_tets - 1.0) > tolerance else None
            if third is not None:
                v2, t2 = mesh_once(third)
                if abs(len(t2) / target_tets - 1.0) < abs(len(t) / target_tets - 1.0):
                    v, t, bound = v2, t2, third
        if relaxed_tetgen and len(t) > (1.0 + count_tolerance) * target_tets:
            # The quality bound forces small tets along short surface features or thin parts
            # whatever the volume bound: trade quality for the count, reported as the min
            # dihedral angle and the sliver count. A looser bound frees the count from the
            # surface, so the volume bound is re-calibrated under it (proportional steps):
            # without that the bound fitted under the strict quality undershoots (-21 % on
            # overlapping shells).
            def miss_of(tets):
                return abs(len(tets) / target_tets - 1.0)

            for quality in _TETGEN_RELAXED_QUALITY:
                quality_bound, seen = bound, []
                for _ in range(_RELAXED_CALIBRATION_RUNS):
                    v2, t2 = mesh_once(quality_bound, quality)
                    if miss_of(t2) < miss_of(t):
                        v, t, bound = v2, t2, quality_bound
                    if miss_of(t2) <= tolerance:
                        break
                    if not seen and len(t2) > _FLOOR_MISS * target_tets and quality != _TETGEN_RELAXED_QUALITY[-1]:
                        break  # this bound's floor is far above the target: the next, looser one
                    seen.append((quality_bound, len(t2)))
                    quality_bound = _next_bound(seen, target_tets)
                    if quality_bound is None:
                        if quality == _TETGEN_RELAXED_QUALITY[-1]:
                            # The loosest bound's floor is above the target (parts thinner
                            # than the spacing): the count nearest it is the floor itself.
                            v2, t2 = mesh_once(8.0 * max(b for b, _ in seen), quality)
                            if miss_of(t2) < miss_of(t):
                                v, t, bound = v2, t2, 8.0 * max(b for b, _ in seen)
                        break
                if miss_of(t) <= tolerance:
                    break
    tet_volume = signed_volumes(v, t)
    dihedral = dihedral_angles_deg(v, t).min(axis=1)
    return TetMesh(
        vertices=v,
        tets=t.astype(np.int32),
        backend=backend,
        max_volume=bound,
        surface_volume=volume,
        volume_error=float(tet_volume.sum() / volume - 1.0),
        min_dihedral_deg=float(dihedral.min()),
        sliver_count=int(np.sum(dihedral < 5.0)),
        runs=runs,
        seconds=time.perf_counter() - start,
    )
