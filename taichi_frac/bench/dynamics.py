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
from typing import NamedTuple

import numpy as np

from .common import BenchContext, deepest_below_ground, load_average, md_table, ms_pair, provenance

#: Motion per substep [particle radii] of the table's coarse-stepping row. Measured with
#: the rings unbreakable (worst collision-sphere depth below the floor during a 3 s run):
#: 0.16 radii; with fracture, small chips went up to 0.87 physics-particle radii into the
#: floor (the scene test allows 1), so the scene keeps 1.5 (scenes/thirteen_rings.toml).
COARSE_FRACTION = 3.0


def _fragment_model():
    import tetgen
    import trimesh

    from ..model import build_body_model
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
    from ..dynamics import DynamicsOptions
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
    from ..scenes import load_scene
    from . import grouping
    from .common import Progress, warm_up

    ctx = BenchContext(arch=args.arch, progress=Progress(enabled=not args.quiet))
    scene = load_scene(args.scene, args.set or [])
    sim = scene.simulation
    t0 = time.perf_counter()
    warm_up(ctx)
    if args.contact_only:
        return _print_contact(ctx, scene, args, t0)
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
    _print_contact(ctx, scene, args, time.perf_counter())
    return 0


def _print_contact(ctx: BenchContext, scene, args, t0: float) -> int:
    """The surface-contact table, printed and written to ``args.contact_out``."""
    from pathlib import Path

    from ..scenes import load_scene
    from .contact_grouping import GROUPING_SEED_SHIFTS, grouping_section
    from .tables import other_seeds

    frames = args.contact_frames or None

    def seeded(shifts):  # the scene with its own crack seeds, then shifted by each of ``shifts``
        return [scene] + [load_scene(args.scene, (args.set or []) + other_seeds(scene, k)) for k in shifts if k]

    text = "\n".join([
        "## Surface contacts",
        "",
        f"Generated by `taichi-frac bench dynamics{' --contact-only' if args.contact_only else ''}"
        f"{f' --contact-frames {frames}' if frames else ''}` (arch {args.arch}; {provenance()}, "
        f"load average {load_average()} at the start: "
        "times compare within this page): the same bodies with the "
        "contacts computed from the true surface (patches of the boundary groups' surface triangles, grouped by "
        "default: 12 surface particles a sphere on a body of 384 or more whose patches keep their facets, else 4), "
        "from the boundary spheres (4 a sphere), and from the single-scale spheres, in one run. The ring drop is "
        "measured against single-scale, whose spheres sit on tets' centroids inside the surface; the "
        "frictionless landing against the closed form for a rigid body struck at one point.",
        "",
        contact_section(ctx, scene, frames, seeded(CONTACT_SEED_SHIFTS)),
        "",
        "### Surface contacts against the boundary grouping n",
        "",
        "With surface contacts the spheres only find which patches may touch, and the patches set the rest "
        "heights and where a landing strikes (the patch's lowest point): coarser spheres (n adjacent surface "
        "particles each) are fewer to test. A body of few tets gets a few large spheres whose patches fold round "
        "its edges; the default keeps n = 4 for it. In one run, after the table above:",
        "",
        grouping_section(ctx, scene, frames, seeded(GROUPING_SEED_SHIFTS)),
        "",
        f"({time.perf_counter() - t0:.0f} s in all.)",
    ])
    print(text)
    if args.contact_out:
        Path(args.contact_out).write_text(text + "\n")
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


# ---------------------------------------------------------------- surface contacts

#: The contact modes compared side by side: (label, single_scale, surface_contact).
CONTACT_MODES = (("two-scale, surface contacts", False, True), ("two-scale, sphere contacts", False, False),
                 ("single-scale, sphere contacts", True, False))


def _with_contact(scene, single: bool, surface: bool):
    import dataclasses

    return dataclasses.replace(scene, simulation=dataclasses.replace(
        scene.simulation, single_scale=single, surface_contact=surface))


