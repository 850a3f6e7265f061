"""Part 3: how the cost grows: ms per frame and peak memory against the physics particle
count, from about 1,000 to 1,000,000 physics particles.

Scenes: porcelain rings (the 13-ring scene's ring: torus R 0.1 m, r 0.025 m, ~5,450 physics
particles; one ring of ~1,000 for the smallest size) laid out on a square grid 0.3 m apart,
each tilted at random and starting 1.5 cm or more above the ground at 4.4 m/s downwards (as if
dropped from 1 m, like scenes/single_ring.toml), so every ring hits the ground in the first frames and, with fracture
on, breaks there (crack controls as in the 13-ring scene). Each size runs in its own
process (``python -m benchmarks.scaling --child ...``), so the peak resident memory
it reports (``ru_maxrss``) is that size's alone, everything included: Taichi, the World's
fields (sized by ``Simulation`` for the fragments to come), every ring's model.

The child first compiles the kernels on the same World with a one-ring drop, then times
the scene: the first frames hold the impacts and every fracture, so the per-frame average
is the expensive part of a run, not a resting pile.
"""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import time

import numpy as np

from .common import REPO, BenchContext, Section, md_table, pyplot

RING_PARTICLES = 5550  # target_particles of scenes/thirteen_rings.toml
SPACING = 0.3  # m between ring centres (bounding sphere radius 0.125 m)
START_SPEED = 4.4  # m/s downwards: a 1 m drop, as scenes/single_ring.toml
LIMIT_GB = 4.0
MARKER = "SCALING_RESULT "


def ring_layout_scene(rings: int, ring_particles: int = RING_PARTICLES, frames: int = 10, fracture: bool = True,
                      seed: int = 0):
    """``rings`` porcelain rings on a square grid, tilted at random, falling onto the ground."""
    from taichi_frac.options import FractureOptions, Material, ParticleOptions
    from taichi_frac.scenes import Collider, Scene, SceneObject, SimulationOptions

    rng = np.random.default_rng(seed)
    side = math.ceil(math.sqrt(rings))
    material = Material(name="porcelain (effective strength)", density=2400.0, young_modulus=70e9,
                        poisson_ratio=0.2, tensile_strength=1.0e6)
    objects = []
    for k in range(rings):
        row, col = divmod(k, side)
        objects.append(SceneObject(
            name=f"ring{k:04d}", primitive="torus:major=0.1,minor=0.025", material=material,
            breakable=fracture, position=((col - (side - 1) / 2) * SPACING, (row - (side - 1) / 2) * SPACING, 0.14),
            euler_deg=tuple(float(a) for a in rng.uniform(0.0, 90.0, 3)), linear_velocity=(0.0, 0.0, -START_SPEED),
            friction=0.5, restitution=0.1, particles=ParticleOptions(target_particles=ring_particles),
            # (the 13-ring scene's model: the paper's half-space stress; "auto" would read a
            # ring's own elasticity, a factorisation per ring and per piece struck)
            fracture=FractureOptions(crack_count=1 + k % 5, seed=k + 1, impact_force_threshold=2000.0,
                                     stress_model="halfspace"),
        ))
    return Scene(name=f"rings_{rings}x{ring_particles}", objects=objects,
                 colliders=[Collider.ground(0.0, friction=0.6, restitution=0.1)],
                 simulation=SimulationOptions(fps=50, duration=frames / 50, substeps=10))


