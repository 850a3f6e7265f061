"""Runs as a user runs them: a fresh process, the cache written, start to exit.

Each row runs ``taichi-frac run SCENE -o CACHE -q --stats-json STATS`` in a new process and
times it from outside (the median of ``repeat`` runs after one untimed run, for the warm
rows); the stats give where the time went inside. ``imports + exit`` is what the process
spent outside the run's own clocks (the interpreter, the imports, writing the stats).
Beside them: the same process running the 13 rings twice (the second run's time), the time
to the first progress line, and pybullet's whole run of the 13 rings (import, V-HACD of
each ring with an empty cache, 3 s simulated) in a fresh process. Writes
``benchmarks/startup.md`` under the markdown folder (``taichi-frac bench startup --out docs``).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .common import REPO, BenchContext, Section, md_table

ENTRY = [sys.executable, "-m", "taichi_frac"]
#: The quick-look row's option: the pieces cut on the cracks as the analysis placed them,
#: without the volume fit's extra cuts (docs/guide/fragment-geometry.md says what it costs).
QUICK_LOOK = "--draft"


def _timed_run(scene: str, folder: Path, env: dict, extra=()) -> dict:
    """One fresh ``taichi-frac run``: its wall time [s] and its stats."""
    cache, stats = folder / f"{scene}.usdc", folder / f"{scene}.json"
    cache.unlink(missing_ok=True)
    t = time.perf_counter()
    done = subprocess.run([*ENTRY, "run", scene, "-o", str(cache), "-q", "--overwrite", "--stats-json", str(stats),
                           *extra], env=env, capture_output=True, text=True, cwd=folder)
    wall = time.perf_counter() - t
    if done.returncode != 0:
        raise RuntimeError(f"taichi-frac run {scene} failed: {done.stderr.strip().splitlines()[-1:]}")
    return dict(wall=wall, stats=json.loads(stats.read_text()))


def _breakdown(label: str, run: dict) -> list:
    """A table row: the wall time and where it went [s]."""
    stats, wall = run["stats"], run["wall"]
    stage, ms = stats["stage_seconds"], stats["ms_per_frame"]
    inside = stats["wall_time"] + stage.get("prepare", 0.0) + stage.get("setup", 0.0)
    first_frame = ms["first"] / 1e3
    fracture_first = stage.get("first_analysis", 0.0)  # (the fracture kernels' first launch, mostly)
    physics = stats["wall_time"] - first_frame - fracture_first - stage.get("output", 0.0) \
        - stage.get("surfaces_wait", 0.0)
    if stats.get("surface_workers", 0) == 0:
        physics -= stage.get("render_surfaces", 0.0)
    return [label, f"{wall:.2f}", f"{stats['simulated_time']:.1f}", f"{wall - inside:.2f}",
            f"{stage.get('prepare', 0.0):.2f}", f"{stage.get('setup', 0.0):.2f}", f"{first_frame:.2f}",
            f"{fracture_first:.2f}", f"{physics:.2f}",
            f"{stage.get('render_surfaces', 0.0):.2f}" + (" (workers)" if stats.get("surface_workers") else ""),
            f"{stage.get('surfaces_wait', 0.0):.2f}", f"{stage.get('output', 0.0):.2f}"]


def _second_run_in_process(folder: Path, env: dict) -> float:
    """[s] the second of two ``Simulation(thirteen_rings).run()`` in one process, cache written."""
    code = ("import sys, time\n"
            "from taichi_frac.scenes import load_scene\n"
            "from taichi_frac.simulation import Simulation\n"
            "for k in range(2):\n"
            "    t = time.perf_counter()\n"
            f"    Simulation(load_scene('thirteen_rings'), output=r'{folder}' + f'/same_{{k}}.usdc', overwrite=True).run()\n"
            "print(time.perf_counter() - t)\n")
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=folder)
    if done.returncode != 0:
        raise RuntimeError(f"the same-process runs failed: {done.stderr.strip().splitlines()[-1:]}")
    return float(done.stdout.strip().splitlines()[-1])


def _first_progress_line(folder: Path, env: dict) -> float:
    """[s] from the command's start to its first progress line (``--progress-json``)."""
    cache = folder / "progress.usdc"
    t = time.perf_counter()
    process = subprocess.Popen([*ENTRY, "run", "thirteen_rings", "-o", str(cache), "--overwrite",
                                "--progress-json"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                               text=True, cwd=folder)
    first = None
    for line in process.stderr:
        if first is None and line.lstrip().startswith("{"):
            first = time.perf_counter() - t
    process.wait()
    return float("nan") if first is None else first


def _pybullet_rings(folder: Path, env: dict) -> float | None:
    """[s] pybullet's fresh process: import, V-HACD with an empty cache, the 13 rings' 3 s."""
    code = ("import time\n"
            "from pathlib import Path\n"
            "import pybullet\n"
            "from benchmarks.pybullet_ref import run_rings\n"
            "from taichi_frac.scenes import load_scene\n"
            f"vhacd = Path(r'{folder}') / 'vhacd'\n"
            "vhacd.mkdir(exist_ok=True)\n"
            "run_rings(load_scene('thirteen_rings'), cache_dir=vhacd)\n")
    t = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", code], env=env | {"PYTHONPATH": str(REPO)}, capture_output=True,
                          text=True, cwd=folder)
    wall = time.perf_counter() - t
    return wall if done.returncode == 0 else None


