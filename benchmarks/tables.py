"""Part 1: the paper's Table 1 (scene sizes, fragments) and Table 2 (ms per 20 ms frame)
beside our runs of the same scenes.

Every scene runs through ``Simulation(scene, output=False, world=shared_world)``: the
``RunSummary`` gives Table 1's columns and the per-frame times of the fracture-on runs;
the same scenes again with ``fracture=False`` (and with ``single_scale=True``, the paper's
single-scale column) give the rest of Table 2.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .common import SCENES, BenchContext, Section, md_table, ms_pair

#: ../shared/paper/BRIEF.md section 4, Table 1: physics, surface, boundary particles, fragments.
PAPER_TABLE1 = {
    "single ring, control 1": (5044, 1608, 543, 2),
    "single ring, control 2": (5044, 1608, 543, 5),
    "single ring, control 3": (5044, 1608, 543, 10),
    "3 glass walls": (20748, 7713, 3400, 217),
    "13 rings": (70616, 14951, 7645, 106),
}
#: BRIEF.md section 4, Table 2: dynamics ms per 20 ms step, (average, maximum), Intel Core
#: i3-2100 3.2 GHz + GeForce GTX 460: two-scale, single-scale.
PAPER_TABLE2 = {
    "3 glass walls": ((54.0, 94.0), (218.0, 350.0)),
    "13 rings": ((7.5, 31.5), (32.0, 107.0)),
}


@dataclass
class SceneCase:
    """A scene of the tables: ``label`` is the paper's row name (a key of PAPER_TABLE1, or
    any name for a scene the paper does not have); ``timed`` puts it in Table 2.
    ``variants``: (name, scene) pairs of other crack controls, run with fracture on for the
    table of fragments against time; those named ``SCENE_ROW + ", seeds + k"`` are the scene
    with its crack seeds shifted, summed up with the scene's own run in the table of the
    spread over seed sets (against ``target_ms``)."""

    label: str
    scene: object
    timed: bool = False
    note: str = ""
    variants: tuple = ()
    target_ms: float | None = None  # the scene's target [ms/frame], fracture on


#: The glass walls at fewer cracks per impact: cheaper,
#: further from the paper's 217 fragments.
GLASS_FEWER_CRACKS = ["wall0.fracture.crack_count=4", "wall1.fracture.crack_count=3", "wall2.fracture.crack_count=2",
                      *[f"wall{k}.fracture.ring_crack_count=2" for k in range(3)]]
#: The glass walls with the radial cracks alone (the paper's crack model: planes only).
GLASS_RADIAL_ONLY = [f"wall{k}.fracture.ring_crack_count=0" for k in range(3)]
#: The 13 rings with the five rings of one crack, or of short cracks, cut too short to split
#: them (the scene's controls before it gave them cracks across the ring).
RINGS_SHORT_CRACKS = ["ring00.fracture.crack_length=none", "ring05.fracture.crack_length=0.07",
                      "ring09.fracture.crack_length=none", "ring10.fracture.crack_length=0.09",
                      "ring12.fracture.crack_length=none"]


#: The name of a timed scene's own row in the table of fragments against time.
SCENE_ROW = "the scene's"

#: Crack-seed shifts the report runs besides each scene's own seeds. A run of these chaotic
#: scenes is one draw: a change of ~1e-16 in the stresses moves the fragment count by tens
#: of percent, as much as another seed does. The targets are judged on the mean over these
#: sets.
RINGS_SEED_SHIFTS = (13, 26, 39, 52, 65, 78, 91)
GLASS_SEED_SHIFTS = (3, 6, 9, 12)


def other_seeds(scene, shift: int) -> list[str]:
    """Overrides that shift every breakable object's crack seed by ``shift``: the same
    scene with other crack directions, to show how far its counts and times spread."""
    return [f"{o.name}.fracture.seed={o.fracture.seed + shift}" for o in scene.breakable_objects]


def default_cases() -> list[SceneCase]:
    from taichi_frac.scenes import load_scene

    ring, glass, rings = SCENES / "single_ring.toml", SCENES / "glass_walls.toml", SCENES / "thirteen_rings.toml"
    glass_scene, rings_scene = load_scene(glass), load_scene(rings)
    return [
        SceneCase("single ring, control 1", load_scene(ring, ["ring.fracture.crack_count=1"]), note="crack_count 1"),
        SceneCase("single ring, control 2", load_scene(ring, ["ring.fracture.crack_count=3"]), note="crack_count 3"),
        SceneCase("single ring, control 3", load_scene(ring, ["ring.fracture.crack_count=5"]), note="crack_count 5"),
        SceneCase("3 glass walls", glass_scene, timed=True, target_ms=20.0, variants=(
            *[(f"{SCENE_ROW}, seeds + {k}", load_scene(glass, other_seeds(glass_scene, k))) for k in GLASS_SEED_SHIFTS],
            ("crack_count 4, 3, 2 and two rings (the scene: 8, 7, 6 and three)", load_scene(glass, GLASS_FEWER_CRACKS)),
            ("radial cracks only (ring_crack_count 0; the scene: 3)", load_scene(glass, GLASS_RADIAL_ONLY)))),
        SceneCase("13 rings", rings_scene, timed=True, target_ms=5.0, variants=(
            *[(f"{SCENE_ROW}, seeds + {k}", load_scene(rings, other_seeds(rings_scene, k))) for k in RINGS_SEED_SHIFTS],
            ("five rings cut short (one cut, or none, across the tube)", load_scene(rings, RINGS_SHORT_CRACKS)))),
    ]


def run_scene(ctx: BenchContext, scene, label: str, *, fracture: bool = True, single_scale: bool | None = None,
              frames: int | None = None, output=False, surface_workers: int | None = None):
    """Run one scene on the report's World; returns (Simulation, RunSummary, counts) where
    counts are Table 1's particle counts summed over the scene's bodies at the start
    (every body, breakable or not, so a fracture-off run is counted the same way).
    ``output``: a cache path to write (default: none, as the timed rows); ``surface_workers``:
    as ``Simulation``'s (0 keeps the pieces' render solids readable here)."""
    from taichi_frac.simulation import Simulation

    mode = ("fracture on" if fracture else "fracture off") + (", single-scale" if single_scale else "")
    mode += ", USD cache written" if output else ""
    sim = Simulation(scene, output=output, world=ctx.world(), fracture=fracture, single_scale=single_scale,
                     frames=frames, progress=ctx.progress.frames(f"{label} ({mode})"),
                     surface_workers=surface_workers)
    breakable = [r.model for r in sim.records.values() if r.breakable]
    counts = dict(
        physics=sum(m.tet_count for m in breakable), surface=sum(m.surface_particle_count for m in breakable),
        boundary=sum(m.boundary_particle_count for m in breakable),
        all_physics=sum(r.model.tet_count for r in sim.records.values()),
        collision=sum(count for _, count in sim.world.slots.body_range.values()),
    )
    substeps_before = sim.world.stats.total_substeps
    summary = sim.run()
    counts["substeps_per_frame"] = (sim.world.stats.total_substeps - substeps_before) / max(summary.frames, 1)
    return sim, summary, counts


def run(ctx: BenchContext, cases: list[SceneCase] | None = None, frames: int | None = None) -> Section:
    """Table 1 and Table 2. ``frames`` caps every run (None: each scene's own duration;
    quick mode: 10)."""
    if frames is None and ctx.quick:
        frames = 10
    cases = default_cases() if cases is None else cases
    t0 = time.perf_counter()
    table1, runs = [], {}
    for case in cases:
        sim, summary, counts = run_scene(ctx, case.scene, case.label, frames=frames)
        runs[case.label] = dict(on=(summary, counts))
        mass_ok = abs(summary.mass_final + summary.mass_dropped - summary.mass_initial) <= 1e-9 * summary.mass_initial
        paper = PAPER_TABLE1.get(case.label)
        ours = (summary.physics_particles, summary.surface_particles, summary.boundary_particles, summary.fragments)
        cells = [f"{o:,} / {p:,}" if paper else f"{o:,}" for o, p in zip(ours, paper or (0,) * 4)]
        table1.append([case.label + (f" ({case.note})" if case.note else ""), *cells, summary.frames,
                       summary.fractures, "yes" if mass_ok else "**no**"])
        ctx.progress(f"table 1: {case.label}: {summary.fragments} fragments in {summary.frames} frames")
    table2, stages, cached = [], [], []
    for case in cases:
        if not case.timed:
            continue
        summary, counts = runs[case.label]["on"]
        with tempfile.TemporaryDirectory() as folder:
            _, written, _ = run_scene(ctx, case.scene, case.label, frames=frames,
                                      output=Path(folder) / "cache.usdc")
        cached.append([case.label, f"{summary.ms_per_frame['mean']:.1f}", f"{written.ms_per_frame['mean']:.1f}",
                       f"{1e3 * written.stage_seconds['output'] / max(written.frames, 1):.1f}",
                       written.fragments])
        _, off, off_counts = run_scene(ctx, case.scene, case.label, fracture=False, frames=frames)
        _, single, single_counts = run_scene(ctx, case.scene, case.label, fracture=False, single_scale=True,
                                             frames=frames)
        runs[case.label].update(off=(off, off_counts), single=(single, single_counts))
        paper = PAPER_TABLE2.get(case.label)
        table2.append([
            case.label, f"{counts['physics']:,}", f"{counts['collision']:,} / {single_counts['collision']:,}",
            ms_pair(summary.ms_per_frame["mean"], summary.ms_per_frame["max"]),
            ms_pair(off.ms_per_frame["mean"], off.ms_per_frame["max"]),
            ms_pair(single.ms_per_frame["mean"], single.ms_per_frame["max"]),
            ms_pair(*paper[0]) if paper else "", ms_pair(*paper[1]) if paper else "",
        ])
        per_frame = {k: 1e3 * v / max(summary.frames, 1)
                     for k, v in (summary.stage_seconds | summary.dynamics_stage_seconds).items()}
        stages.append([case.label, summary.frames, f"{counts['substeps_per_frame']:.1f}",
                       f"{per_frame.get('collision', 0.0):.2f}", f"{per_frame.get('response', 0.0):.2f}",
                       f"{per_frame['dynamics']:.1f}", f"{per_frame['fracture_analysis']:.1f}",
                       f"{per_frame['fragment_split']:.1f}", summary.fractures, summary.fragments])
        ctx.progress(f"table 2: {case.label}: fracture on {summary.ms_per_frame['mean']:.1f} ms/frame, "
                     f"off {off.ms_per_frame['mean']:.1f}, single-scale {single.ms_per_frame['mean']:.1f}")

    variants = []
    mean_ms = {}  # (scene, crack controls) -> ms per frame, unrounded
    for case in cases:
        if not case.timed:
            continue
        summary, _ = runs[case.label]["on"]
        variants.append([case.label, SCENE_ROW, summary.fragments, summary.fractures,
                         ms_pair(summary.ms_per_frame["mean"], summary.ms_per_frame["max"])])
        mean_ms[(case.label, SCENE_ROW)] = summary.ms_per_frame["mean"]
        for name, scene in case.variants:
            _, other, _ = run_scene(ctx, scene, f"{case.label}, {name}", frames=frames)
            variants.append([case.label, name, other.fragments, other.fractures,
                             ms_pair(other.ms_per_frame["mean"], other.ms_per_frame["max"])])
            mean_ms[(case.label, name)] = other.ms_per_frame["mean"]
            ctx.progress(f"variants: {case.label}, {name}: {other.fragments} fragments, "
                         f"{other.ms_per_frame['mean']:.1f} ms/frame")

    parts = [
        "Each scene runs through `Simulation(scene, output=False, world=shared_world)` and its "
        "`RunSummary`; paper values from `../shared/paper/BRIEF.md` section 4. Cells are **ours / paper**. "
        "Particle counts are the breakable bodies' at the start (Table 1's definition); fragments are the "
        "live pieces made by fracture at the end of the run.",
        "",
        "**Table 1: scene sizes and fragments**",
        "",
        md_table(["scene", "physics particles", "surface particles", "boundary particles", "fragments", "frames",
                  "fracture events", "mass conserved"], table1, "lrrrrrrc"),
    ]
    if table2:
        parts += [
            "",
            "**Table 2: ms per 20 ms frame, average / maximum** (ours: this machine, wall clock per "
            "frame including the fracture stage when it is on; the paper: dynamics only, Intel Core i3-2100 "
            "3.2 GHz + GeForce GTX 460). Collision particles: two-scale / single-scale.",
            "",
            md_table(["scene", "physics particles", "collision particles", "ours, fracture on",
                      "ours, fracture off", "ours, single-scale, fracture off", "paper two-scale",
                      "paper single-scale"], table2, "lrrrrrrr"),
            "",
            "Where the fracture-on time goes (ms per frame averaged over the run):",
            "",
            md_table(["scene", "frames", "substeps per frame", "collision", "contact response", "dynamics (both + host)",
                      "fracture analysis", "fragment split",
                      "fracture events", "fragments"], stages, "lrrrrrrrrr"),
            "",
            "The timed runs write no cache. Writing it, as `taichi-frac run` does (one more run each; "
            "the new pieces' meshes are written in the split stage, the poses and checkpoints in the "
            "output stage):",
            "",
            md_table(["scene", "ms/frame, no cache", "ms/frame, USD cache written", "of which output stage",
                      "fragments"], cached, "lrrrr"),
        ]
    if any(row[1] != SCENE_ROW for row in variants):
        parts += [
            "",
            "Fragments against time: the same scenes with other crack seeds (other crack directions: "
            "how far one scene's counts and times spread) and other crack controls (fracture on). More "
            "pieces cost more, mostly in the dynamics of the pieces that fly and pile up.",
            "",
            md_table(["scene", "crack controls", "fragments", "fracture events", "ms per frame, average / maximum"],
                     variants, "llrrr"),
        ]
    spread = seed_spread(cases, variants, mean_ms)
    if spread:
        parts += [
            "",
            "The spread over seed sets (the scene's own seeds and the shifted ones above): one run of "
            "these chaotic scenes is one draw, so the targets are judged on the mean.",
            "",
            md_table(["scene", "seed sets", "fragments, range (mean)", "ms per frame, range (mean)",
                      "target [ms/frame]", "mean under the target"], spread, "lrrrrc"),
        ]
    figures, headline = [], {}
    if table2:
        path, link = _plot_table2(ctx, table2_rows(cases, runs))
        figures.append(path)
        parts += ["", f"![Table 2: ms per frame, ours and the paper's]({link})"]
        headline = {label: dict(on=runs[label]["on"][0].ms_per_frame, off=runs[label]["off"][0].ms_per_frame,
                                fragments=runs[label]["on"][0].fragments)
                    for label in runs if "off" in runs[label]}
    parts += ["", f"*Part time: {time.perf_counter() - t0:.0f} s.*"]
    return Section("tables", "Tables 1 and 2 beside the paper", "\n".join(parts), figures,
                   headline | {"runs": runs, "variants": variants})


def seed_spread(cases, variants, mean_ms) -> list[list]:
    """One row per timed scene with shifted-seed variants: how many seed sets, the range and
    mean of their fragments and of their mean ms per frame, the target and whether the mean
    is under it. ``variants``: the rows of the fragments-against-time table (scene, crack
    controls, fragments, ...); ``mean_ms``: (scene, crack controls) -> ms per frame."""
    rows = []
    for case in cases:
        seeded = [row for row in variants if row[0] == case.label
                  and (row[1] == SCENE_ROW or row[1].startswith(f"{SCENE_ROW}, seeds + "))]
        if len(seeded) < 2:
            continue
        fragments = np.array([row[2] for row in seeded], dtype=float)
        ms = np.array([mean_ms[(row[0], row[1])] for row in seeded])
        met = "" if case.target_ms is None else ("yes" if ms.mean() < case.target_ms else "no")
        rows.append([case.label, len(seeded), f"{fragments.min():.0f}-{fragments.max():.0f} ({fragments.mean():.1f})",
                     f"{ms.min():.1f}-{ms.max():.1f} ({ms.mean():.2f})",
                     "" if case.target_ms is None else f"{case.target_ms:g}", met])
    return rows


def table2_rows(cases, runs) -> list[tuple[str, list[tuple[str, float, float]]]]:
    """(scene, [(column, average ms, max ms)]) for the plot."""
    rows = []
    for case in cases:
        if "off" not in runs.get(case.label, {}):
            continue
        r = runs[case.label]
        bars = [("ours, fracture on", r["on"][0].ms_per_frame["mean"], r["on"][0].ms_per_frame["max"]),
                ("ours, fracture off", r["off"][0].ms_per_frame["mean"], r["off"][0].ms_per_frame["max"]),
                ("ours, single-scale", r["single"][0].ms_per_frame["mean"], r["single"][0].ms_per_frame["max"])]
        if case.label in PAPER_TABLE2:
            (a2, m2), (a1, m1) = PAPER_TABLE2[case.label]
            bars += [("paper two-scale", a2, m2), ("paper single-scale", a1, m1)]
        rows.append((case.label, bars))
    return rows


def _plot_table2(ctx: BenchContext, rows):
    from .common import pyplot

    plt = pyplot()
    fig, axes = plt.subplots(1, len(rows), figsize=(5.2 * len(rows), 3.6), squeeze=False)
    for ax, (label, bars) in zip(axes[0], rows):
        names = [b[0] for b in bars]
        avg = np.array([b[1] for b in bars])
        peak = np.array([b[2] for b in bars])
        x = np.arange(len(bars))
        ax.bar(x, avg, color=["C0", "C0", "C1", "C2", "C3"][: len(bars)], alpha=0.85, label="average")
        ax.scatter(x, peak, color="k", marker="_", s=200, label="maximum")
        ax.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel("ms per 20 ms frame")
        ax.set_title(label)
        ax.legend(fontsize=8)
    return ctx.save_figure(fig, "table2.png")
