"""Part 2a: two-scale against single-scale dynamics, boundary grouping n = 1, 2, 4, 8.

n is ``ParticleOptions.boundary_group_size``: every n adjacent surface particles merge into
one collision sphere. n = 1 is the single-scale reference (every surface particle collides
on its own). For each n:

- **time**: ms per 20 ms frame of the 13-ring scene with the rings unbreakable
  (``fracture=False``), every ring built with that n;
- **error** against n = 1, on a single ring (unbreakable, restitution 0.5) dropped almost flat
  from 0.3 m: its rest height (the exact value for a flat torus is its minor radius, 0.025 m),
  the rebound height after the first bounce, the first-impact impulse and the deepest
  collision sphere below the ground.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .common import SCENES, BenchContext, Section, deepest_below_ground, md_table, ms_pair, pyplot

GROUP_SIZES = (1, 2, 4, 8)
MINOR_RADIUS = 0.025  # m: COM height of a torus lying flat on the ground
DROP_HEIGHT = 0.3  # m
TILT = 0.1  # rad about x: lands almost flat, on one side first


def drop_scene(group_size: int, particles: int = 5000, seconds: float = 3.0, coarse: int | None = None):
    """The single-ring drop, built with the scene API. ``coarse``: the ring's
    ``surface_group_size`` (None: the default; read only with surface contacts)."""
    from taichi_frac.options import ParticleOptions
    from taichi_frac.scenes import Collider, Scene, SceneObject, SimulationOptions

    ring = SceneObject(
        name="ring", primitive=f"torus:major=0.1,minor={MINOR_RADIUS}", material="porcelain", breakable=False,
        position=(0.0, 0.0, DROP_HEIGHT), orientation=(math.cos(TILT / 2), math.sin(TILT / 2), 0.0, 0.0),
        friction=0.5, restitution=0.5,
        particles=ParticleOptions(target_particles=particles, boundary_group_size=group_size,
                                  **({} if coarse is None else {"surface_group_size": coarse})),
    )
    return Scene(name=f"ring_drop_n{group_size}", objects=[ring],
                 colliders=[Collider.ground(0.0, friction=0.5, restitution=0.5)],
                 simulation=SimulationOptions(fps=50, duration=seconds, substeps=10))


@dataclass
class DropResult:
    group_size: int
    collision_particles: int
    mean_radius: float
    rest_height: float
    rebound: float
    first_impulse: float
    penetration: float
    surface_depth: float  # [m] deepest vertex of the true surface below the ground


def surface_depth(model, state) -> float:
    """[m] deepest vertex of ``model``'s surface below z = 0 at the pose in ``state`` (row 0)."""
    from taichi_frac.kinematics.quaternion import quaternion_matrix

    z = (model.vertices @ quaternion_matrix(state["orientation"][0]).T + state["position"][0])[:, 2]
    return max(0.0, -float(z.min()))


def measure_drop(ctx: BenchContext, scene) -> DropResult:
    """Run the drop frame by frame and measure rest height, rebound, first impulse, the
    deepest collision sphere and the deepest surface vertex below the ground (sampled at
    every frame end)."""
    from taichi_frac.simulation import Simulation

    sim = Simulation(scene, output=False, world=ctx.world())
    body = sim.world.body_ids[0]
    model = sim.records[body].model
    seen = dict(first_impulse=None, bounced=False, peak=-np.inf, penetration=0.0, depth=0.0)

    def frame_done(frame, total, t, fragments, fps):
        rows = sim.world.impacts()
        if seen["first_impulse"] is None and len(rows["body"]):
            seen["first_impulse"] = float(np.linalg.norm(rows["impulse"].sum(axis=0)))
        state = sim.world.body_state([body])
        if seen["first_impulse"] is not None and state["linear_velocity"][0][2] > 0:
            seen["bounced"] = True
        if seen["bounced"] and not seen.get("landed"):
            seen["peak"] = max(seen["peak"], state["position"][0][2])
            seen["landed"] = state["linear_velocity"][0][2] < 0 and seen["peak"] > state["position"][0][2]
        seen["penetration"] = max(seen["penetration"], deepest_below_ground(sim.world, [body]))
        seen["depth"] = max(seen["depth"], surface_depth(model, state))

    sim.progress = frame_done
    sim.run()
    rest = float(sim.world.body_state([body])["position"][0][2])
    n = model.boundary_group_size
    return DropResult(
        group_size=n, collision_particles=model.boundary_particle_count,
        mean_radius=float(model.boundary_radius.mean()), rest_height=rest,
        rebound=float(seen["peak"] - rest) if seen["bounced"] else 0.0,
        first_impulse=seen["first_impulse"] or 0.0, penetration=max(seen["penetration"], 0.0),
        surface_depth=seen["depth"])


def rings_scene(group_size: int):
    """scenes/thirteen_rings.toml with every ring built with boundary_group_size n."""
    import tomllib

    from taichi_frac.scenes import load_scene

    names = [o["name"] for o in tomllib.loads((SCENES / "thirteen_rings.toml").read_text())["objects"]]
    return load_scene(SCENES / "thirteen_rings.toml", [f"{name}.particles.boundary_group_size={group_size}"
                                                       for name in names])