def run(ctx: BenchContext, repeat: int | None = None) -> Section:
    t0 = time.perf_counter()
    repeat = repeat or (1 if ctx.quick else 3)
    header = ["run", "wall [s]", "simulated [s]", "imports + exit", "prepare", "set-up", "first frame",
              "first impact analysis", "physics", "piece surfaces", "waited for surfaces", "cache write"]
    rows, headline = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        env = dict(os.environ)
        quick = [QUICK_LOOK]
        for scene, label, key, extra in (("single_ring", "single_ring", "single_ring_warm_s", ()),
                                         ("thirteen_rings", "thirteen_rings", "thirteen_rings_warm_s", ()),
                                         ("thirteen_rings", f"thirteen_rings, a quick look ({QUICK_LOOK})",
                                          "thirteen_rings_quick_look_s", quick)):
            ctx.progress(f"startup: {label}, warm ({repeat} runs after one)")
            _timed_run(scene, folder, env, extra)
            runs = sorted((_timed_run(scene, folder, env, extra) for _ in range(repeat)), key=lambda r: r["wall"])
            rows.append(_breakdown(f"{label}, warm", runs[len(runs) // 2]))
            headline[key] = statistics.median(r["wall"] for r in runs)
        ctx.progress(f"startup: an empty cache (a fresh machine): the demo, then a new scene ({repeat} times)")
        demos, fresh_scenes = [], []
        for k in range(repeat):  # (each time a cache folder of its own, empty)
            empty = env | {"TAICHI_FRAC_CACHE": str(folder / f"empty_cache_{k}")}
            demos.append(_timed_run("single_ring", folder, empty))
            fresh_scenes.append(_timed_run("thirteen_rings", folder, empty))
        demo = sorted(demos, key=lambda r: r["wall"])[len(demos) // 2]
        fresh_scene = sorted(fresh_scenes, key=lambda r: r["wall"])[len(fresh_scenes) // 2]
        rows.append(_breakdown("single_ring (the demo), empty cache", demo))
        rows.append(_breakdown("thirteen_rings, first run after single_ring", fresh_scene))
        headline.update(demo_empty_cache_s=demo["wall"], new_scene_s=fresh_scene["wall"])
        ctx.progress("startup: the same process, a second run; the first progress line; pybullet")
        second = _second_run_in_process(folder, env)
        first_line = _first_progress_line(folder, env)
        pybullet = _pybullet_rings(folder, env)
    headline.update(same_process_second_s=second, first_progress_line_s=first_line, pybullet_rings_s=pybullet)
    lines = [
        "Runs as a user runs them: `taichi-frac run SCENE -o CACHE -q` in a new process, the cache written, "
        "timed from outside start to exit (warm rows: the median of "
        f"{repeat} after one untimed run; the empty-cache rows: the median of {repeat}, each with a cache "
        "folder of its own). The other columns come from the run's own stats [s]: *first frame* "
        "is the dynamics kernels' first launch (Taichi's front end reads their source in every new process), "
        "*first impact analysis* mostly the fracture kernels' first launch, "
        "*piece surfaces* the time the pieces' render surfaces took to cut (in worker processes beside the "
        "frames unless marked otherwise), *waited* what the run then waited for them at its end. The quick-look "
        f"row runs with `{QUICK_LOOK}` (`crack_fit_rounds = 0` on every ring): the pieces are cut on the cracks "
        "as the analysis placed them, without the cuts that fit their volumes to their tets' (on this scene the "
        "pieces of 100 tets or more are then off by about 5 % instead of 1 % at the 95th percentile: the "
        "piece-geometry page).",
        "",
        md_table(header, rows),
        "",
        f"- The same process, a second `Simulation(thirteen_rings).run()` with its cache: **{second:.2f} s** "
        "(its World and kernels are the first run's).",
        f"- The first progress line of `taichi-frac run thirteen_rings`: **{first_line:.2f} s** after the "
        "command started.",
        ("- pybullet, the 13 rings in a fresh process (import, V-HACD of each ring with an empty cache, 3 s "
         f"simulated): **{pybullet:.2f} s** end to end." if pybullet is not None
         else "- pybullet is not installed here: its end-to-end row is left out."),
        "",
        f"Part time: {time.perf_counter() - t0:.0f} s.",
    ]
    markdown = "\n".join(lines)
    path = ctx.markdown_dir / "benchmarks" / "startup.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("# Start to exit: a run as a user runs it\n\n" + markdown + "\n")
    ctx.progress(f"wrote {path}")
    return Section("startup", "Start to exit: a run as a user runs it", markdown, headline=headline)