def _model(vertices, tets, single: bool, surface: bool, group: int = 4, coarse: int | None = None,
           density: float = 2400.0):
    """The BodyModel a contact mode collides with: single-scale n = 1; two-scale n =
    ``group``, and with surface contacts the coarse n of large bodies (``coarse``, default
    ``ParticleOptions().surface_group_size``, as a scene builds it; 0: ``group`` for all)."""
    from ..model import build_body_model
    from ..options import ParticleOptions

    if coarse is None:
        coarse = ParticleOptions().surface_group_size
    return build_body_model(vertices, tets, density, boundary_group_size=1 if single else group,
                            coarse_group_size=coarse if surface else 0)


def _ring_drop(ctx: BenchContext, single: bool, surface: bool, group: int = 4, coarse: int | None = None) -> dict:
    """The report's single-ring drop (``grouping.measure_drop`` on ``grouping.drop_scene``):
    rest height, rebound, first-impact impulse and the deepest point of the true surface
    below the ground. ``group``, ``coarse``: the boundary grouping n of two-scale and the
    coarse n of surface contacts (``_model``)."""
    from . import grouping

    scene = _with_contact(grouping.drop_scene(1 if single else group, coarse=coarse), single, surface)
    drop = grouping.measure_drop(ctx, scene)
    return dict(rest=drop.rest_height, rebound=drop.rebound, impulse=drop.first_impulse, depth=drop.surface_depth)


#: Tilts [degrees] of the frictionless landing (``_landing``): ones at which one vertex of
#: the 40 x 12-section torus is clearly the lowest.
LANDING_TILTS = (10, 20, 25, 30)


def _landing(ctx: BenchContext, single: bool, surface: bool, group: int = 4, coarse: int | None = None) -> list[float]:
    """The torus of the dynamics tests (``bodies.ring_model``) landing without friction at
    each of ``LANDING_TILTS`` (``bodies.tilted_landing``, e = 0.5, from 0.1 m): the first
    impact's normal impulse relative to the closed form, less 1."""
    import math

    from ..dynamics import DynamicsOptions
    from . import bodies

    ring = bodies.ring_model()
    model = _model(ring.vertices, ring.tets, single, surface, group, coarse, bodies.DENSITY)
    errors = []
    for degrees in LANDING_TILTS:
        world = ctx.world()
        world.clear()
        world.set_options(DynamicsOptions(single_scale=single, surface_contact=surface))
        impulse, exact, _ = bodies.tilted_landing(world, model, math.radians(degrees))
        errors.append(impulse / exact - 1.0)
    return errors


def landing_row(errors) -> str:
    """``_landing``'s errors as a table cell [%]."""
    return " / ".join(f"{100 * e:+.1f}" for e in errors)


LANDING_LABEL = ("torus (40 x 12 sections, the tests') landing on its lowest vertex without friction, tilted "
                 + " / ".join(str(t) for t in LANDING_TILTS) + "°, e = 0.5, from 0.1 m: first impact's normal "
                 "impulse − the closed form (1 + e) v / (1/m + (r × n)·I⁻¹(r × n)) [%]")


