"""Source (file, primitive spec or mesh) -> checked surface -> tets -> BodyModel.

The tet mesh is cached on disk under ``runtime.cache_dir()/tets`` keyed by a SHA-256 of the
surface's vertex and face bytes, the mesher settings and :data:`CACHE_VERSION`, so the same
object in a second run (or thirteen identical rings in one scene) is meshed once. The
BodyModel itself is rebuilt from the cached tets (0.3 s for 70,000 tets): it depends on
density and grouping options that change more often than the shape.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from ..model import BodyModel, build_body_model
from ..options import Material, ParticleOptions, material_preset
from .bounded import DEFAULT_PREPARE_SECONDS, StepClock, StepShareExceeded
from .meshio_in import (check_or_repair, check_up_axis, file_up_axis, is_tet_file, load_raw_surface, load_surface, load_tet_mesh,
                        to_z_up, unit_scale)
from .primitives import make_primitive, parse_primitive_spec
from .simplify import deviation_points, simplified_tet_surfaces, surface_deviation
from .tetra import BACKENDS, TetMesh, regular_tet_edge, tetrahedralize
from .topology import boundary_faces, dihedral_angles_deg, signed_volumes
from .validate import MeshError

#: Bump when meshing changes so old cache entries are not reused.
CACHE_VERSION = 4

#: A primitive's surface edge = this x the edge of a regular tet of the target particle
#: volume. Finer surfaces push the tet count above the target (the surface alone forces
#: tets); 1.3 lands tetgen within a few % of the target on tori, boxes and spheres.
PRIMITIVE_EDGE_FACTOR = 1.3


@dataclass
class PrepareReport:
    """What preparing one body did and measured (the `info` command prints this).

    Counts are the paper's Table 1 columns; volumes [m^3], mass [kg], lengths [m],
    inertia [kg m^2] about the centre of mass in the source axes, timings [s].
    """

    source: str
    physics_particles: int
    surface_particles: int
    boundary_particles: int
    dropped_surface_particles: int
    tets: int
    surface_triangles: int
    surface_volume: float
    tet_volume: float
    volume_error: float
    min_dihedral_deg: float
    sliver_count: int
    mass: float
    center_of_mass: list
    inertia: list
    backend: str
    cache_hit: bool
    repair_steps: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    # The artist's solid at full input resolution (None for tet-mesh files): closed,
    # manifold, outward, in metres in the source frame (the frame of the BodyModel's
    # com_in_source); its outer triangles are the input's own (split only where shells cross
    # or holes were closed), with the input's UVs (per vertex, and exactly per corner in
    # ``surface.metadata["corner_uvs"]`` (F,3,2)) where it had them. The tets fill
    # ``tet_surface`` (None: this surface itself). Not part of the printed report.
    surface: object = field(default=None, repr=False, compare=False)
    tet_surface: object = field(default=None, repr=False, compare=False)
    #: Triangles of the surface the tets fill (differs from surface_triangles when simplified).
    tet_surface_triangles: int = -1
    #: Fraction of the input's generalized winding-number volume inside the repaired solid
    #: (None without repair: the input itself is the solid).
    kept_volume_fraction: float | None = None
    #: Volume of the input's winding-number solid [m^3] (None without repair).
    input_volume: float | None = None
    #: Bounding-box sizes (3,) [m] of the input and of the simulated tets.
    input_extents: list = field(default_factory=list)
    tet_extents: list = field(default_factory=list)
    #: Whether ``surface`` is closed at full resolution (False: the best surface there was).
    surface_closed: bool = True
    #: Largest distance [m] from a point of ``surface`` (its vertices, at most 50,000) to the
    #: tets' boundary: how far the simulated solid strays from the artist's (None for
    #: tet-mesh files).
    surface_deviation: float | None = None
    #: The up axis of the source file's coordinates ("z": as it is; "y": turned Z up).
    up_axis: str = "z"
    #: [m] the mean V^(1/3) of the tets (``BodyModel.spacing``): the unit of the SPH smoothing
    #: length, the crack roughness and the piece-geometry measures. A regular tet of that
    #: volume has edges about 2.04 times as long.
    particle_spacing: float = float("nan")

    def as_dict(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k not in ("surface", "tet_surface")}


def _surface_from_source(source, factor: float, repair: bool, edge_length_for, clock: StepClock,
                         up_axis: str = "z", checked: bool = True):
    """Returns (name, trimesh surface in metres, is_primitive) for a path, primitive spec or
    Trimesh; a mesh's repair report is in ``surface.metadata["repair_report"]``. With
    ``checked`` False a mesh is returned unchecked (``input_solid`` decides what it becomes)."""
    if isinstance(source, trimesh.Trimesh):
        mesh = to_z_up(source.copy(), up_axis)
        mesh.apply_scale(factor)
        if not checked:
            return "mesh", mesh, False
        return "mesh", check_or_repair(mesh, "mesh", repair=repair, clock=clock), False
    spec = str(source)
    parsed = parse_primitive_spec(spec) if not os.path.exists(spec) else None
    if parsed is not None:
        name, params = parsed
        # The smooth solid's volume fixes the target tet size, which fixes the facet size.
        volume = make_primitive(name, params).volume * factor**3
        mesh = make_primitive(name, params, edge_length=edge_length_for(volume) / factor)
        mesh.apply_scale(factor)
        return spec, mesh, True
    if not checked:
        return Path(spec).name, load_raw_surface(spec, scale=factor, up_axis=up_axis, clock=clock), False
    return Path(spec).name, load_surface(spec, scale=factor, repair=repair, clock=clock, up_axis=up_axis), False


def _volume_of(mesh: trimesh.Trimesh) -> float:
    """The volume [m^3] of ``mesh``'s winding-number solid (coarse; for a volume bound's count)."""
    from .winding_solid import estimate_volume, usable_faces

    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    return max(estimate_volume(vertices, usable_faces(vertices, mesh.faces)), 1e-300)


def _cache_key(mesh: trimesh.Trimesh, backend: str, target: int | None, max_volume: float | None,
               min_dihedral: float, relax_quality: bool = False) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    settings = (CACHE_VERSION, backend, target, max_volume, float(min_dihedral))
    h.update(repr(settings + ((True,) if relax_quality else ())).encode())
    return h.hexdigest()


def _cache_root() -> Path:
    """``runtime.cache_dir()``; importing runtime imports Taichi, whose banner goes to stdout
    and would corrupt ``info --json``, so it is sent to stderr."""
    with contextlib.redirect_stdout(sys.stderr):
        from .. import runtime
    return runtime.cache_dir()


#: Share of the time left that TetGen gets before the fTetWild fallback takes over.
TETGEN_TIME_SHARE = 0.2


def _mesh_with_fallback(mesh, kwargs: dict, clock, backend: str, notes: list | None, fallback_on_refusal: bool):
    """``tetrahedralize`` under ``clock``; with TetGen, when it crashes, hangs past
    :data:`TETGEN_TIME_SHARE` of the time left (TetGen loops on some unions of many shells,
    e.g. the 33-piece beetle) or (``fallback_on_refusal``) refuses the surface, the surface is
    meshed with fTetWild (``wildmeshing``) in the time left, and ``notes`` gets a line."""
    if clock is None:
        return tetrahedralize(mesh, **kwargs)
    step = f"tetrahedralize ({backend})"
    if backend != "tetgen" or notes is None or "wildmeshing" not in BACKENDS:
        return clock.run(step, tetrahedralize, mesh, **kwargs)
    left = clock.remaining()
    try:
        return clock.run_within(step, None if left is None else TETGEN_TIME_SHARE * left, tetrahedralize, mesh,
                                **kwargs)
    except StepShareExceeded as exc:
        reason = f"TetGen ran past its share of the time bound ({TETGEN_TIME_SHARE * left:.1f} s)"
        cause = exc
    except MeshError as exc:
        if "ran out of time" in str(exc):
            raise
        crashed = "crashed" in str(exc)
        if not (crashed or fallback_on_refusal):
            raise
        reason = "TetGen crashed" if crashed else f"TetGen refused the surface ({exc})"
        cause = exc
    fallback = dict(kwargs, backend="wildmeshing", relax_quality=False)
    try:
        tm = clock.run("tetrahedralize (wildmeshing fallback)", tetrahedralize, mesh, **fallback)
    except MeshError as exc:
        raise MeshError(f"{exc} (after: {reason})") from cause
    notes.append(f"meshed with fTetWild (wildmeshing) instead: {reason}")
    return tm


def _cached_tetrahedralize(mesh, *, backend, target, max_volume, min_dihedral, use_cache, clock=None,
                           relax_quality=False, notes=None, fallback_on_refusal=True):
    """Returns (TetMesh, cache_hit); the mesher runs under ``clock``'s bound when given, with
    the fTetWild fallback of :func:`_mesh_with_fallback` when ``notes`` is a list."""
    key = _cache_key(mesh, backend, target, max_volume, min_dihedral, relax_quality)
    path = _cache_root() / "tets" / f"{key}.npz"
    if use_cache and path.exists():
        try:
            with np.load(path) as data:
                meta = data["meta"]
                used = str(data["backend"]) if "backend" in data.files else backend
                if used != backend and notes is not None:
                    notes.append(f"meshed with fTetWild ({used}) instead of {backend} (cached)")
                return TetMesh(
                    vertices=data["vertices"], tets=data["tets"], backend=used,
                    max_volume=None if np.isnan(meta[0]) else float(meta[0]), surface_volume=float(meta[1]),
                    volume_error=float(meta[2]), min_dihedral_deg=float(meta[3]), sliver_count=int(meta[4]),
                    runs=0, seconds=0.0,
                ), True
        except (OSError, KeyError, ValueError):
            pass  # a corrupt or old entry: re-mesh and overwrite it
    kwargs = dict(target_tets=target, max_volume=max_volume, backend=backend, min_dihedral_deg=min_dihedral,
                  relax_quality=relax_quality)
    tm = _mesh_with_fallback(mesh, kwargs, clock, backend, notes, fallback_on_refusal)
    if use_cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
        meta = np.array([np.nan if tm.max_volume is None else tm.max_volume, tm.surface_volume,
                         tm.volume_error, tm.min_dihedral_deg, tm.sliver_count])
        extra = {} if tm.backend == backend else {"backend": np.array(tm.backend)}
        np.savez(tmp, vertices=tm.vertices, tets=tm.tets, meta=meta, **extra)
        os.replace(tmp, path)  # atomic: a parallel run never reads half a file
    return tm, False


def _cleaned_copy(copy: trimesh.Trimesh, clock: StepClock):
    """``copy`` through MeshFix (degenerate spots, crossings), or None if that loses more
    than 0.5 % of its volume or leaves it open."""
    from .repair import _meshfix

    v, f = clock.run("clean copy (pymeshfix)", _meshfix, copy.vertices, copy.faces)
    cleaned = trimesh.Trimesh(v, f, process=True)
    if not (cleaned.is_watertight and cleaned.is_winding_consistent) or abs(cleaned.volume / copy.volume - 1) > 0.005:
        return None
    return cleaned


def _mesh_simplified(surface, count: int, clock: StepClock, kwargs: dict):
    """Tets of the simplified copies of ``surface`` (``simplify.simplified_tet_surfaces``),
    keeping the copy whose count is nearest ``count``. Returns (tet surface, TetMesh or None,
    cache_hit, report line or None); (surface, None, False, ...) when no copy applies or the
    mesher refused them all (the caller then meshes the full surface)."""
    copies = simplified_tet_surfaces(surface, count, clock)
    # A copy's count matters more than its last degree; a TetGen refusal of a copy is first
    # answered by cleaning the copy (faster than the fTetWild fallback), so only the second
    # try falls back.
    kwargs = dict(kwargs, relax_quality=True, fallback_on_refusal=False)
    best, failed, tets, started = None, None, None, False
    while True:
        try:
            copy, step = copies.send(tets) if started else next(copies)
            started = True
        except StopIteration:
            break
        try:
            candidate, hit = _cached_tetrahedralize(copy, **kwargs)
        except MeshError as exc:
            if "ran out of time" in str(exc):
                raise
            # TetGen refuses some copies (near-degenerate spots): MeshFix cleans them, and if
            # TetGen still refuses, a coarser copy is tried.
            copy = _cleaned_copy(copy, clock)
            try:
                candidate, hit = (_cached_tetrahedralize(copy, **dict(kwargs, fallback_on_refusal=True))
                                  if copy is not None else (None, False))
            except MeshError as again:
                if "ran out of time" in str(again):
                    raise
                candidate = None
            if candidate is None:
                failed, tets = str(exc), 10 * count
                continue
            step += "; cleaned by pymeshfix for the mesher"
        if best is None or abs(candidate.tet_count / count - 1) < abs(best[1].tet_count / count - 1):
            best = (copy, candidate, hit, step)
        tets = candidate.tet_count
    if best is not None:
        return best
    if failed is not None:
        return surface, None, False, f"meshed the full-resolution surface: the mesher refused the simplified copy ({failed})"
    return surface, None, False, None


def _mesh_surface(surface, count: int, kwargs: dict, clock: StepClock, simplify: bool = True):
    """(tet surface, TetMesh, cache hit, step or None) of a clean ``surface`` under ``clock``:
    its simplified copy when ``simplify``, else (or when no copy applies) the surface itself."""
    kwargs = dict(kwargs, clock=clock)
    tet_surface, tm, hit, step = surface, None, False, None
    if simplify:
        tet_surface, tm, hit, step = _mesh_simplified(surface, count, clock, kwargs)
    if tm is None:
        tm, hit = _cached_tetrahedralize(surface, **kwargs)
    return tet_surface, tm, hit, step


def prepare_body(
    source,
    *,
    scale: float = 1.0,
    units: str = "m",
    material: Material | str = "porcelain",
    particles: ParticleOptions | None = None,
    repair: bool = False,
    max_volume: float | None = None,
    backend: str = "tetgen",
    use_cache: bool = True,
    time_limit: float | None = DEFAULT_PREPARE_SECONDS,
    simplify: bool = True,
    thickness: float | None = None,
    up_axis: str = "z",
    surface_contact: bool = False,
) -> tuple[BodyModel, PrepareReport]:
    """Build the two-scale model of one solid.

    Args:
        source: a surface file (OBJ/STL/PLY/OFF/glTF/GLB), a tet-mesh file (.msh/.vtk/.vtu/
            .mesh, used as is), a primitive spec ("torus", "box:x=1,y=1,z=0.01", ...) or a
            closed ``trimesh.Trimesh``.
        scale, units: size of the source's coordinates (metres = value x scale x unit).
        material: a Material or a preset name (density is what matters here).
        particles: target count, boundary group size, leftovers, quality bound.
        repair: a mesh that is not a clean solid (open, a soup, overlapping or crossing
            shells, non-manifold, degenerate) becomes one: repaired into a closed solid of
            its own triangles where that works, else the solid of its generalized winding
            number (``input_solid``; the steps are in ``PrepareReport.repair_steps``).
            False: such a mesh is an error saying what is wrong.
        max_volume: mesh with this tet volume bound [m^3] instead of a target count.
        backend: tet mesher ("tetgen" or "wildmeshing").
        use_cache: read and write the on-disk tet cache.
        time_limit: wall-clock bound [s] on loading, checking, repairing, simplifying and
            meshing a surface (None: unbounded); running out is a MeshError naming the step.
        simplify: mesh a copy of a surface finer than the target's particle spacing,
            decimated to that spacing (``simplify.simplify_for_target``); primitives are
            built at that spacing already and never simplified.
        thickness: [m] a shell this thick about the surface joins the solid: an open sheet (a
            pane, a leaf) becomes a closed one (``winding_solid``). None: a surface with no
            volume is an error.
        up_axis: "z" or "y": the up axis of an OBJ/STL/PLY/OFF source's (or a Trimesh's)
            coordinates; Y up is turned Z up. glTF/GLB are Y-up by their specification.
        surface_contact: the body will collide through its true surface: it is grouped by
            ``particles.surface_group_size`` when large enough (``model.group_sizes``).

    Returns (BodyModel in its body frame, PrepareReport).
    """
    particles = particles or ParticleOptions()
    if isinstance(material, str):
        material = material_preset(material)
    factor = unit_scale(scale, units)
    timings = {}
    t0 = time.perf_counter()
    cache_hit = False
    solid = None  # what input_solid built (meshes with repair or a thickness)
    repair_steps: list[str] = []
    if not isinstance(source, trimesh.Trimesh) and is_tet_file(str(source)):
        name = Path(str(source)).name
        vertices, tets = load_tet_mesh(source, scale=scale, units=units)
        timings["load"] = time.perf_counter() - t0
        vol = np.abs(signed_volumes(vertices, tets))
        # The source tet mesh's own boundary is the reference surface: its enclosed volume
        # is the tets' volume, so volume_error measures only inverted/overlapping tets.
        tm = TetMesh(vertices=vertices, tets=tets.astype(np.int32), backend="file", max_volume=None,
                     surface_volume=float(vol.sum()), volume_error=0.0,
                     min_dihedral_deg=float(dihedral_angles_deg(vertices, tets).min()),
                     sliver_count=int(np.sum(dihedral_angles_deg(vertices, tets).min(axis=1) < 5.0)),
                     runs=0, seconds=0.0)
        surface_triangles = -1
        surface = None
        tet_surface = None
        repair_report = None
        timings["mesh"] = 0.0
    else:
        target = None if max_volume is not None else particles.target_particles
        mesher_notes: list[str] = []
        def edge_for(volume):
            return PRIMITIVE_EDGE_FACTOR * regular_tet_edge(volume / (target or max(volume / max_volume, 1.0)))
        clock = StepClock(name=Path(str(source)).name if not isinstance(source, trimesh.Trimesh) else "mesh",
                          seconds=time_limit)
        check_up_axis(up_axis)
        # With repair or a thickness a mesh goes to input_solid, which decides: the mesh as it
        # is when clean, else the solid of its winding number.
        lenient = bool(repair or thickness is not None) and not (
            isinstance(source, str) and parse_primitive_spec(source) is not None and not os.path.exists(source))
        name, surface, is_primitive = _surface_from_source(source, factor, repair, edge_for, clock, up_axis,
                                                           checked=not lenient)
        repair_steps = list(surface.metadata.get("repair", []))
        repair_report = surface.metadata.get("repair_report")
        surface_triangles = len(surface.faces)
        timings["load"] = time.perf_counter() - t0
        t1 = time.perf_counter()
        kwargs = dict(backend=backend, target=target, max_volume=max_volume,
                      min_dihedral=particles.min_dihedral_deg, use_cache=use_cache, clock=clock,
                      notes=mesher_notes)
        tet_surface, tm, cache_hit = surface, None, False
        if lenient:
            from .input_solid import solid_of_input

            count = target if target is not None else max(int(_volume_of(surface) / max_volume), 1)
            solid = solid_of_input(surface, name, count=count, kwargs=kwargs, clock=clock, thickness=thickness,
                                   mesh_surface=functools.partial(_mesh_surface, simplify=simplify),
                                   check_count=target is not None)
            surface, tet_surface, tm, cache_hit = solid.surface, solid.tet_surface, solid.tets, solid.cache_hit
            repair_steps = list(solid.steps)
        elif simplify and not is_primitive:
            # The tets' spacing: the target count, or the count a volume bound asks for.
            count = target if target is not None else max(int(surface.volume / max_volume), 1)
            tet_surface, tm, cache_hit, step = _mesh_simplified(surface, count, clock, kwargs)
            if step:
                repair_steps.append(step)
        if tm is None:
            tm, cache_hit = _cached_tetrahedralize(surface, **kwargs)
        repair_steps.extend(mesher_notes)
        timings["mesh"] = time.perf_counter() - t1
        timings.update({f"step: {k}": v for k, v in clock.step_seconds.items()})
    t2 = time.perf_counter()
    try:
        model = build_body_model(tm.vertices, tm.tets, material.density,
                                 boundary_group_size=particles.boundary_group_size,
                                 keep_leftovers=particles.keep_leftovers,
                                 coarse_group_size=particles.surface_group_size if surface_contact else 0)
    except ValueError as exc:
        raise MeshError(f"{name!r}: cannot build a particle model from its tets: {exc}") from exc
    timings["model"] = time.perf_counter() - t2
    deviation = None
    if surface is not None:
        # Measured on the tets themselves, so a part lost anywhere (decimation, the mesher)
        # shows as a distance of the order of that part's length.
        deviation = surface_deviation(deviation_points(surface), tm.vertices, boundary_faces(tm.tets)[0])
    # The simulated solid is measured against the artist's full-resolution surface.
    reference_volume = float(surface.volume) if surface is not None else tm.surface_volume
    extents = np.ptp(tm.vertices, axis=0)
    timings["total"] = time.perf_counter() - t0
    report = PrepareReport(
        source=name,
        physics_particles=model.tet_count,
        surface_particles=model.surface_particle_count,
        boundary_particles=model.boundary_particle_count,
        dropped_surface_particles=len(model.dropped_surface_particles),
        tets=model.tet_count,
        surface_triangles=surface_triangles,
        surface_volume=reference_volume,
        tet_volume=model.volume,
        volume_error=float(model.volume / reference_volume - 1.0),
        min_dihedral_deg=tm.min_dihedral_deg,
        sliver_count=tm.sliver_count,
        mass=model.mass,
        center_of_mass=model.com_in_source.tolist(),
        inertia=model.inertia.tolist(),
        backend=tm.backend,
        cache_hit=cache_hit,
        repair_steps=repair_steps,
        timings=timings,
        surface=surface,
        tet_surface=None if tet_surface is surface else tet_surface,
        tet_surface_triangles=-1 if surface is None else len(tet_surface.faces),
        kept_volume_fraction=(solid.kept_fraction if solid is not None else
                              None if repair_report is None else repair_report.kept_fraction),
        input_volume=(solid.input_volume if solid is not None else
                      None if repair_report is None else repair_report.input_volume),
        input_extents=(list(solid.input_extents) if solid is not None else
                       list(repair_report.input_extents) if repair_report is not None and repair_report.input_extents
                       else (surface.extents.tolist() if surface is not None else extents.tolist())),
        tet_extents=extents.tolist(),
        surface_closed=surface is None or bool(surface.is_watertight and surface.is_winding_consistent),
        surface_deviation=deviation,
        particle_spacing=model.spacing,
        up_axis=(file_up_axis(str(source), up_axis) if not isinstance(source, trimesh.Trimesh) and surface is not None
                 else up_axis),
    )
    return model, report
