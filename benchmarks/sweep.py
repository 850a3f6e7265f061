"""Sweeps: throughput on Dask against one ``taichi-frac run`` after another, and the spread
of the single ring's fragment counts over seeds per crack_count (``taichi-frac bench sweep``,
written to docs/benchmarks/sweep.md and its plot docs/benchmarks/sweep_spread.png).

Throughput: the same variants (the single ring, crack_count 3, seeds 0..V-1, the first
``FRAMES`` frames: the ring lands and breaks at frame ~22) run (1) as separate
``taichi-frac run`` processes one after another, each loading the kernels anew, (2) as a
sweep on one local worker, (3) on two. Every process reads its kernels from Taichi's
offline cache, which a first untimed run fills. Spread: the ring over 64 seeds for each of
crack_count 1, 3 and 5 (the paper's Table 1 controls, which report 2, 5 and 10 fragments
for one draw each).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from .common import REPO, SCENES, BenchContext, Section, load_average, machine_info, md_table, pyplot

SCENE = SCENES / "single_ring.toml"
#: Frames per variant: the ring lands at frame ~22 and breaks once (refracture false): its fragment count is final.
FRAMES = 30
#: Paper Table 1 rows 1-3: crack_count -> fragments reported.
PAPER_FRAGMENTS = {1: 2, 3: 5, 5: 10}


def _sweep(ctx: BenchContext, vary, out: Path, workers: int, frames: int):
    from taichi_frac.sweep import sweep

    shutil.rmtree(out, ignore_errors=True)
    started = time.perf_counter()
    result = sweep(SCENE, vary, out, frames=frames, workers=workers, sheet=False, progress=False,
                   log=ctx.progress)
    return result, time.perf_counter() - started


def _sequential(ctx: BenchContext, seeds, out: Path, frames: int) -> float:
    """One ``taichi-frac run`` process per variant, one after another."""
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    started = time.perf_counter()
    for seed in seeds:
        subprocess.run([sys.executable, "-m", "taichi_frac", "run", str(SCENE), "--frames", str(frames), "-q",
                        "--set", "ring.fracture.crack_count=3", "--set", f"ring.fracture.seed={seed}",
                        "-o", str(out / f"seed{seed}.usdc")], env=env, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - started


def throughput(ctx: BenchContext, work: Path) -> tuple[str, dict]:
    count = 4 if ctx.quick else 6
    frames = 10 if ctx.quick else FRAMES
    seeds = list(range(count))
    vary = ["ring.fracture.crack_count=3", f"ring.fracture.seed=0:{count}"]
    ctx.progress("sweep throughput: untimed warm-up (fills Taichi's offline cache)")
    _sweep(ctx, ["ring.fracture.crack_count=3", "ring.fracture.seed=100:102"], work / "warmup", 2, frames)
    rows, headline = [], {}
    ctx.progress(f"sweep throughput: {count} variants as separate taichi-frac run processes")
    sequential = _sequential(ctx, seeds, work / "sequential", frames)
    rows.append(["one `taichi-frac run` after another", 1, f"{sequential:.1f}", f"{60 * count / sequential:.1f}",
                 "1.00", "—"])
    headline["sequential_per_min"] = 60 * count / sequential
    for workers in (1, 2):
        ctx.progress(f"sweep throughput: {count} variants on {workers} worker(s)")
        result, seconds = _sweep(ctx, vary, work / f"workers{workers}", workers, frames)
        if result.failed:
            raise RuntimeError(f"the sweep on {workers} workers had failures: {result.records}")
        later = [r["seconds_to_first_frame"] for r in result.done if r["worker_run_index"] > 1]
        first = [r["seconds_to_first_frame"] for r in result.done if r["worker_run_index"] == 1]
        rows.append([f"`taichi-frac sweep --workers {workers}`", workers, f"{seconds:.1f}",
                     f"{60 * count / seconds:.1f}", f"{sequential / seconds:.2f}",
                     f"{np.median(first):.2f} / {np.median(later):.2f} (max {np.max(later):.2f})" if later else "—"])
        headline[f"workers{workers}_per_min"] = 60 * count / seconds
        headline[f"workers{workers}_later_first_frame_max_s"] = float(np.max(later)) if later else None
    text = md_table(["how", "processes", "wall time [s]", "variants / min", "speed-up",
                     "start of the first frame [s]: a worker's first variant / its later ones"], rows, "lrrrrl")
    text += (f"\n\n{count} variants: the single ring, crack_count 3, seeds 0..{count - 1}, {frames} frames each, "
             "cache written. The wall time includes starting the processes (the sweep's: its LocalCluster), "
             "loading the kernels from Taichi's offline cache, meshing (cached on disk) and writing the caches. "
             "A worker's later variants reuse its World, its compiled kernels and its prepared ring, so they start "
             "their first frame within the time in the last column, measured from the moment the worker picks "
             "the variant up.")
    return text, headline


def spread(ctx: BenchContext, work: Path) -> tuple[str, dict, Path]:
    seeds = 4 if ctx.quick else 64
    frames = FRAMES
    counts = (1, 3, 5)
    vary = [f"ring.fracture.crack_count={','.join(map(str, counts))}", f"ring.fracture.seed=0:{seeds}"]
    ctx.progress(f"sweep spread: the single ring, {seeds} seeds x crack_count {counts} on 2 workers")
    result, seconds = _sweep(ctx, vary, work / "spread", 2, frames)
    rows, per_count, headline = [], {}, {}
    for c in counts:
        frags = np.array([r["fragments"] for r in result.done if r["settings"]["ring.fracture.crack_count"] == c])
        per_count[c] = frags
        q10, q50, q90 = np.percentile(frags, [10, 50, 90])
        rows.append([c, PAPER_FRAGMENTS[c], len(frags), frags.min(), f"{q10:.0f}", f"{q50:.0f}", f"{q90:.0f}",
                     frags.max(), f"{frags.mean():.2f} ± {frags.std(ddof=1) if len(frags) > 1 else 0:.2f}"])
        headline[f"crack_count{c}"] = dict(median=float(q50), min=int(frags.min()), max=int(frags.max()))
    failed = sum(r["status"] != "done" for r in result.records)
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    top = max(int(f.max()) for f in per_count.values())
    bins = np.arange(0.5, top + 1.5)
    for c, frags in per_count.items():
        ax.hist(frags, bins=bins, alpha=0.6, label=f"crack_count {c} (paper: {PAPER_FRAGMENTS[c]})")
    ax.set_xlabel("fragments")
    ax.set_ylabel(f"seeds (of {seeds})")
    ax.legend(fontsize=8)
    ax.set_title(f"single ring: fragment count over {seeds} seeds", fontsize=9)
    _, link = ctx.save_figure(fig, "sweep_spread.png")
    text = md_table(["crack_count", "paper", "runs", "min", "p10", "median", "p90", "max", "mean ± sd"], rows)
    text += (f"\n\n![fragment counts over seeds]({link})\n\n{len(result.records)} variants "
             f"({failed} failed), {frames} frames each, in {seconds / 60:.1f} min on 2 local workers "
             f"({60 * len(result.done) / seconds:.1f} variants / min). The paper reports one draw per row.")
    return text, headline, Path(link)


def run(ctx: BenchContext, parts=("throughput", "spread"), written=None) -> Section:
    """The parts in order; ``written(section)``, if given, is called after each part with
    the section so far (the command writes the file then, so a long spread part that is
    stopped leaves the throughput part written)."""
    work = REPO / "out" / ("bench_quick" if ctx.quick else "bench") / "sweep"
    started, load_start = time.perf_counter(), load_average()
    body, headline = [], {}

    def section():
        m = machine_info()
        tail = [f"Machine: {m['cpu']}, {m['cores']} cores; code {m['commit']}; load average (1/5/15 min) "
                f"{load_start} at the start, {load_average()} at the end (other jobs shared the machine); "
                f"{(time.perf_counter() - started) / 60:.1f} min in all."]
        return Section("sweep", "Variant sweeps on Dask", "\n".join(body + tail), headline=dict(headline))

    for part in parts:
        text, h = throughput(ctx, work) if part == "throughput" else spread(ctx, work)[:2]
        title = "Throughput" if part == "throughput" else "Fragment counts over seeds"
        body += [f"### {title}", "", text, ""]
        headline.update(h)
        ctx.progress(f"sweep {part}:\n{text}")
        if written is not None:
            written(section())
    return section()


def run_command(args) -> int:
    """``taichi-frac bench sweep``: run the parts, print the markdown, write ``OUT/sweep.md``."""
    out = Path(args.out) if args.out else (REPO / "out" / "bench_quick" if args.quick else REPO / "docs" / "benchmarks")
    ctx = BenchContext(quick=args.quick, markdown_dir=out, figure_dir=out, arch="cpu")
    parts = tuple(args.parts.split(",")) if args.parts else ("throughput", "spread")
    unknown = [p for p in parts if p not in ("throughput", "spread")]
    if unknown:
        print(f"unknown part(s) {', '.join(unknown)}: use throughput, spread")
        return 2

    def write(section: Section) -> None:
        out.mkdir(parents=True, exist_ok=True)
        text = f"# {section.title}\n\nWritten by `taichi-frac bench sweep{' --quick' if ctx.quick else ''}`.\n\n"
        (out / "sweep.md").write_text(text + section.markdown + "\n")
        ctx.progress(f"wrote {out / 'sweep.md'}")

    section = run(ctx, parts, written=write)
    print(f"# {section.title}\n\n{section.markdown}")
    return 0
