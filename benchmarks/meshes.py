"""``taichi-frac bench meshes``: artists' meshes in, at the requested resolution, whole.

For every surface file of a folder (``TAICHI_FRAC_SHARED_MESHES``, default ../shared/meshes,
the public test meshes beside the checkout) and three
generated stress cases (a 1.3M-face noisy sphere, a sphere with 1,000 random holes, four
overlapping closed shells), scaled to 0.3 m across: faces in, particles out against the
target, the volume and extents the solid keeps, how far its surface strays from the input's,
the preparation's time (repair on), then a 1-second drop onto the ground with fracture
(ms/frame, fragments, mass kept) written as a USD cache that is read back (the meshes a
Blender import would get, and USD's own validators' findings).
Each row ends with a verdict against the targets: particles within 15 % of the target,
at least 98 % of the input's winding-number solid kept, extents within 2 %, prepared within
30 s, and a drop that breaks; the page ends with "N of M ran" and the median and largest
preparation time.
A second table times the checks alone on the 1.3M-face sphere (the bound: 5 s for a million faces).
Writes docs/benchmarks/meshes.md (``--out``: elsewhere).
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np
import trimesh

from .common import REPO, BenchContext, Section, load_average, machine_info, md_table

#: Size the meshes are scaled to: bounding-box diagonal [m].
DIAGONAL = 0.3
TARGET = 5000
QUICK_TARGET = 1500
#: [m/s] straight down, from just above the ground (a fall of about 11 m). At 10 m/s Suzanne
#: stays below the strength with some of her tet meshes (0 fragments; 4 at 12.5 and 15 m/s).
DROP_SPEED = 15.0
#: The drop's material and cracks: porcelain whose cracks run across the whole solid
#: (crack_length = its diagonal), three crack planes an analysis point, pieces under 30
#: particles merged. With the default crack length (only as far as the stress exceeds the
#: strength) a 0.3 m solid at 10 m/s cracks near the contact only: 0-2 pieces.
DROP_MATERIAL = "porcelain"
DROP_CRACK_COUNT = 3
DROP_MIN_FRAGMENT_PARTICLES = 30
#: The preparation's time bound here [s]: the default a user gets.
TIME_LIMIT = 60.0
#: The verdict's bounds: particle count miss, kept share, extents miss, prepare time [s].
COUNT_TOLERANCE = 0.15
MIN_KEPT = 0.98
EXTENTS_TOLERANCE = 0.02
MAX_PREPARE_SECONDS = 30.0
#: Surface files the folder's meshes are read from.
SURFACE_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


def shared_meshes_dir() -> Path:
    """../shared/meshes beside the checkout (or beside its parent folder, for a worktree);
    ``TAICHI_FRAC_SHARED_MESHES`` overrides. May not exist."""
    env = os.environ.get("TAICHI_FRAC_SHARED_MESHES")
    if env:
        return Path(env)
    for base in (REPO.parent, REPO.parent.parent):
        if (base / "shared" / "meshes").is_dir():
            return base / "shared" / "meshes"
    return REPO.parent / "shared" / "meshes"


def noisy_sphere(subdivisions: int = 8, radius: float = 1.0, noise: float = 2e-4, seed: int = 0) -> trimesh.Trimesh:
    """An icosphere (20 x 4^subdivisions faces: 1,310,720 at 8) with radial noise of
    ``noise`` x radius, a scan-like dense surface."""
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    rng = np.random.default_rng(seed)
    sphere.vertices = sphere.vertices * (1.0 + noise * rng.standard_normal(len(sphere.vertices)))[:, None]
    return sphere


def holey_sphere(holes: int = 1000, subdivisions: int = 6, seed: int = 1) -> trimesh.Trimesh:
    """An icosphere (81,920 faces) with ``holes`` faces removed at random, no two sharing an
    edge (so 1,000 separate holes)."""
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    rng = np.random.default_rng(seed)
    neighbours = sphere.face_adjacency
    blocked = np.zeros(len(sphere.faces), dtype=bool)
    removed = []
    for face in rng.permutation(len(sphere.faces)):
        if not blocked[face]:
            removed.append(face)
            blocked[face] = True
            blocked[neighbours[(neighbours == face).any(axis=1)].reshape(-1)] = True
        if len(removed) == holes:
            break
    keep = np.setdiff1d(np.arange(len(sphere.faces)), removed)
    return trimesh.Trimesh(sphere.vertices, sphere.faces[keep], process=False)


def overlapping_shells() -> trimesh.Trimesh:
    """Three spheres and a box, closed, overlapping: one mesh of four shells."""
    parts = []
    for k, centre in enumerate([(0.0, 0.0, 0.0), (0.7, 0.0, 0.0), (0.35, 0.6, 0.0)]):
        s = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
        s.apply_translation(centre)
        parts.append(s)
    box = trimesh.creation.box((1.6, 0.3, 0.3))
    box.apply_translation((0.35, 0.2, 0.3))
    parts.append(box)
    return trimesh.util.concatenate(parts)


def _cases(quick: bool):
    shared = shared_meshes_dir()
    cases = ([(p.stem, p) for p in sorted(shared.iterdir()) if p.suffix.lower() in SURFACE_SUFFIXES]
             if shared.is_dir() else [])
    cases += [("noisy sphere", noisy_sphere(6 if quick else 8)), ("1,000 holes", holey_sphere(100 if quick else 1000)),
              ("overlapping shells", overlapping_shells())]
    return cases


def _scale_for(source) -> float:
    from taichi_frac.geometry.meshio_in import read_surface

    mesh = source if isinstance(source, trimesh.Trimesh) else read_surface(source)
    return DIAGONAL / float(np.linalg.norm(mesh.extents))


def _prepare_row(name, source, target: int, out: Path):
    from taichi_frac.geometry.meshio_in import read_surface
    from taichi_frac.geometry.prepare import prepare_body
    from taichi_frac.geometry.validate import MeshError
    from taichi_frac.options import ParticleOptions

    faces_in = len((source if isinstance(source, trimesh.Trimesh) else read_surface(source)).faces)
    scale = _scale_for(source)
    t0 = time.perf_counter()
    try:
        model, report = prepare_body(source, scale=scale, repair=True, particles=ParticleOptions(target_particles=target),
                                     use_cache=False, time_limit=TIME_LIMIT)
    except MeshError as exc:
        return dict(name=name, faces=faces_in, error=str(exc), seconds=time.perf_counter() - t0), None
    seconds = time.perf_counter() - t0
    # Again through the tet cache, so that the drop's own preparation (inside the
    # Simulation, under the default bound) reuses these tets instead of meshing again.
    try:
        prepare_body(source, scale=scale, repair=True, particles=ParticleOptions(target_particles=target),
                     time_limit=TIME_LIMIT)
    except MeshError as exc:  # the drop's own preparation will say so in the row
        cache_error = str(exc)
    else:
        cache_error = None
    path = source
    if isinstance(source, trimesh.Trimesh):
        path = out / f"{name.replace(' ', '_').replace(',', '')}.obj"
        path.parent.mkdir(parents=True, exist_ok=True)
        source.export(str(path))
    extents = np.array(report.tet_extents) / np.array(report.input_extents)
    from taichi_frac.geometry.simplify import tet_edge

    spacing = tet_edge(report.surface_volume, target)
    row = dict(deviation=report.surface_deviation / spacing, name=name, faces=faces_in, tet_faces=report.tet_surface_triangles, particles=report.physics_particles,
               target=target, volume_error=report.volume_error, kept=report.kept_volume_fraction,
               extents_min=float(extents.min()), extents_max=float(extents.max()), seconds=seconds,
               steps=report.timings, surface_closed=report.surface.is_watertight,
               input_extents=np.sort(np.asarray(report.input_extents, dtype=float)),
               surface_volume=report.surface_volume, mesher=report.backend)
    if cache_error is not None:
        row["cache_error"] = cache_error
    return row, (path, scale, report)


def _drop(ctx: BenchContext, name: str, path, scale: float, target: int, cache_dir: Path):
    from taichi_frac.options import FractureOptions, ParticleOptions
    from taichi_frac.scenes import Collider, Scene, SceneObject, SimulationOptions
    from taichi_frac.simulation import Simulation

    fps = 50
    height = 0.5 * DIAGONAL + 0.01
    fracture = FractureOptions(crack_length=DIAGONAL, crack_count=DROP_CRACK_COUNT,
                               min_fragment_particles=DROP_MIN_FRAGMENT_PARTICLES)
    scene = Scene(name=f"drop {name}", objects=[SceneObject(
        name="solid", mesh=str(path), scale=scale, repair=True, material=DROP_MATERIAL, position=(0.0, 0.0, height),
        linear_velocity=(0.0, 0.0, -DROP_SPEED), particles=ParticleOptions(target_particles=target),
        fracture=fracture)],
        colliders=[Collider(type="ground")], simulation=SimulationOptions(fps=fps, duration=1.0))
    cache_dir.mkdir(parents=True, exist_ok=True)
    cache = cache_dir / f"{name.replace(' ', '_').replace(',', '')}.usdc"
    sim = Simulation(scene, output=str(cache), world=ctx.world(), arch=ctx.arch)
    summary = sim.run()
    lost = abs(summary.mass_final + summary.mass_dropped - summary.mass_initial) / summary.mass_initial
    return dict(ms=summary.ms_per_frame["mean_after_first"] or summary.ms_per_frame["mean"],
                fragments=summary.fragments, mass_error=lost, dropped=summary.mass_dropped / summary.mass_initial,
                **_read_back(cache))


def _read_back(cache: Path) -> dict:
    """What an import into Blender reads from a written cache, without Blender: ``meshes``
    (fragment meshes with faces), ``issues`` (findings of USD's validators), ``extents`` (3,)
    [m] (the visible meshes' world box at the first frame, sorted: the whole solid as it
    renders before it breaks) and ``volume`` [m^3] (the enclosed volume of the meshes
    visible at the last frame: every piece's render surface)."""
    from pxr import Usd, UsdGeom

    from taichi_frac.io.cache import check_cache

    stage = Usd.Stage.Open(str(cache))
    metres = UsdGeom.GetStageMetersPerUnit(stage)
    meshes = [UsdGeom.Mesh(prim) for prim in stage.Traverse() if prim.IsA(UsdGeom.Mesh)
              and len(UsdGeom.Mesh(prim).GetFaceVertexCountsAttr().Get() or []) > 0]
    first = stage.GetStartTimeCode()
    box = UsdGeom.BBoxCache(first, [UsdGeom.Tokens.default_, UsdGeom.Tokens.render]).ComputeWorldBound(
        stage.GetPseudoRoot()).ComputeAlignedRange()
    extents = np.sort(np.array(box.GetSize()) * metres) if not box.IsEmpty() else np.zeros(3)
    last = stage.GetEndTimeCode()
    volume = 0.0
    for mesh in meshes:
        if mesh.ComputeVisibility(last) == UsdGeom.Tokens.invisible:
            continue
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(last))
        indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(last))
        points = np.asarray(mesh.GetPointsAttr().Get(last), dtype=np.float64) * metres
        if np.all(counts == 3):
            triangles = indices.reshape(-1, 3)
        else:  # fan-triangulate each polygon
            starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
            triangles = np.array([(indices[s], indices[s + k], indices[s + k + 1])
                                  for s, c in zip(starts, counts) for k in range(1, c - 1)])
        # (Rigid poses leave a closed mesh's volume as it is in its own frame.)
        volume += trimesh.Trimesh(points, triangles, process=False).volume
    return dict(meshes=len(meshes), issues=len(check_cache(cache)), extents=extents, volume=volume)


