"""Piece geometry: the render surfaces the cache gives broken pieces (surfaces/cut.py)
measured on the paper's scenes and a mesh from ../shared/meshes, beside the tets' own
boundary faces (what a piece looks like without them). Writes ``benchmarks/piece-geometry.md``.

Per scene: the live pieces at the end of a run that writes a cache, each measured by
surfaces/checks.py (open / non-manifold / misoriented edges, shells, crack faces' RMS
distance from their cracks, volume against the tets', render-to-tets distance), and the
cost of cutting the render solid per split. The timed rows of the tables part write no
cache, so they build no render solid and this cost is not in them.
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

from .common import REPO, SCENES, BenchContext, Section, load_average, md_table, provenance, spread

SHARED_MESH = REPO.parent / "shared" / "meshes" / "spot.obj"
#: Pieces with at least this many tets are the "large" ones the volume bound is read on: a
#: piece of a few tets where cracks meet is smaller than the planes' resolution.
LARGE_PIECE_TETS = 100
#: The volume bound a piece's render solid is held to, against its tets'.
VOLUME_BOUND = 0.02


def _scene_cases(quick: bool):
    """(label, scene, frames) per case: each paper scene as it is, and with the rendered crack
    planes left where the analysis put them (``crack_fit_rounds`` 0), the same physics."""
    from taichi_frac.scenes import load_scene

    frames = 40 if quick else None
    cases = []
    for label, path, overrides in (("single ring, crack_count 5", SCENES / "single_ring.toml",
                                    ["ring.fracture.crack_count=5"]),
                                   ("glass walls", SCENES / "glass_walls.toml", []),
                                   ("13 rings", SCENES / "thirteen_rings.toml", [])):
        scene = load_scene(path, overrides)
        unmoved = [f"{o.name}.fracture.crack_fit_rounds=0" for o in scene.breakable_objects]
        cases.append((label, scene, frames))
        cases.append((f"{label}, {UNMOVED}", load_scene(path, overrides + unmoved), frames))
        # Rough crack faces, the noise's amplitude ROUGH_SPACINGS of each body's particle spacing.
        rough = [f"{o.name}.fracture.crack_roughness={ROUGH_SPACINGS * o.prepare()[0].spacing:.6g}"
                 for o in scene.breakable_objects]
        cases.append((f"{label}, {ROUGH}", load_scene(path, overrides + rough), frames))
        if len(scene.breakable_objects) > 1:  # (the scenes of many pieces of a few tens of tets)
            smaller = [f"{o.name}.fracture.crack_fit_min_tets={SMALL_FIT_TETS}" for o in scene.breakable_objects]
            cases.append((f"{label}, {SMALL_FIT}", load_scene(path, overrides + smaller), frames))
    return cases


#: The label suffix of the cases whose crack planes the volume fit leaves where they are.
UNMOVED = "cracks unmoved"

#: ``crack_fit_min_tets`` of the cases that fit the crack stretches to smaller pieces too.
SMALL_FIT_TETS = 30
SMALL_FIT = f"stretches fitted to pieces of {SMALL_FIT_TETS}+ tets"

#: ``crack_roughness`` of the rough-crack cases [particle spacings].
ROUGH_SPACINGS = 0.3
ROUGH = f"rough cracks ({ROUGH_SPACINGS:g} spacings)"


def tet_height(model) -> float:
    """[particle spacings] the mean over ``model``'s tets of the largest height (vertex to
    opposite face): how deep the tets' staircase along a crack is, the distance a flat crack
    face can lie from its piece's tets."""
    corners = model.vertices[model.tets]  # (T,4,3)
    heights = []
    for apex in range(4):
        a, b, c = (corners[:, k] for k in range(4) if k != apex)
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        heights.append(3.0 * model.tet_volume / np.maximum(area, 1e-300))
    return float(np.mean(np.max(heights, axis=0)) / model.spacing)