def _reset_peak_rss() -> bool:
    """Reset the kernel's peak-RSS mark of this process (Linux >= 4.0: ``clear_refs`` 5),
    so the run's own peak can be told from the compilation's."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _peak_rss_mb() -> float:
    """VmHWM of this process [MB] (what ``ru_maxrss`` reports, but resettable)."""
    try:
        for line in open("/proc/self/status"):
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def measure_scene(scene, world, frames: int, fracture: bool) -> dict:
    """Time ``scene`` on ``world`` (kernels already compiled): per-frame ms, stages, counts."""
    from taichi_frac.simulation import Simulation

    sim = Simulation(scene, output=False, world=world, frames=frames, fracture=fracture)
    models = [r.model for r in sim.records.values()]
    collision = sum(count for _, count in world.slots.body_range.values())
    substeps0 = world.stats.total_substeps
    summary = sim.run()
    return dict(
        frames=summary.frames, fracture=fracture, physics_particles=sum(m.tet_count for m in models),
        surface_particles=sum(m.surface_particle_count for m in models), collision_particles=collision,
        ms_mean=summary.ms_per_frame["mean"], ms_max=summary.ms_per_frame["max"],
        stage_seconds=summary.stage_seconds, fragments=summary.fragments, fractures=summary.fractures,
        substeps_per_frame=(world.stats.total_substeps - substeps0) / max(summary.frames, 1),
        capacity=dict(max_bodies=world.capacity.max_bodies,
                      max_boundary_particles=world.capacity.max_boundary_particles,
                      max_contacts=world.capacity.max_contacts),
    )


def child(rings: int, ring_particles: int, frames: int, fracture: bool, arch: str) -> dict:
    """Runs in the size's own process; returns what the parent reports. Peak memory: the
    whole process (``peak_rss_mb``, kernel compilation included) and the timed run alone
    (``run_peak_rss_mb``: the peak mark reset after compiling)."""
    import gc

    from taichi_frac import runtime
    from taichi_frac.simulation import Simulation

    runtime.init(arch)
    t0 = time.perf_counter()
    scene = ring_layout_scene(rings, ring_particles, frames, fracture)
    # The World that Simulation sizes for this scene; its kernels compile on a one-ring drop.
    probe = Simulation(scene, output=False, frames=frames, fracture=fracture)
    world = probe.world
    del probe
    Simulation(ring_layout_scene(1, 1000, 15, True), output=False, world=world).run()
    gc.collect()
    setup_seconds = time.perf_counter() - t0
    reset = _reset_peak_rss()
    result = measure_scene(scene, world, frames, fracture)
    return result | dict(rings=rings, ring_particles=ring_particles, setup_seconds=setup_seconds,
                         peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                         run_peak_rss_mb=_peak_rss_mb() if reset else None)


def in_process_runner(ctx: BenchContext):
    """A runner for ``run`` that measures on the report's World in this process (tests: no
    subprocess, no compilation); peak memory is this process's, not the size's."""
    def runner(rings, ring_particles, frames, fracture, arch="cpu"):
        scene = ring_layout_scene(rings, ring_particles, frames, fracture)
        result = measure_scene(scene, ctx.world(), frames, fracture)
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        return result | dict(rings=rings, ring_particles=ring_particles, setup_seconds=0.0, peak_rss_mb=peak,
                             run_peak_rss_mb=None)

    return runner


def run_size(rings: int, ring_particles: int, frames: int, fracture: bool, arch: str = "cpu",
             timeout: float | None = None) -> dict:
    """One size in a subprocess; returns the child's result (peak RSS included)."""
    cmd = [sys.executable, "-m", "benchmarks.scaling", "--child", "--rings", str(rings),
           "--ring-particles", str(ring_particles), "--frames", str(frames), "--arch", arch]
    if not fracture:
        cmd.append("--no-fracture")
    env = dict(os.environ, TI_LOG_LEVEL="error")
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, env=env, timeout=timeout)
    for line in done.stdout.splitlines():
        if line.startswith(MARKER):
            return json.loads(line[len(MARKER):])
    raise RuntimeError(f"scaling child ({rings} rings) failed with exit code {done.returncode}:\n"
                       f"{done.stdout[-2000:]}\n{done.stderr[-4000:]}")


def default_sizes(quick: bool) -> list[tuple[int, int]]:
    """(rings, particles per ring): ~1e3, 5.5e3, 2.2e4, 8.7e4, 3.5e5, 1e6 physics particles."""
    if quick:
        return [(1, 1000), (4, RING_PARTICLES)]
    # Four sizes, not six: each child compiles its kernels afresh (field shapes differ, so
    # Taichi's offline cache cannot serve them), ~2.5 min a size on this CPU.
    return [(1, 1000), (4, RING_PARTICLES), (32, RING_PARTICLES), (184, RING_PARTICLES)]