def _rendered(row: dict, drop: dict) -> str:
    box = drop["extents"] / row["input_extents"]
    return f"{box.min():.3f}-{box.max():.3f}, {100 * drop['volume'] / row['surface_volume']:.1f} %"


def _validation_timing(quick: bool):
    from taichi_frac.geometry.intersections import crossing_face_pairs
    from taichi_frac.geometry.validate import validate_surface

    sphere = noisy_sphere(6 if quick else 8)
    crossing_face_pairs(sphere.vertices[:6], np.array([[0, 1, 2], [3, 4, 5]]))  # compile outside the timing
    t0, c0 = time.perf_counter(), time.process_time()
    pairs = crossing_face_pairs(sphere.vertices, sphere.faces)
    t1, c1 = time.perf_counter(), time.process_time()
    validate_surface(sphere, "noisy sphere")
    t2 = time.perf_counter()
    return dict(faces=len(sphere.faces), pairs=len(pairs), crossing_wall=t1 - t0, crossing_cpu=c1 - c0,
                validate_wall=t2 - t1)


#: Icosphere subdivisions of the face-count scaling table (20,480 to 1,310,720 faces).
SCALING_SUBDIVISIONS = (5, 6, 7, 8)


def _scaling(quick: bool) -> list[dict]:
    """Preparation time of the noisy sphere at 4x the faces a step (repair on, the target's
    5,000 particles, no tet cache): whether it grows faster than the face count."""
    from taichi_frac.geometry.prepare import prepare_body
    from taichi_frac.options import ParticleOptions

    rows = []
    for subdivisions in SCALING_SUBDIVISIONS[:2] if quick else SCALING_SUBDIVISIONS:
        sphere = noisy_sphere(subdivisions, radius=0.5 * DIAGONAL / math.sqrt(3.0))
        t0 = time.perf_counter()
        _, report = prepare_body(sphere, repair=True, particles=ParticleOptions(target_particles=TARGET),
                                 use_cache=False, time_limit=TIME_LIMIT)
        rows.append(dict(faces=len(sphere.faces), seconds=time.perf_counter() - t0, particles=report.physics_particles,
                         mesher=report.backend))
    return rows