def measure_pieces(pieces) -> dict:
    """Totals over pieces ((model, root model, render solid or None) each) of the render
    surfaces' and the tets' boundary faces' measures."""
    from taichi_frac.surfaces.checks import edge_counts, piece_quality
    from taichi_frac.surfaces.mesh import piece_mesh
    from taichi_frac.surfaces.mesh import fragment_surface

    rows, before = [], []
    for model, root, render in pieces:
        _, tet_faces, _ = fragment_surface(model, root)
        before.append(edge_counts(tet_faces))
        if render is not None:
            rows.append((model.tet_count, piece_quality(piece_mesh(render), model)))
    quality = [q for _, q in rows]
    large = [q for n, q in rows if n >= LARGE_PIECE_TETS]
    mid = np.array([q["volume_error"] for n, q in rows if SMALL_FIT_TETS <= n < LARGE_PIECE_TETS])
    volume = np.array([q["volume_error"] for q in quality]) if quality else np.zeros(1)
    large_volume = np.array([q["volume_error"] for q in large]) if large else np.full(1, np.nan)
    roots = {id(root): root for _, root, _ in pieces}
    return dict(
        tet_height=float(np.mean([tet_height(root) for root in roots.values()])) if roots else float("nan"),
        pieces=len(before), rendered=len(quality), fallback=len(before) - len(quality),
        before_nonmanifold=sum(b["nonmanifold_edges"] for b in before),
        before_pieces_nonmanifold=sum(b["nonmanifold_edges"] > 0 for b in before),
        nonmanifold=sum(q["nonmanifold_edges"] for q in quality), open=sum(q["open_edges"] for q in quality),
        misoriented=sum(q["misoriented_edges"] for q in quality),
        closed=sum(q["watertight"] and q["outward"] for q in quality),
        multi_shell=sum(q["shells"] > 1 for q in quality),
        crack_rms=float(np.nanmax([q["crack_rms_spacings"] for q in quality])) if quality else float("nan"),
        large=len(large), large_volume=float(np.nanmax(np.abs(large_volume))),
        median_volume=float(np.median(np.abs(volume))),
        volume_over=int(np.sum(np.abs(volume) > VOLUME_BOUND)) if quality else 0,
        mid=len(mid), mid_over=int(np.sum(np.abs(mid) > VOLUME_BOUND)),
        mid_median=float(np.median(np.abs(mid))) if len(mid) else float("nan"),
        far=sum(q["distance_to_tets_spacings"] > 1.0 for q in quality),
        distance=spread([q["distance_to_tets_spacings"] for q in quality]),
        distance_back=spread([q["distance_from_tets_spacings"] for q in quality]),
        within=sum(q["distance_to_tets_spacings"] <= 1.0 and q["distance_from_tets_spacings"] <= 1.0
                   for q in quality),
        large_volume_spread=spread(100 * np.abs(large_volume)) if large else "-",
    )


def _segments(render_cuts) -> str:
    """'segments (splits) (largest shift [spacings])': the stretches of crack planes between
    one pair of pieces the ``render_cuts`` shifted on their own."""
    moved = [c.get("moved_segments", 0) for _, c in render_cuts]
    largest = max((c.get("largest_segment_shift", 0.0) for _, c in render_cuts), default=0.0)
    return f"{sum(moved)} in {sum(m > 0 for m in moved)} ({largest:.2f})"


def _trimmed(render_cuts, volume: float) -> str:
    """'pieces (volume [cm^3], share of ``volume`` [m^3])' the ``render_cuts`` trimmed to their
    tets' reach."""
    pieces = sum(c.get("trimmed_pieces", 0) for _, c in render_cuts)
    trimmed = sum(c.get("trimmed_volume", 0.0) for _, c in render_cuts)
    return f"{pieces} ({1e6 * trimmed:.2f} cm³, {100 * trimmed / max(volume, 1e-300):.3f} %)"