def _cube_rest(ctx: BenchContext, single: bool, surface: bool, on_edge: bool) -> dict:
    """A 0.1 m porcelain cube let down flat (or on an edge, turned 45 degrees) 1 mm above
    the ground, restitution 0: its centre-of-mass height after 1 s (0.3 s on the edge,
    before it can tip) and the deepest point of its surface below the ground."""
    import math

    import trimesh

    from ..dynamics import DynamicsOptions
    from ..geometry.tetra import tetrahedralize
    from . import grouping

    mesh = tetrahedralize(trimesh.creation.box((0.1, 0.1, 0.1)), target_tets=5000)
    model = _model(mesh.vertices, mesh.tets, single, surface)
    world = ctx.world()
    world.clear()
    world.set_options(DynamicsOptions(single_scale=single, surface_contact=surface))
    world.add_ground(0.0, restitution=0.0)
    if surface:
        low = -float(model.vertices[:, 2].min())
    else:
        layer = (model.particle_position[model.surface_particles], model.particle_radius[model.surface_particles]) \
            if single else (model.collision_position, model.boundary_radius)
        low = -float(np.min(layer[0][:, 2] - layer[1]))
    half = math.pi / 8
    q = (math.cos(half), math.sin(half), 0.0, 0.0) if on_edge else (1.0, 0.0, 0.0, 0.0)
    height = low if not on_edge else (0.05 * math.sqrt(2.0) + (low - 0.05))
    body = world.add_body(model, (0, 0, height + 1e-3), q, restitution=0.0)
    depth = 0.0
    for _ in range(15 if on_edge else 50):
        world.advance(0.02, 10)
        depth = max(depth, grouping.surface_depth(model, world.body_state([body])))
    return dict(rest=float(world.body_state([body])["position"][0][2]), depth=depth)


#: Tets of the cubes stacked in the contact table (``_cube_on_cube``): a fine cube, whose
#: patches fold round its edges only there, and a coarse one, all of whose patches fold.
CUBE_STACK_TETS = (5000, 60)


def _cube_on_cube(ctx: BenchContext, single: bool, surface: bool, tets: int, group: int = 4,
                  coarse: int | None = None) -> float:
    """A 0.1 m porcelain cube of about ``tets`` tets let down 1 mm above another resting
    on the ground, offset 10 / 5 mm, restitution 0: the upper one's centre-of-mass height
    above the lower one's after 1 s, less the exact 0.1 m [m]. ``group``, ``coarse``: as
    ``_model``."""
    import trimesh

    from ..dynamics import DynamicsOptions
    from ..geometry.tetra import tetrahedralize
    from .bodies import stack_cubes

    mesh = tetrahedralize(trimesh.creation.box((0.1, 0.1, 0.1)), target_tets=tets)
    model = _model(mesh.vertices, mesh.tets, single, surface, group, coarse)
    world = ctx.world()
    world.clear()
    world.set_options(DynamicsOptions(single_scale=single, surface_contact=surface))
    layer = (model.particle_position[model.surface_particles], model.particle_radius[model.surface_particles]) \
        if single else (model.collision_position, model.boundary_radius)
    bottom, top = stack_cubes(world, model, -float(np.min(layer[0][:, 2] - layer[1])))
    for _ in range(50):
        world.advance(0.02, 10)
    z = world.body_state([bottom, top])["position"][:, 2]
    return float(z[1] - z[0] - 0.1)


#: Rings in the contact table's stack (``_ring_stack``).
STACK_RINGS = 5


def _ring_stack(ctx: BenchContext, single: bool, surface: bool) -> dict:
    """``STACK_RINGS`` unbreakable tori (major 0.1, minor 0.025 m) stacked flat, each let
    down 0.5 mm above the one below, restitution 0, for 2 s: the top ring's centre-of-mass
    height against exact (one tube diameter a ring), how far any ring moved in the last
    second, and whether all sleep."""
    from ..dynamics import DynamicsOptions
    from .bodies import ring_model, settle_and_hold, stack_rings

    world = ctx.world()
    world.clear()
    world.set_options(DynamicsOptions(single_scale=single, surface_contact=surface))
    ring = ring_model()
    rings = stack_rings(world, _model(ring.vertices, ring.tets, single, surface, density=ring.density), STACK_RINGS)
    settled, state = settle_and_hold(world, rings, 50, 50)
    return dict(top=float(state["position"][-1][2]) - (0.025 + 0.05 * (STACK_RINGS - 1)),
                drift=float(np.max(np.linalg.norm(state["position"] - settled, axis=1))),
                asleep=int(state["sleeping"].sum()))