def run(ctx: BenchContext) -> Section:
    from taichi_frac.geometry.validate import MeshError

    target = QUICK_TARGET if ctx.quick else TARGET
    out = ctx.markdown_dir / "meshes_inputs"
    rows, drops = [], {}
    load_before = load_average()
    timing = _validation_timing(ctx.quick)
    ctx.progress(f"checks of {timing['faces']:,} faces: crossing pairs {timing['crossing_wall']:.1f} s, "
                 f"all checks {timing['validate_wall']:.1f} s")
    for name, source in _cases(ctx.quick):
        ctx.progress(f"{name}: preparing")
        row, prepared = _prepare_row(name, source, target, out)
        row["group"] = "generated" if isinstance(source, trimesh.Trimesh) else "folder"
        rows.append(row)
        if prepared is None:
            ctx.progress(f"{name}: {row['error']}")
            continue
        ctx.progress(f"{name}: {row['particles']:,} particles in {row['seconds']:.1f} s; dropping")
        path, scale, _ = prepared
        try:
            drops[name] = _drop(ctx, name, path, scale, target, out / "caches")
        except Exception as exc:  # noqa: BLE001 - any failure of the drop is this row's finding, not the end of the run
            row["drop_error"] = f"{type(exc).__name__}: {exc}" if not isinstance(exc, MeshError) else str(exc)
            ctx.progress(f"{name}: drop not run: {exc}")
            _write(ctx, _markdown(rows, drops, timing, target, load_before))
            continue
        ctx.progress(f"{name}: {drops[name]['ms']:.1f} ms/frame, {drops[name]['fragments']} fragments, "
                     f"{drops[name]['meshes']} meshes read back")
        _write(ctx, _markdown(rows, drops, timing, target, load_before))  # what is done so far survives
    scaling = _scaling(ctx.quick)
    ctx.progress("face-count scaling: " + ", ".join(f"{r['faces']:,} faces {r['seconds']:.1f} s" for r in scaling))
    markdown = _markdown(rows, drops, timing, target, load_before, scaling, sheet=not ctx.quick)
    _write(ctx, markdown)
    return Section(key="meshes", title=TITLE, markdown=markdown)