def _mesh_case(ctx: BenchContext, fit_rounds: int | None = None):
    """spot.obj (full resolution, with UVs) struck once: prepare, analyse, split, cut (the
    crack planes fitted ``fit_rounds`` times; None: FractureOptions' default). Returns the
    pieces' measures, the cut's time [s], the surface's triangle count, the cut's counts and
    (model, render solid) of the whole body."""
    from taichi_frac.fracture.cracks import analyze_impact
    from taichi_frac.fracture.fragments import make_fragments, split_body
    from taichi_frac.surfaces.cut import cut_render_solid
    from taichi_frac.surfaces.solid import render_solid_from_surface
    from taichi_frac.geometry.prepare import prepare_body
    from taichi_frac.options import FractureOptions, ParticleOptions, material_preset

    material = material_preset("porcelain")
    particles = ParticleOptions(target_particles=3000 if ctx.quick else 5000)
    model, report = prepare_body(str(SHARED_MESH), material=material, particles=particles)
    # Cracks as long as the cow (the stress field's own length stops them inside it: one piece).
    options = FractureOptions(crack_count=4, crack_length=float(np.ptp(model.vertices, axis=0).max()), seed=0)
    if fit_rounds is not None:
        options = dataclasses.replace(options, crack_fit_rounds=fit_rounds)
    top = int(np.argmax(model.particle_position[:, 2]))
    point = model.particle_position[top]
    analysis = analyze_impact(model, point, [0.0, 0.0, -1.0], [0.0, 0.0, -4.0 * model.mass * 9.81 * 200.0],
                              material, options)
    split = split_body(model, analysis, options)
    pieces = make_fragments(model, split, np.zeros(3), [1.0, 0.0, 0.0, 0.0], np.zeros(3), np.zeros(3), material,
                            particles, options=options)
    render = render_solid_from_surface(report.surface, model.com_in_source, model.spacing)
    t = time.perf_counter()
    renders, counts = cut_render_solid(render, model, split.fragment_tets, analysis.cracks,
                                       [p.model.com_in_source for p in pieces], fit_rounds=options.crack_fit_rounds)
    seconds = time.perf_counter() - t
    counts = dict(counts, volume=model.volume)
    return measure_pieces([(p.model, model, r) for p, r in zip(pieces, renders)]), [seconds], len(report.surface.faces), counts, (model, render.solid)


def _scene_solid(path: Path, name: str):
    """(BodyModel, render solid) of the object ``name`` of the scene at ``path``."""
    from taichi_frac.surfaces.solid import render_solid_from_surface
    from taichi_frac.scenes import load_scene

    obj = next(o for o in load_scene(path).objects if o.name == name)
    model, report = obj.prepare()
    return model, render_solid_from_surface(report.surface, model.com_in_source, model.spacing).solid