#: Heaps of ring chips in the contact table (``bodies.ring_chips`` / ``drop_heap`` seeds),
#: 36 chips each, and the times [s] their sleeping chips are counted at.
HEAPS = 4
HEAP_TIMES = (1.0, 2.0, 3.0)


def _chip_heaps(ctx: BenchContext, single: bool, surface: bool) -> list:
    """Chips asleep at each of ``HEAP_TIMES``, summed over the ``HEAPS`` heaps
    (``bodies.heap_asleep``), and the chips in all."""
    from ..dynamics import DynamicsOptions
    from .bodies import heap_asleep

    asleep = [0] * len(HEAP_TIMES)
    chips = 0
    for seed in range(HEAPS):
        world = ctx.world()
        world.clear()
        world.set_options(DynamicsOptions(single_scale=single, surface_contact=surface))
        counts, total = heap_asleep(world, seed, HEAP_TIMES)
        asleep = [n + c for n, c in zip(asleep, counts)]
        chips += total
    return asleep + [chips]


#: Rounds of the contact table's unbroken 13 rings: each runs every mode once, back to back,
#: and the modes are compared on the median over the rounds of each round's ratio. A mode's
#: first run in a process compiles its kernels inside one of its frames, so the first frame
#: is left out. On a machine shared with other jobs a run's time varies by a third from run
#: to run: in twelve rounds of one build surface contacts took 1.19-2.49 times the sphere
#: contacts' time (median 1.63), so the fastest of a few runs of each can land anywhere there.
CONTACT_RING_RUNS = 9

#: Crack-seed shifts of the contact table's 13 rings with fracture: the scene's own seeds
#: (0) and the report's seven other sets (``tables.RINGS_SEED_SHIFTS``). A run with
#: fracture is one chaotic draw whose fragment count, and so its cost, moves with the
#: contact mode as much as with the seeds; the modes are compared on their mean over these
#: sets. Over four sets, two runs of the same code put surface contacts at 1.88 and 2.10
#: times the sphere contacts' time.
CONTACT_SEED_SHIFTS = (0, 13, 26, 39, 52, 65, 78, 91)

#: Runs of each mode on each seed set with fracture, interleaved; the fastest counts (a
#: set's runs of one mode are the same run: the fracture is reproducible, its time not).
CONTACT_FRACTURE_RUNS = 2


class RingRun(NamedTuple):
    """One 13-ring run: its mean ms/frame (the first frame left out); the ms per frame, over
    all frames, in the dynamics and in the fracture stage (analysis and split); its
    substeps per frame; the contacts of its last substep, its fragments, and its bodies
    asleep at the end and in all."""

    ms: float
    dynamics_ms: float
    fracture_ms: float
    substeps: float
    contacts: int
    fragments: int
    asleep: int
    bodies: int


class RingRuns(NamedTuple):
    """A contact mode's runs of one scene (``_rings_fastest``): ``fastest``, the fastest run
    (its counts are every run's: the fracture is reproducible, its time not), and
    ``ms``, every run's ms/frame in round order."""

    fastest: RingRun
    ms: list


def _rings_ms(ctx: BenchContext, scene, single: bool, surface: bool, fracture: bool, frames) -> RingRun:
    """One 13-ring run in one contact mode (``RingRun``)."""
    from .tables import run_scene

    label = [m[0] for m in CONTACT_MODES if m[1] == single and m[2] == surface][0]
    sim, summary, counts = run_scene(ctx, _with_contact(scene, single, surface), f"13 rings, {label}",
                                     fracture=fracture, frames=frames)
    sleeping = sim.world.body_state()["sleeping"]
    per_frame = 1000.0 / max(summary.frames, 1)
    return RingRun(float(summary.ms_per_frame["mean_after_first"]), sim.times.dynamics * per_frame,
                   (sim.times.fracture_analysis + sim.times.fragment_split) * per_frame,
                   counts["substeps_per_frame"], sim.world.stats.contacts, summary.fragments, int(sleeping.sum()),
                   len(sleeping))