TITLE = "Artists' meshes: resolution, every part kept, bounded time"


#: The contact sheet of the folder's drops (rendered from this run's caches by
#: scripts/render_mesh_drops.py --all), linked when it is there.
CONTACT_SHEET_TEXT = ("The folder's drops, whole at frame 1 and in pieces at frame 8, each frame framed on its own "
                      "pieces (`scripts/render_mesh_drops.py --all -o docs/benchmarks/meshes_drops.jpg` on this run's "
                      "caches; Blender, 320x240, 6 samples a tile):\n\n"
                      "![every mesh of the folder dropped, whole and broken](meshes_drops.jpg)")


def _write(ctx: BenchContext, markdown: str) -> None:
    docs = ctx.markdown_dir if ctx.quick else REPO / "docs" / "benchmarks"
    docs.mkdir(parents=True, exist_ok=True)
    (docs / "meshes.md").write_text(f"# {TITLE}\n\n{markdown}\n")


def verdict(row: dict, drop: dict | None, target: int) -> str:
    """One line: "ok", or each bound the row misses (see the module docstring)."""
    if "error" in row:
        return "did not run"
    misses = []
    if abs(row["particles"] / target - 1) > COUNT_TOLERANCE:
        misses.append(f"particles {row['particles'] / target - 1:+.0%}")
    if row["kept"] is not None and row["kept"] < MIN_KEPT:
        misses.append(f"kept {100 * row['kept']:.1f} %")
    if max(abs(row["extents_min"] - 1), abs(row["extents_max"] - 1)) > EXTENTS_TOLERANCE:
        misses.append("extents off")
    if row["seconds"] > MAX_PREPARE_SECONDS:
        misses.append(f"prepare {row['seconds']:.0f} s")
    if drop is None:
        misses.append("no drop")
    elif drop["fragments"] < 2:
        misses.append("drop did not break")
    return "ok" if not misses else "misses: " + ", ".join(misses)