def fit_slope(particles, ms) -> float:
    """Least-squares slope of log(ms) against log(particles)."""
    return float(np.polyfit(np.log(particles), np.log(ms), 1)[0])


def run(ctx: BenchContext, sizes=None, frames: int | None = None, fracture_off: bool | None = None,
        runner=None) -> Section:
    """``sizes``: (rings, particles per ring) list; ``frames`` per size (default 10, quick 3).
    With ``fracture_off`` (default off: it doubles the part's time) every size also runs with
    the rings unbreakable (dynamics alone). ``runner`` measures one size (default: ``run_size``, a
    subprocess per size)."""
    t0 = time.perf_counter()
    runner = runner or run_size
    fracture_off = False if fracture_off is None else fracture_off  # the off pass doubles a ~10 min part
    sizes = sizes or default_sizes(ctx.quick)
    frames = frames or (3 if ctx.quick else 10)
    results = {True: [], False: []}
    for fracture in (True, False) if fracture_off else (True,):
        for rings, per_ring in sizes:
            r = runner(rings, per_ring, frames, fracture, ctx.arch)
            results[fracture].append(r)
            ctx.progress(f"scaling ({'fracture on' if fracture else 'fracture off'}): {r['physics_particles']:,} "
                         f"physics particles, {r['ms_mean']:.1f} ms/frame, peak {r['peak_rss_mb']:.0f} MB, "
                         f"{r['fragments']} fragments")
    rows, slopes = [], {}
    for fracture, res in results.items():
        if not res:
            continue
        p = np.array([r["physics_particles"] for r in res], dtype=float)
        ms = np.array([r["ms_mean"] for r in res])
        slopes[fracture] = fit_slope(p, ms) if len(res) >= 2 else float("nan")
        upper = p >= np.sqrt(p.min() * p.max())
        slopes[(fracture, "upper")] = fit_slope(p[upper], ms[upper]) if upper.sum() >= 2 else float("nan")
        for r in res:
            st = r["stage_seconds"]
            per = {k: 1e3 * st.get(k, 0.0) / max(r["frames"], 1) for k in ("dynamics", "fracture_analysis",
                                                                             "fragment_split")}
            rows.append(["on" if fracture else "off", f"{r['physics_particles']:,}",
                         f"{r['rings']} x {r['physics_particles'] // r['rings']:,}", f"{r['collision_particles']:,}",
                         r["frames"], f"{r['ms_mean']:.1f} / {r['ms_max']:.1f}", f"{per['dynamics']:.1f}",
                         f"{per['fracture_analysis'] + per['fragment_split']:.1f}", f"{r['substeps_per_frame']:.1f}",
                         r["fractures"], r["fragments"], f"{r['peak_rss_mb']:,.0f}",
                         "" if r.get("run_peak_rss_mb") is None else f"{r['run_peak_rss_mb']:,.0f}"])
    biggest = max(results[True], key=lambda r: r["physics_particles"])
    fits = biggest["peak_rss_mb"] <= LIMIT_GB * 1024
    path, link = _plot(ctx, results, slopes)
    text = "\n".join([
        f"Rings of ~{RING_PARTICLES:,} target physics particles (one ring of ~1,000 for the smallest size) on a "
        f"square grid {SPACING} m apart, tilted at random, starting at 0.14 m with {START_SPEED} m/s downwards: "
        f"every ring hits the ground within the first frames. Each size ran **{frames} frames of 20 ms** "
        "(the impacts, every fracture and the first bounce: the expensive part of a drop) in its own process, "
        "after compiling the kernels on the same World with a one-ring drop. **Fracture on**: every ring "
        "breakable (crack_count 1-5, threshold 2 kN, effective strength 1 MPa, as the 13-ring scene). "
        + ("**fracture off**: the same rings unbreakable (dynamics alone). " if fracture_off else "")
        + "Peak memory: the child process's own peak resident set (`ru_maxrss`), everything included "
        "(LLVM compiling the kernels takes most of it for small sizes; the Taichi offline cache, once warm, "
        "avoids that); *peak after compiling*: the same mark reset (`/proc/self/clear_refs`) after the "
        "warm-up, so it is the timed run's own peak (it cannot fall below what the process already holds).",
        "",
        md_table(["fracture", "physics particles", "rings x particles", "collision particles", "frames",
                  "ms/frame avg / max", "dynamics ms/frame", "fracture ms/frame", "substeps per frame",
                  "fracture events", "fragments", "peak memory [MB]", "peak after compiling [MB]"], rows,
                 "lrrrrrrrrrrrr"),
        "",
        "Fitted slope of log(ms per frame) against log(physics particles): "
        + "; ".join(f"fracture {'on' if f else 'off'}: **{slopes[f]:.2f}** over the whole range"
                    + (f", {slopes[(f, 'upper')]:.2f} over the upper half (sizes >= the geometric middle)"
                       if np.isfinite(slopes[(f, "upper")]) else "") for f in (True, False) if f in slopes)
        + " (1 = linear).",
        "",
        f"The largest case, {biggest['physics_particles']:,} physics particles with fracture on, peaked at "
        f"**{biggest['peak_rss_mb']:,.0f} MB** of resident memory: "
        + (f"within the {LIMIT_GB:g} GB limit." if fits else f"**over the {LIMIT_GB:g} GB limit**."),
        "",
        f"![ms per frame and peak memory against physics particles]({link})",
        "",
        f"*Part time: {time.perf_counter() - t0:.0f} s.*",
    ])
    headline = dict(slope_on=slopes.get(True), slope_off=slopes.get(False),
                    biggest_particles=biggest["physics_particles"], biggest_mb=biggest["peak_rss_mb"],
                    biggest_ms=biggest["ms_mean"], fits=fits, frames=frames)
    return Section("scaling", "How cost grows with the particle count", text, [path],
                   headline | {"results": results})