def _rings_fastest(ctx: BenchContext, scenes, fracture: bool, frames, runs: int) -> dict:
    """Each contact mode's 13 rings on each of ``scenes``, ``runs`` times interleaved (every
    mode and scene once per round): mode label -> one ``RingRuns`` per scene."""
    done = {(m[0], k): [] for m in CONTACT_MODES for k in range(len(scenes))}
    for _ in range(runs):
        for k, scene in enumerate(scenes):
            for m in CONTACT_MODES:
                done[m[0], k].append(_rings_ms(ctx, scene, m[1], m[2], fracture, frames))
    return {m[0]: [RingRuns(min(done[m[0], k], key=lambda run: run.ms), [run.ms for run in done[m[0], k]])
                   for k in range(len(scenes))] for m in CONTACT_MODES}


def contact_section(ctx: BenchContext, scene, frames=None, seed_scenes=None) -> str:
    """The surface contacts against sphere contacts, side by side in one run: rest heights
    against exact, the ring drop against single-scale, and the 13 rings' ms/frame without
    fracture (the scene) and with it (the mean over ``seed_scenes``, the scene with other
    crack seeds: ``CONTACT_SEED_SHIFTS``; default the scene alone) (markdown)."""
    import math

    drops = {m[0]: _ring_drop(ctx, m[1], m[2]) for m in CONTACT_MODES}
    landings = {m[0]: _landing(ctx, m[1], m[2]) for m in CONTACT_MODES}
    flat = {m[0]: _cube_rest(ctx, m[1], m[2], on_edge=False) for m in CONTACT_MODES}
    edge = {m[0]: _cube_rest(ctx, m[1], m[2], on_edge=True) for m in CONTACT_MODES}
    stacks = {m[0]: _ring_stack(ctx, m[1], m[2]) for m in CONTACT_MODES}
    cubes = {tets: {m[0]: _cube_on_cube(ctx, m[1], m[2], tets) for m in CONTACT_MODES} for tets in CUBE_STACK_TETS}
    labels = [m[0] for m in CONTACT_MODES]
    ref = drops[labels[2]]
    rows = [
        ["torus (major 0.1, minor 0.025 m) at rest, COM z − exact 25.0 mm [mm]"]
        + [f"{1e3 * (drops[k]['rest'] - 0.025):+.2f}" for k in labels],
        ["0.1 m cube flat at rest, COM z − exact 50.0 mm [mm]"] + [f"{1e3 * (flat[k]['rest'] - 0.05):+.2f}"
                                                                  for k in labels],
        [f"0.1 m cube on an edge (0.3 s), COM z − exact {50 * math.sqrt(2):.2f} mm [mm]"]
        + [f"{1e3 * (edge[k]['rest'] - 0.05 * math.sqrt(2)):+.2f}" for k in labels],
        *[[f"0.1 m cube on a cube ({tets} tets each, offset 10 / 5 mm), COM z above the lower − exact 100.0 mm "
           "[mm]"] + [f"{1e3 * cubes[tets][k]:+.2f}" for k in labels] for tets in CUBE_STACK_TETS],
        [f"{STACK_RINGS} tori stacked flat: top COM z − exact {25 + 50 * (STACK_RINGS - 1)}.0 mm [mm] / "
         "largest move 1-2 s [mm] / asleep at 2 s"]
        + [f"{1e3 * stacks[k]['top']:+.2f} / {1e3 * stacks[k]['drift']:.2f} / {stacks[k]['asleep']} of {STACK_RINGS}"
           for k in labels],
        ["ring drop: rebound (e = 0.5, from 0.3 m) [mm], vs single-scale"]
        + [f"{1e3 * drops[k]['rebound']:.1f} ({100 * (drops[k]['rebound'] / max(ref['rebound'], 1e-12) - 1):+.1f} %)"
           for k in labels],
        ["ring drop: first-impact impulse [N s], vs single-scale"]
        + [f"{drops[k]['impulse']:.3f} ({100 * (drops[k]['impulse'] / max(ref['impulse'], 1e-12) - 1):+.1f} %)"
           for k in labels],
        [LANDING_LABEL] + [landing_row(landings[k]) for k in labels],
        ["deepest point of the true surface below the ground, ring / cube flat / cube edge [mm]"]
        + [f"{1e3 * drops[k]['depth']:.2f} / {1e3 * flat[k]['depth']:.2f} / {1e3 * edge[k]['depth']:.2f}"
           for k in labels],
    ]
    heaps = {m[0]: _chip_heaps(ctx, m[1], m[2]) for m in CONTACT_MODES}
    rows.append([f"{HEAPS} heaps of 36 ring chips (3-50 tets) dropped in four layers: chips asleep at "
                 + " / ".join(f"{t:g}" for t in HEAP_TIMES) + " s, of all"]
                + [" / ".join(str(v) for v in heaps[k][:-1]) + f" of {heaps[k][-1]}" for k in labels])
    off = _rings_fastest(ctx, [scene], False, frames, CONTACT_RING_RUNS)
    rounds = {k: np.asarray(off[k][0].ms) for k in labels}
    ratios = {k: rounds[k] / rounds[labels[1]] for k in labels}
    rows.append([f"13 rings, fracture off, ms/frame, median of {CONTACT_RING_RUNS} rounds of every mode once "
                 "(ratio to sphere contacts: median of the rounds' ratios, least-most)"]
                + [f"{np.median(rounds[k]):.2f} ({np.median(ratios[k]):.2f}x, {ratios[k].min():.2f}-"
                   f"{ratios[k].max():.2f})" for k in labels])
    rows.append(["13 rings, fracture off, contacts in the last substep"]
                + [f"{off[k][0].fastest.contacts:,}" for k in labels])
    scenes = seed_scenes or [scene]
    on = _rings_fastest(ctx, scenes, True, frames, CONTACT_FRACTURE_RUNS)
    fastest = {k: [runs.fastest for runs in on[k]] for k in labels}
    ms = {k: float(np.mean([r.ms for r in fastest[k]])) for k in labels}
    sets = f"{len(scenes)} seed sets" if len(scenes) > 1 else "the scene's seeds"
    rows.append([f"13 rings, fracture on, ms/frame, mean over {sets} of each set's fastest of "
                 f"{CONTACT_FRACTURE_RUNS} interleaved runs (ratio of means to sphere contacts)"]
                + [f"{ms[k]:.1f} ({ms[k] / ms[labels[1]]:.2f}x)" for k in labels])
    rows.append([f"13 rings, fracture on, mean over {sets}: ms per frame in the dynamics / in the fracture "
                 "stage (analysis and split), over all frames / substeps per frame (0 in a frame when every body "
                 "sleeps)"]
                + [" / ".join(f"{np.mean([getattr(r, name) for r in fastest[k]]):.{digits}f}"
                              for name, digits in (("dynamics_ms", 1), ("fracture_ms", 1), ("substeps", 2)))
                   for k in labels])
    rows.append(["13 rings, fracture on, per seed set: ms/frame / fragments"]
                + [", ".join(f"{r.ms:.1f} / {r.fragments}" for r in fastest[k]) for k in labels])
    rows.append([f"13 rings, fracture on, mean over {sets}: contacts in the last substep / fragments"]
                + [f"{np.mean([r.contacts for r in fastest[k]]):,.0f} / "
                   f"{np.mean([r.fragments for r in fastest[k]]):.1f}" for k in labels])
    rows.append(["13 rings, fracture on, per seed set: bodies asleep at the end / bodies"]
                + [", ".join(f"{r.asleep} / {r.bodies}" for r in fastest[k]) for k in labels])
    return md_table(["measure", *labels], rows)
