"""``taichi-frac bench dynamics``: the rigid-body table of issue 3 (13 rings two- vs
single-scale, a pile of loose fragments, what two-scale changes), driving the World directly.
The report's ``grouping`` part measures the same question per boundary grouping n through
``Simulation``; this table stays as issue 3's quick check.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

TORUS_MAJOR, TORUS_MINOR = 0.1, 0.025


def _ring_model(particles: int):
    import tetgen
    import trimesh

    from ..model import build_body_model

    mesh = trimesh.creation.torus(TORUS_MAJOR, TORUS_MINOR, major_sections=64, minor_sections=20)
    gen = tetgen.TetGen(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    vertices, tets = gen.tetrahedralize(order=1, mindihedral=10, minratio=1.5,
                                        maxvolume=mesh.volume / (1.55 * particles))[:2]
    return build_body_model(vertices, tets, 2400.0, boundary_group_size=4)


def _fragment_model():
    import tetgen
    import trimesh

    from ..model import build_body_model

    mesh = trimesh.creation.icosphere(subdivisions=1, radius=0.02)
    gen = tetgen.TetGen(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    vertices, tets = gen.tetrahedralize(order=1, maxvolume=mesh.volume / 30)[:2]
    return build_body_model(vertices, tets, 2400.0, boundary_group_size=4)


def _pile_poses(count: int, rng):
    """A loose pile: rings in layers of 4-5, tilted at random, 2 cm apart vertically."""
    poses = []
    for k in range(count):
        layer, slot = divmod(k, 5)
        angle = 2 * math.pi * slot / 5 + 0.6 * layer
        centre = np.array([0.12 * math.cos(angle), 0.12 * math.sin(angle), 0.08 + 0.07 * layer])
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        tilt = rng.uniform(0.1, 0.5)
        q = np.concatenate([[math.cos(tilt / 2)], math.sin(tilt / 2) * axis])
        poses.append((centre, q))
    return poses


def _run_frames(world, frames, frame_dt, substeps):
    times = []
    for _ in range(frames):
        t = time.perf_counter()
        world.advance(frame_dt, substeps)
        times.append(time.perf_counter() - t)
    return np.array(times) * 1e3


def _ground_penetration(world, bodies):
    depth = 0.0
    for b in bodies:
        p = world.particle_state(b)
        depth = max(depth, float(np.max(p["radius"] - p["position"][:, 2])))
    return depth


def run_dynamics(args) -> int:
    """Print issue 3's table (see the module docstring)."""
    from .. import runtime
    from ..dynamics import DynamicsOptions, World, WorldCapacity

    runtime.init(args.arch)
    frame_dt, frames, substeps = 1.0 / args.fps, int(round(args.seconds * args.fps)), args.substeps
    t0 = time.perf_counter()
    ring = _ring_model(args.ring_particles)
    fragment = _fragment_model()
    print(f"ring: {ring.tet_count} physics, {ring.surface_particle_count} surface, "
          f"{ring.boundary_particle_count} boundary particles; fragment: {fragment.tet_count} tets, "
          f"{fragment.boundary_particle_count} boundary particles; meshing {time.perf_counter() - t0:.1f} s")
    capacity = WorldCapacity(max_bodies=max(args.rings, args.fragments) + 8,
                             max_boundary_particles=max(args.rings * ring.surface_particle_count,
                                                        args.fragments * fragment.surface_particle_count) + 64,
                             max_contacts=200_000)
    world = World(capacity, DynamicsOptions(solver_iterations=args.iterations), arch=args.arch)
    results = {}
    for mode, single in (("two-scale", False), ("single-scale", True)):
        # Single ring dropped flat-ish: rest height, rebound height, first-impact impulse.
        world.clear()
        world.add_ground(0.0, friction=0.5, restitution=0.5)
        body = world.add_body(ring, (0, 0, 0.3), (math.cos(0.05), math.sin(0.05), 0, 0), single_scale=single,
                              restitution=0.5)
        first_impulse, bounced, peak_after, last_vz = None, False, 0.0, 0.0
        for _ in range(int(2.0 * args.fps)):
            world.advance(frame_dt, substeps)
            rows = world.impacts()
            if first_impulse is None and len(rows["body"]):
                first_impulse = float(np.linalg.norm(rows["impulse"].sum(axis=0)))
            state = world.body_state([body])
            vz = state["linear_velocity"][0][2]
            if first_impulse is not None and vz > 0:
                bounced = True
            if bounced:
                peak_after = max(peak_after, state["position"][0][2])
        rest_height = world.body_state([body])["position"][0][2]
        # 13 rings in a pile.
        world.clear()
        world.add_ground(0.0, friction=0.5, restitution=0.2)
        rng = np.random.default_rng(1)
        bodies = [world.add_body(ring, c, q, single_scale=single) for c, q in _pile_poses(args.rings, rng)]
        particles = sum(world._body_range[b][1] for b in bodies)
        world.advance(frame_dt, substeps)  # compile outside the timing
        ms = _run_frames(world, frames, frame_dt, substeps)
        results[mode] = dict(
            particles=particles, avg=ms.mean(), max=ms.max(), rest=world.body_state(bodies)["position"],
            penetration=_ground_penetration(world, bodies), rest_height=rest_height,
            rebound=peak_after - rest_height, first_impulse=first_impulse or 0.0,
            substeps=world.stats.total_substeps, overflows=world.stats.total_contact_overflows,
            asleep=int(world.body_state(bodies)["sleeping"].sum()),
        )
    # Pile of loose fragments (two-scale).
    world.clear()
    world.add_ground(0.0)
    for sign in (-1, 1):
        world.add_static_box((sign * 0.22, 0, 0.3), (0.02, 0.24, 0.3))
        world.add_static_box((0, sign * 0.22, 0.3), (0.24, 0.02, 0.3))
    side = math.ceil(args.fragments ** (1 / 3))
    rng = np.random.default_rng(2)
    cells = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), -1).reshape(-1, 3)[: args.fragments]
    frag_bodies = [world.add_body(fragment, (c - [side / 2 - 0.5, side / 2 - 0.5, -0.5]) * 0.05 + rng.normal(0, 0.003, 3),
                                  (1, 0, 0, 0), (0, 0, 0), rng.normal(0, 2.0, 3)) for c in cells]
    world.advance(frame_dt, substeps)
    frag_ms = _run_frames(world, frames, frame_dt, substeps)

    two, one = results["two-scale"], results["single-scale"]
    rest_error = np.linalg.norm(two["rest"] - one["rest"], axis=1)
    lines = [
        f"13 rings ({args.rings} x torus R {TORUS_MAJOR} m r {TORUS_MINOR} m), {args.seconds:g} s at "
        f"{1e3 * frame_dt:g} ms frames, {substeps} substeps (+ anti-tunnelling), {args.iterations} iterations",
        "",
        "| scene | collision particles | two-scale ms/frame avg / max | single-scale ms/frame avg / max | speed-up |",
        "|---|---|---|---|---|",
        f"| {args.rings} rings | {two['particles']} / {one['particles']} | {two['avg']:.2f} / {two['max']:.2f} | "
        f"{one['avg']:.2f} / {one['max']:.2f} | {one['avg'] / two['avg']:.1f}x |",
        f"| {args.fragments} fragments (two-scale) | {sum(world._body_range[b][1] for b in frag_bodies)} | "
        f"{frag_ms.mean():.2f} / {frag_ms.max():.2f} | | |",
        "",
        "| what two-scale changes against single-scale | two-scale | single-scale | difference |",
        "|---|---|---|---|",
        f"| single ring rest height (COM z, true 0.025 m) [m] | {two['rest_height']:.4f} | {one['rest_height']:.4f} | "
        f"{two['rest_height'] - one['rest_height']:+.4f} |",
        f"| single ring rebound (e = 0.5, from 0.3 m) [m] | {two['rebound']:.4f} | {one['rebound']:.4f} | "
        f"{two['rebound'] - one['rebound']:+.4f} |",
        f"| first-impact impulse [N s] | {two['first_impulse']:.4f} | {one['first_impulse']:.4f} | "
        f"{100 * (two['first_impulse'] / max(one['first_impulse'], 1e-12) - 1):+.1f} % |",
        f"| pile rest positions, mean / max COM distance [m] | | | {rest_error.mean():.4f} / {rest_error.max():.4f} |",
        f"| penetration into the ground at rest [mm] | {1e3 * two['penetration']:.3f} | {1e3 * one['penetration']:.3f} | |",
        f"| rings asleep at the end | {two['asleep']} | {one['asleep']} | |",
        f"| contacts lost to capacity | {two['overflows']} | {one['overflows']} | |",
    ]
    try:
        import pybullet  # noqa: F401
        lines.append("pybullet is importable but the comparison scene is not implemented yet")
    except ImportError:
        lines.append("")
        lines.append("pybullet not importable: comparison skipped")
    print("\n".join(lines))
    return 0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rings", type=int, default=13)
    p.add_argument("--ring-particles", type=int, default=5400, help="physics particles per ring (default 5400)")
    p.add_argument("--fragments", type=int, default=216)
    p.add_argument("--seconds", type=float, default=3.0)
    p.add_argument("--fps", type=float, default=50.0)
    p.add_argument("--substeps", type=int, default=4)
    p.add_argument("--iterations", type=int, default=10)
    p.add_argument("--arch", default="cpu")