def _plot(ctx, results, slopes):
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.8))
    for fracture, style in ((True, "o-"), (False, "s--")):
        res = results.get(fracture) or []
        if not res:
            continue
        p = np.array([r["physics_particles"] for r in res], dtype=float)
        ms = np.array([r["ms_mean"] for r in res])
        mb = np.array([r["peak_rss_mb"] for r in res])
        label = f"fracture {'on' if fracture else 'off'} (slope {slopes[fracture]:.2f})"
        ax1.loglog(p, ms, style, label=label)
        ax2.loglog(p, mb, style, label=f"fracture {'on' if fracture else 'off'}")
    res = results[True]
    p = np.array([r["physics_particles"] for r in res], dtype=float)
    ms = np.array([r["ms_mean"] for r in res])
    ref = ms[0] * p / p[0]
    ax1.loglog(p, ref, ":", color="gray", label="linear from the smallest")
    ax1.set_xlabel("physics particles")
    ax1.set_ylabel("ms per 20 ms frame (avg)")
    ax1.set_title("time per frame")
    ax1.legend(fontsize=8)
    ax2.axhline(LIMIT_GB * 1024, color="r", linestyle=":", label=f"{LIMIT_GB:g} GB limit")
    ax2.set_xlabel("physics particles")
    ax2.set_ylabel("peak resident memory [MB]")
    ax2.set_title("peak memory")
    ax2.legend(fontsize=8)
    return ctx.save_figure(fig, "scaling.png")


def main(argv=None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description="one size of the scaling benchmark (a child process)")
    parser.add_argument("--child", action="store_true", required=True)
    parser.add_argument("--rings", type=int, required=True)
    parser.add_argument("--ring-particles", type=int, default=RING_PARTICLES)
    parser.add_argument("--frames", type=int, default=10)
    parser.add_argument("--no-fracture", action="store_true")
    parser.add_argument("--arch", default="cpu")
    args = parser.parse_args(argv)
    result = child(args.rings, args.ring_particles, args.frames, not args.no_fracture, args.arch)
    print(MARKER + json.dumps(result, default=float), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