def run(ctx: BenchContext) -> Section:
    from taichi_frac.surfaces.parts import (FOREIGN_DEPTH_FACTOR, GAINED_VOLUME_FACTOR, GAINED_VOLUME_SHARE,
                                        LOST_VOLUME_SHARE, OVERREACH_FACTOR)
    from taichi_frac.surfaces.reach import BALL_BOUND, REACH_FACTOR
    from taichi_frac.surfaces.crack_fit import (FITTED_PIECE_TETS, MAX_OFFSET_FACTOR, MAX_TILT_FACTOR,
                                          SMALL_PIECE_WEIGHT, VOLUME_TOLERANCE)
    from taichi_frac.options import FractureOptions
    from .perfect_cut import FLOOR_HEADER, PLANES, WEDGE_TETS, floor_rows, perfect_cuts
    from .tables import run_scene

    t0 = time.perf_counter()
    rows, cost_rows = [], []
    with tempfile.TemporaryDirectory() as folder:
        for label, scene, frames in _scene_cases(ctx.quick):
            sim, summary, _ = run_scene(ctx, scene, label, frames=frames, output=Path(folder) / "cache.usdc",
                                        surface_workers=0)
            records = [sim.records[b] for b in sim.world.body_ids if sim.records[b].generation > 0]
            m = measure_pieces([(rec.model, rec.root, sim.surfaces.render_of(b))
                                for b in sim.world.body_ids if (rec := sim.records[b]).generation > 0])
            cuts = [s for s, _ in sim.render_cuts]
            rows.append((label, m))
            split_ms = 1e3 * sum(cuts) / max(summary.frames, 1)
            fallbacks = sum(c.get("fallback_pieces", 0) for _, c in sim.render_cuts)
            cells = sum(c.get("cell_pieces", 0) for _, c in sim.render_cuts)
            fit_cuts = [c.get("fit_cuts", 0) for _, c in sim.render_cuts]
            cost_rows.append([label, len(cuts), f"{fallbacks} ({cells})",
                              _trimmed(sim.render_cuts, sum(rec.model.volume for rec in records)),
                              f"{np.mean(fit_cuts):.1f}" if cuts else "-", _segments(sim.render_cuts),
                              f"{1e3 * np.mean(cuts):.0f}" if cuts else "-",
                              f"{1e3 * np.max(cuts):.0f}" if cuts else "-", f"{split_ms:.2f}",
                              f"{summary.ms_per_frame['mean']:.1f}"])
            ctx.progress(f"{label}: {m['pieces']} pieces, {m['closed']} closed, crack RMS {m['crack_rms']:.1e}")
    floors = []
    for label, path, name in (("single ring", SCENES / "single_ring.toml", "ring"),
                              ("a glass wall", SCENES / "glass_walls.toml", "wall0")):
        floors += floor_rows(label, perfect_cuts(*_scene_solid(path, name)))
    if SHARED_MESH.exists():
        for fit_rounds, suffix in ((None, ""), (0, f", {UNMOVED}")):
            m, cuts, triangles, counts, body = _mesh_case(ctx, fit_rounds)
            if fit_rounds is None:
                floors += floor_rows(SHARED_MESH.name, perfect_cuts(*body))
            rows.append((f"{SHARED_MESH.name} ({triangles:,} triangles), one impact{suffix}", m))
            cost_rows.append([f"{SHARED_MESH.name}, one impact{suffix}", 1,
                              f"{counts['fallback_pieces']} ({counts['cell_pieces']})",
                              _trimmed([(0, counts)], counts["volume"]), counts["fit_cuts"], _segments([(0, counts)]),
                              f"{1e3 * cuts[0]:.0f}", f"{1e3 * cuts[0]:.0f}", "-", "-"])
    quality_rows = [[label, m["pieces"], m["fallback"],
                     f"{m['before_nonmanifold']} in {m['before_pieces_nonmanifold']}",
                     f"{m['nonmanifold']} / {m['open']} / {m['misoriented']}", f"{m['closed']} of {m['rendered']}",
                     m["multi_shell"], f"{m['crack_rms']:.1e}", f"{m['large_volume_spread']} ({m['large']})",
                     f"{100 * m['median_volume']:.1f} %", m["volume_over"],
                     f"{100 * m['mid_median']:.1f} % / {m['mid_over']} of {m['mid']}", m["distance"], m["far"],
                     m["distance_back"], f"{m['within']} of {m['rendered']}", f"{m['tet_height']:.2f}"]
                    for label, m in rows]
    markdown = "\n".join([
        "Each broken piece's render surface is the artist's surface cut along the cracks "
        "([docs/guide/fragment-geometry.md](../guide/fragment-geometry.md)). Measured on the live pieces at "
        "the end of each run (a cache written), against each piece's tets (their boundary faces: the staircase a piece would show uncut; "
        f"{provenance()}, machine load "
        f"{load_average()}: the times compare with each other, not with other pages' machines). A part "
        f"reaching more than {OVERREACH_FACTOR:.0f} spacings from its piece's nearest tet centroid is first divided: the material "
        f"nearest another piece's tets farther than {FOREIGN_DEPTH_FACTOR:g} spacings from its own goes to that "
        "piece. A piece the cut still fails (its render solid "
        f"under {100 * LOST_VOLUME_SHARE:.0f} % of its tets' volume, over it by more than "
        f"{100 * GAINED_VOLUME_SHARE:.0f} % and {GAINED_VOLUME_FACTOR:.0f} spacings cubed, or reaching more than "
        f"{OVERREACH_FACTOR:.0f} spacings from its nearest tet, or the one that lost that volume to it) gets "
        "the solid nearer its tets' centroids than the other failed pieces', less what the others hold (it "
        "is measured with the rest); only where that fails too does it keep its tets' boundary, exact in "
        "volume: those are counted in the third column and left out of the render columns. The render-to-tets "
        "distance is the largest, over a piece's render vertices, distance to its tets' union (0 inside); the "
        "tets-to-render one the largest, over its tets' boundary vertices, distance to its render solid; both "
        "in particle spacings (the body's mean tet V^(1/3)). A flat crack face crosses the tets' staircase, so "
        "it lies up to about a tet's height (last column) from its piece's tets and its volume differs from theirs by that "
        "layer: the distance and volume columns measure that difference, not an error of the cut alone. "
        f"What lies farther than {REACH_FACTOR:g} spacings from a piece's tets and within that of another's "
        "(the tip of a wedge between two cracks meeting at a sharp angle) is cut away along its tets grown "
        f"by that reach, a hull within {BALL_BOUND:.2f} times it: the distance's bound. "
        f"Each crack plane is then shifted along its normal by at most {MAX_OFFSET_FACTOR:g} spacings and, where "
        f"shifts cannot do it, tilted by at most {MAX_TILT_FACTOR:g} more at its far end, and each ring crack's sphere "
        f"resized by at most {MAX_OFFSET_FACTOR:g}, so the pieces of {FITTED_PIECE_TETS} tets or more come "
        f"nearest their tets' volumes (while one is off by more than {100 * VOLUME_TOLERANCE:g} %, up to the default "
        f"{FractureOptions().crack_fit_rounds} rounds). Where that leaves one off by more than that, the stretch "
        "of a crack plane between each pair of pieces is shifted on its own (by at most "
        f"{MAX_OFFSET_FACTOR:g} spacings more, the fewest stretches that do it, a wall cut across each step "
        f"between two), up to {FractureOptions().crack_fit_rounds} rounds more; the rows '{UNMOVED}' are the "
        "same runs with the cracks where the analysis put them; the rows "
        f"'{SMALL_FIT}' fit the stretches to the pieces of {SMALL_FIT_TETS} tets or more too "
        f"(`crack_fit_min_tets` {SMALL_FIT_TETS}), a smaller piece's error counted at {SMALL_PIECE_WEIGHT:g} of a "
        f"larger one's; the rows '{ROUGH}' roughen the crack faces (`crack_roughness` {ROUGH_SPACINGS:g} particle "
        "spacings, the default scale): their RMS column is the noise's, and their stretches are shifted in one "
        "warped surface, without walls.",
        "",
        md_table(["case", "pieces", "on their tets' boundary (cut failed)",
                  "tet faces: non-manifold edges (in pieces)",
                  "render: non-manifold / open / misoriented edges", "closed and outward", "pieces with 2+ shells",
                  "crack faces' RMS off their cracks [spacings]",
                  f"volume error [%], pieces >= {LARGE_PIECE_TETS} tets: median / 95th pct / max (count)",
                  "median volume error, all", f"pieces off by more than {100 * VOLUME_BOUND:.0f} %",
                  f"pieces of {SMALL_FIT_TETS}-{LARGE_PIECE_TETS - 1} tets: median volume error / off by more than "
                  f"{100 * VOLUME_BOUND:.0f} %",
                  "render-to-tets distance per piece [spacings]: median / 95th pct / max",
                  "pieces farther than 1 spacing",
                  "tets-to-render distance per piece [spacings]: median / 95th pct / max",
                  "pieces within 1 spacing both ways",
                  "a tet's height, mean [spacings]"],
                 quality_rows),
        "",
        "The floor under the distance and volume columns: each body's render solid cut exactly by "
        f"{PLANES} random planes through its particles and its tets split by the same planes (each tet to the "
        "side its centroid lies on), so the pieces and the flat faces agree as well as flat faces can: halves, "
        f"and wedges where a second plane at 30-90° to the first leaves about {' or '.join(map(str, WEDGE_TETS))} "
        "tets (the pieces made where cracks meet). A tet straddling the plane with its centroid on the piece's "
        "side reaches past the face by up to 3/4 of its extent along the normal, so no flat face lies within "
        "one spacing of its tets both ways, and a small piece's staircase is a large share of its volume:",
        "",
        md_table(FLOOR_HEADER, floors),
        "",
        "What cutting the render solids costs (only runs that write a cache pay it):",
        "",
        md_table(["case", "splits", "pieces the cuts failed (given the solid nearest their tets)",
                  "pieces trimmed to their tets' reach (volume cut away, share of the pieces')",
                  "cuts for the volume fit, per split",
                  "crack segments shifted on their own, in splits (largest shift [spacings])",
                  "ms per split, mean", "max", "ms per frame from it",
                  "ms per frame, whole run"], cost_rows),
        "",
        f"Part took {time.perf_counter() - t0:.0f} s.",
    ])
    path = ctx.markdown_dir / "benchmarks" / "piece-geometry.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("# Piece geometry\n\n" + markdown + "\n")
    ctx.progress(f"wrote {path}")
    return Section("pieces", "Piece geometry", markdown)
