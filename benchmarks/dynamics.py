"""``taichi-frac bench dynamics``: the rigid-body table, in one run.

- ``scenes/thirteen_rings.toml`` with the rings unbreakable, two-scale (the boundary layer)
  and single-scale (every physics surface particle collides), the paper's Table 2 columns:
  ms per 20 ms frame (average / max), substeps per frame, contacts lost to capacity, bodies
  asleep at the end, the deepest collision sphere below the ground at the end; and
  two-scale again with coarser refinement (``COARSE_FRACTION`` particle radii of motion per
  substep instead of the scene's 1.5), what unbreakable rings can afford;
- what two-scale costs against single-scale: the report's single-ring drop
  (``grouping.measure_drop``: rest height against the exact 0.025 m, rebound, first-impact
  impulse, penetration) with boundary grouping n = 4 against n = 1 (the rings' rest
  positions are no measure: a pile is chaotic, two runs of one mode differ by as much);
- a pile of loose fragments (two-scale) in a box, with the scene's time stepping.

Every run uses the report's one World (``BenchContext.world``), so the kernels compile once.
``--set KEY=VALUE`` overrides the scene as ``taichi-frac run --set`` does.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from .common import BenchContext, deepest_below_ground, md_table, ms_pair
from .contact import print_contact

#: Motion per substep [particle radii] of the table's coarse-stepping row. Measured with
#: the rings unbreakable (worst collision-sphere depth below the floor during a 3 s run):
#: 0.16 radii; with fracture, small chips went up to 0.87 physics-particle radii into the
#: floor (the scene test allows 1), so the scene keeps 1.5 (scenes/thirteen_rings.toml).
COARSE_FRACTION = 3.0


def _fragment_model():
    import tetgen
    import trimesh

    from taichi_frac.model import build_body_model
    from .pile import FRAGMENT_DENSITY, FRAGMENT_RADIUS

    mesh = trimesh.creation.icosphere(subdivisions=1, radius=FRAGMENT_RADIUS)
    gen = tetgen.TetGen(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    vertices, tets = gen.tetrahedralize(order=1, maxvolume=mesh.volume / 30)[:2]
    return build_body_model(vertices, tets, FRAGMENT_DENSITY, boundary_group_size=4)


def _rings(ctx: BenchContext, scene, single: bool, repeat: int) -> dict:
    """``repeat`` runs of the rings; the median of their average and of their slowest
    frame [ms], the other columns from the median run. The runs compute the same motion
    (the contacts are visited in a reproducible order) but not in the same time: the
    slowest frame of one run ranged 6.8-14.8 ms in three runs (before the contacts were
    sorted, single-scale runs also differed in their motion, by up to 1.6x in time)."""
    from .tables import run_scene

    label = "single-scale" if single else "two-scale"
    runs = []
    for _ in range(repeat):
        sim, summary, counts = run_scene(ctx, scene, f"13 rings {label}", fracture=False, single_scale=single)
        world = sim.world
        bodies = world.body_ids
        state = world.body_state(bodies)
        runs.append(dict(mean=summary.ms_per_frame["mean"], max=summary.ms_per_frame["max"],
                         frames=summary.frames, particles=counts["collision"], substeps=counts["substeps_per_frame"],
                         overflows=world.stats.total_contact_overflows, asleep=int(state["sleeping"].sum()),
                         bodies=len(bodies), depth=deepest_below_ground(world, bodies)))
    means = [r["mean"] for r in runs]
    maxes = [r["max"] for r in runs]
    median_run = runs[int(np.argsort(means)[len(runs) // 2])]
    return dict(median_run, mean=float(np.median(means)), max=float(np.median(maxes)), means=means, maxes=maxes)


def _rings_row(label: str, r: dict) -> list:
    spread = ""
    if len(r["means"]) > 1:
        spread = (f" ({min(r['means']):.1f}-{max(r['means']):.1f} / "
                  f"{min(r['maxes']):.1f}-{max(r['maxes']):.1f})")
    return [label, f"{r['particles']:,}", ms_pair(r["mean"], r["max"]) + spread, f"{r['substeps']:.1f}",
            f"{r['asleep']} / {r['bodies']}", f"{1e3 * r['depth']:.3f}", r["overflows"]]


def _fragment_pile(ctx: BenchContext, scene, count: int, seconds: float) -> dict:
    """``count`` small fragments dropped into a 0.44 m box from a loose cube lattice
    (``bench/pile.py``, the layout pybullet's pile uses too)."""
    from taichi_frac.dynamics import DynamicsOptions
    from . import pile

    sim = scene.simulation
    world = ctx.world()
    world.clear()
    world.set_options(DynamicsOptions.from_simulation(sim))
    world.add_ground(0.0)
    for centre, half in pile.WALLS:
        world.add_static_box(centre, half)
    fragment = _fragment_model()
    positions, spins = pile.layout(count)
    bodies = [world.add_body(fragment, x, (1, 0, 0, 0), (0, 0, 0), w) for x, w in zip(positions, spins)]
    frame_dt = sim.frame_dt
    world.advance(frame_dt, sim.substeps)  # compile outside the timing
    times = []
    for frame in range(int(round(seconds / frame_dt))):
        t = time.perf_counter()
        world.advance(frame_dt, sim.substeps)
        times.append(time.perf_counter() - t)
        if frame % 25 == 0:
            ctx.progress(f"fragment pile: frame {frame}, {1e3 * np.mean(times):.1f} ms/frame so far")
    ms = np.array(times) * 1e3
    return dict(avg=ms.mean(), max=ms.max(), particles=sum(world.slots.body_range[b][1] for b in bodies),
                tets=fragment.tet_count, asleep=int(world.body_state(bodies)["sleeping"].sum()),
                depth=deepest_below_ground(world, bodies), overflows=world.stats.total_contact_overflows)


def run_dynamics(args) -> int:
    """Print the rigid-body tables (see the module docstring)."""
    from taichi_frac.scenes import load_scene
    from . import grouping
    from .common import Progress, warm_up

    ctx = BenchContext(arch=args.arch, progress=Progress(enabled=not args.quiet))
    scene = load_scene(args.scene, args.set or [])
    sim = scene.simulation
    t0 = time.perf_counter()
    warm_up(ctx)
    if args.contact_only:
        return print_contact(ctx, scene, args, t0)
    two = _rings(ctx, scene, single=False, repeat=args.repeat)
    one = _rings(ctx, scene, single=True, repeat=args.repeat)
    # The same unbreakable rings refined to 3 particle radii of motion per substep instead
    # of the scene's: what unbreakable bodies can afford (see the scene file's notes).
    coarse_scene = load_scene(args.scene, (args.set or []) + [f"simulation.substep_motion_fraction={COARSE_FRACTION}"])
    coarse = _rings(ctx, coarse_scene, single=False, repeat=args.repeat)
    drops = {n: grouping.measure_drop(ctx, grouping.drop_scene(n)) for n in (4, 1)}
    pile = _fragment_pile(ctx, scene, args.fragments, args.seconds)
    d4, d1 = drops[4], drops[1]
    lines = [
        f"`{args.scene}`{' with ' + ', '.join(args.set) if args.set else ''}: rings unbreakable, "
        f"{two['frames']} frames of {1e3 * sim.frame_dt:g} ms, {sim.substeps} substeps where bodies touch "
        f"(more while one moves over {sim.substep_motion_fraction:g} particle radius per substep), "
        f"{sim.solver_iterations} solver sweeps; arch {args.arch}.",
        "",
        md_table(["scene", "collision particles",
                  "ms/frame avg / max" + (f", median of {args.repeat} runs (range)" if args.repeat > 1 else ""),
                  "substeps/frame", "asleep at end", "deepest below ground [mm]", "contacts lost"], [
            _rings_row("13 rings, two-scale", two),
            _rings_row("13 rings, single-scale", one),
            _rings_row(f"13 rings, two-scale, {COARSE_FRACTION:g} particle radii per substep", coarse),
            [f"{args.fragments} fragments ({pile['tets']} tets each), two-scale, {args.seconds:g} s",
             f"{pile['particles']:,}", ms_pair(pile["avg"], pile["max"]), "", f"{pile['asleep']} / {args.fragments}",
             f"{1e3 * pile['depth']:.3f}", pile["overflows"]],
        ]),
        "",
        f"Two-scale is **{one['mean'] / two['mean']:.1f}x** faster than single-scale on average "
        f"({one['max'] / two['max']:.1f}x on the slowest frame; medians of {args.repeat} runs each).",
        "",
        md_table(["what two-scale changes against single-scale", "two-scale (n = 4)", "single-scale (n = 1)",
                  "difference"], [
            ["single ring drop: rest height (COM z; exact 25.0 mm) [mm]", f"{1e3 * d4.rest_height:.1f}",
             f"{1e3 * d1.rest_height:.1f}", f"{1e3 * (d4.rest_height - d1.rest_height):+.1f}"],
            ["single ring drop: rebound (e = 0.5, from 0.3 m) [mm]", f"{1e3 * d4.rebound:.1f}",
             f"{1e3 * d1.rebound:.1f}", f"{1e3 * (d4.rebound - d1.rebound):+.1f}"],
            ["single ring drop: first-impact impulse [N s]", f"{d4.first_impulse:.3f}", f"{d1.first_impulse:.3f}",
             f"{100 * (d4.first_impulse / max(d1.first_impulse, 1e-12) - 1):+.1f} %"],
            ["single ring drop: deepest below ground [mm]", f"{1e3 * d4.penetration:.3f}",
             f"{1e3 * d1.penetration:.3f}", ""],
        ]),
        "",
        f"({time.perf_counter() - t0:.0f} s in all.)",
    ]
    if args.no_pybullet:
        lines.append("pybullet comparison skipped (--no-pybullet).")
    else:
        try:
            import pybullet  # noqa: F401
        except ImportError:
            lines.append("pybullet is not installed: comparison skipped (`pip install pybullet==3.2.7`, "
                         "or the `bench` extra).")
        else:
            from . import pybullet_ref

            models = {}  # our collision spheres for pybullet; identical objects share one model
            for obj in scene.objects:
                key = (obj.source, obj.scale, obj.units, obj.particles)
                if key not in models:
                    models[key] = obj.prepare()[0]
            spheres = [(m.collision_position, m.boundary_radius) for m in
                       (models[(o.source, o.scale, o.units, o.particles)] for o in scene.objects)]
            lines += ["", pybullet_ref.comparison_table(
                scene, spheres, rings_ms=(two["mean"], two["max"]), pile_ms=(pile["avg"], pile["max"]),
                fragments=args.fragments, seconds=args.seconds, progress=ctx.progress,
                rings_note=f"median of {args.repeat} runs" if args.repeat > 1 else "")]
    print("\n".join(lines))
    print_contact(ctx, scene, args, time.perf_counter())
    return 0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scene", default="thirteen_rings",
                   help="the rings scene: a scene file or a built-in scene (default thirteen_rings)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scene value, e.g. --set simulation.substeps=4 (repeatable)")
    p.add_argument("--fragments", type=int, default=216, help="fragments in the pile (default 216)")
    p.add_argument("--seconds", type=float, default=3.0, help="simulated time of the pile [s] (default 3)")
    p.add_argument("--repeat", type=int, default=3,
                   help="runs of each rings row; the table shows their medians (default 3)")
    p.add_argument("--arch", default="cpu")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument("--contact-only", action="store_true",
                   help="only the surface-contact table (rest heights, ring drop, 13 rings per contact mode)")
    p.add_argument("--contact-frames", type=int, default=0,
                   help="frames of each 13-ring run in the surface-contact table (default 0: the scene's)")
    p.add_argument("--contact-out", default="docs/benchmarks/contact.md",
                   help="where the surface-contact table is written (default docs/benchmarks/contact.md; '' for none)")
    p.add_argument("--no-pybullet", action="store_true",
                   help="skip the pybullet comparison (run when pybullet is installed)")