def run(ctx: BenchContext, group_sizes=GROUP_SIZES, frames: int | None = None, drop_particles: int = 5000,
        drop_seconds: float = 3.0, timing_scene=rings_scene) -> Section:
    """``timing_scene(n)`` builds the timed scene (default: the 13 rings); ``frames`` caps
    its run (None: its 3 s; quick mode: 10)."""
    from .tables import run_scene

    if frames is None and ctx.quick:
        frames = 10
    t0 = time.perf_counter()
    drops, timings = {}, {}
    for n in group_sizes:
        drops[n] = measure_drop(ctx, drop_scene(n, drop_particles, drop_seconds))
        d = drops[n]
        ctx.progress(f"grouping n={n}: drop rest {d.rest_height:.4f} m, rebound {d.rebound:.4f} m, "
                     f"impulse {d.first_impulse:.3f} N s")
        _, summary, counts = run_scene(ctx, timing_scene(n), f"13 rings, n={n}", fracture=False, frames=frames)
        timings[n] = (summary, counts)
    ref = drops[min(group_sizes)]
    ref_ms = timings[min(group_sizes)][0].ms_per_frame["mean"]
    speed_rows, error_rows = [], []
    for n in group_sizes:
        summary, counts = timings[n]
        d = drops[n]
        speed_rows.append([n if n > 1 else "1 (single-scale)", f"{counts['collision']:,}",
                           f"{1e3 * d.mean_radius:.1f}", ms_pair(summary.ms_per_frame["mean"], summary.ms_per_frame["max"]),
                           f"{counts['substeps_per_frame']:.1f}", f"{ref_ms / summary.ms_per_frame['mean']:.2f}x"])
        error_rows.append([
            n if n > 1 else "1 (single-scale)",
            f"{d.rest_height:.4f} ({1e3 * (d.rest_height - MINOR_RADIUS):+.1f} mm)",
            f"{1e3 * (d.rest_height - ref.rest_height):+.1f}",
            f"{d.rebound:.4f}", f"{1e3 * (d.rebound - ref.rebound):+.1f}",
            f"{d.first_impulse:.3f}", f"{100 * (d.first_impulse / max(ref.first_impulse, 1e-12) - 1):+.1f} %",
            f"{1e3 * d.penetration:.3f}",
        ])
    frames_run = timings[group_sizes[0]][0].frames
    link_path, link = _plot(ctx, group_sizes, timings, drops)
    text = "\n".join([
        f"Boundary grouping n (`particles.boundary_group_size`): n adjacent surface particles merge into one "
        f"collision sphere; n = 1 is the single-scale reference. Time: `scenes/thirteen_rings.toml`, rings "
        f"unbreakable (`fracture=False`), {frames_run} frames of 20 ms. Error: one ring "
        f"(~{drop_particles:,} physics particles, unbreakable, restitution 0.5 against a ground of 0.5) dropped "
        f"from {DROP_HEIGHT} m tilted {TILT} rad, {drop_seconds:g} s; rest height against the exact "
        f"{MINOR_RADIUS} m of a flat torus, the rebound (highest COM after the first bounce minus rest, sampled "
        "at frame ends), the first-impact impulse (the frame's summed impact rows), and the deepest "
        "collision sphere below the ground at any frame end.",
        "",
        "**Speed** (13 rings, unbreakable)",
        "",
        md_table(["n", "collision particles", "mean collision radius of the ring [mm]", "ms/frame avg / max",
                  "substeps per frame", "speed-up vs n = 1"], speed_rows),
        "",
        "**Error against n = 1** (single ring drop)",
        "",
        md_table(["n", "rest height [m] (vs exact 0.025)", "rest vs n=1 [mm]", "rebound [m]",
                  "rebound vs n=1 [mm]", "first impulse [N s]", "impulse vs n=1", "max penetration [mm]"],
                 error_rows),
        "",
        f"![time and error against the boundary grouping n]({link})",
        "",
        f"*Part time: {time.perf_counter() - t0:.0f} s.*",
    ])
    headline = {n: dict(ms=timings[n][0].ms_per_frame["mean"], rest_error=drops[n].rest_height - MINOR_RADIUS)
                for n in group_sizes}
    return Section("grouping", "Two-scale against single-scale: boundary grouping n", text, [link_path],
                   dict(per_n=headline, drops=drops, timings=timings))


def _plot(ctx, group_sizes, timings, drops):
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.6))
    ns = np.array(group_sizes)
    ms = np.array([timings[n][0].ms_per_frame["mean"] for n in group_sizes])
    rest = np.array([1e3 * (drops[n].rest_height - MINOR_RADIUS) for n in group_sizes])
    ax1.plot(ns, ms, "o-")
    ax1.set_xscale("log", base=2)
    ax1.set_xticks(ns, [str(n) for n in ns])
    ax1.set_xlabel("boundary grouping n (1 = single-scale)")
    ax1.set_ylabel("ms per frame, 13 rings (avg)")
    ax1.set_title("speed")
    ax2.plot(ms, rest, "o-")
    for n, x, y in zip(ns, ms, rest):
        ax2.annotate(f"n={n}", (x, y), textcoords="offset points", xytext=(5, 5))
    ax2.set_xlabel("ms per frame, 13 rings (avg)")
    ax2.set_ylabel("rest height error vs exact [mm]")
    ax2.set_title("speed against error")
    return ctx.save_figure(fig, "grouping.png")