def summary(rows, group: str) -> str:
    """ "N of M ran, median and max prepare time" over the rows of ``group``."""
    mine = [r for r in rows if r.get("group") == group]
    ran = [r for r in mine if "error" not in r]
    if not mine:
        return f"{group}: none"
    times = np.array([r["seconds"] for r in ran]) if ran else np.zeros(1)
    return (f"{group}: {len(ran)} of {len(mine)} ran; prepare median {np.median(times):.1f} s, "
            f"max {times.max():.1f} s")


def _markdown(rows, drops, timing, target, load_before, scaling=(), sheet: bool = False) -> str:
    m = machine_info()
    table_rows = []
    for r in rows:
        d = drops.get(r["name"])
        if "error" in r:
            table_rows.append([r["name"], f"{r['faces']:,}", "-", "-", "-", "-", "-", "-", f"{r['seconds']:.1f}",
                               "-", "-", "-", "-", "-", "-", "did not run", f"error: {r['error'][:120]}"])
            continue
        table_rows.append([
            r["name"], f"{r['faces']:,}", f"{r['tet_faces']:,}", f"{r['particles']:,} ({r['particles'] / target - 1:+.0%})",
            f"{r['volume_error']:+.2e}", "-" if r["kept"] is None else f"{100 * r['kept']:.1f} %",
            f"{r['extents_min']:.3f}-{r['extents_max']:.3f}", f"{r['deviation']:.2f}", f"{r['seconds']:.1f}",
            f"{d['ms']:.1f}" if d else "-", f"{d['fragments']}" if d else "-",
            f"{d['mass_error']:.1e}" if d else "-", f"{d['meshes']} ({d['issues']})" if d else "-",
            _rendered(r, d) if d else "-", r["mesher"], verdict(r, d, target),
            ("" if r["surface_closed"] else "surface not closed; ")
            + (f"drop: {r['drop_error'][:160]}" if "drop_error" in r else "")])
    table = md_table(["mesh", "faces in", "tet surface", f"particles (target {target:,})", "volume error",
                      "kept (winding no.)", "extents kept", "deviation [tet edges]", "prepare [s]", "drop ms/frame",
                      "fragments", "mass error", "cache read back", "rendered: box, volume", "tets from", "verdict",
                      "note"], table_rows, align="lrrrrrrrrrrrrrlll")
    check = md_table(["faces", "crossing pairs found", "crossing check wall [s]", "its main-thread CPU [s]",
                      "all checks wall [s]"],
                     [[f"{timing['faces']:,}", timing["pairs"], f"{timing['crossing_wall']:.2f}",
                       f"{timing['crossing_cpu']:.2f}", f"{timing['validate_wall']:.2f}"]])
    return "\n\n".join([
        f"Generated by `taichi-frac bench meshes` on {m.get('cpu', 'this machine')} "
        f"({m.get('cores', '?')} cores; load average {load_before} at the start: other jobs shared the cores, "
        "so wall times are upper bounds). Each mesh is scaled to 0.3 m across and prepared with repair on "
        f"(`prepare_body(repair=True, time_limit={TIME_LIMIT:.0f})`, no tet cache), then dropped at {DROP_SPEED:.0f} m/s onto "
        f"the ground for 1 s (50 frames) with fracture: {DROP_MATERIAL}, cracks as long as the solid ({DIAGONAL} m), "
        f"{DROP_CRACK_COUNT} crack planes an analysis point, pieces under {DROP_MIN_FRAGMENT_PARTICLES} particles merged. "
        "*Volume error*: simulated tets against the full-resolution solid; *kept*: "
        "the fraction of the input's generalized winding-number solid inside the simulated tets (random points "
        "of the input's box until 20,000 lie in the solid: a standard error of about 0.1 %); *extents kept*: the "
        "tets' bounding box over the input's, "
        "smallest and largest axis; *deviation*: the farthest point of the input's surface from the "
        "simulated solid's, in tet edges (the edge of a regular tet of the target's particle volume, about 2.04 particle spacings); "
        "*mass error*: |final + dropped debris - initial| / initial; *cache read back*: the drop's USD cache "
        "opened again: fragment meshes with faces (findings of USD's validators); *rendered*: in that cache, the "
        "visible meshes' box at the first frame over the input's box (axes sorted; smallest and largest ratio), and "
        "the volume the meshes visible at the last frame enclose over the full-resolution solid's (every piece's "
        "render surface: off where a piece's surface is not its tets' volume, see the piece-geometry section).",
        table,
        "**" + summary(rows, "folder") + "**; " + summary(rows, "generated") + ". *Tets from*: `tetgen`, the clean "
        "input meshed as it is; `lattice`, the input's winding-number solid (a cube lattice fitted to its contour). "
        "*Verdict*: particles within 15 % of the target, kept >= 98 %, extents within 2 %, prepared in 30 s or "
        "less, a drop that breaks (2 or more fragments).",
        CONTACT_SHEET_TEXT if sheet and (REPO / "docs" / "benchmarks" / "meshes_drops.jpg").exists() else "",
        ("Preparation time against the face count: the noisy sphere (a 0.3 m icosphere, radial noise 2e-4) at "
         "4x the faces a step, repair on, the same target, no tet cache (time per face flat or falling: linear "
         "or better):\n\n" + md_table(["faces", "prepare [s]", "us per face", "particles", "tets from"],
                                       [[f"{r['faces']:,}", f"{r['seconds']:.1f}", f"{1e6 * r['seconds'] / r['faces']:.1f}",
                                         f"{r['particles']:,}", r["mesher"]] for r in scaling])) if scaling else "",
        "The checks alone (`validate_surface`: closedness, manifold edges, winding, self-crossings) on the "
        "noisy sphere, after the crossing kernel's one-time compilation:",
        check,
    ])
