"""``taichi-frac bench TARGET``: timed measurements (never part of the test suite).

``report`` runs every part and writes docs/benchmarks.md, its plots in docs/benchmarks/ and
a headline summary out/benchmarks_summary.md (``--quick``: a smoke version under
out/bench_quick/). Each part runs alone too (``tables``, ``grouping``, ``sph``, ``scaling``,
``stability``: prints its markdown, plots under ``--out``); ``pieces``, ``startup`` and
``physics`` (the automatic fracture model against experiments) write their own pages
(``taichi-frac bench physics --out docs``: docs/benchmarks/physics.md and its plots).
``dynamics`` prints the rigid-body table, ``meshes`` runs every mesh of a folder, ``sweep`` times variant sweeps.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def _run_report(args) -> int:
    from .report import PARTS, run_report

    parts = args.parts.split(",") if args.parts else None
    unknown = [p for p in parts or [] if p not in PARTS]
    if unknown:
        print(f"unknown part(s) {', '.join(unknown)}: use {', '.join(PARTS)}")
        return 2
    sections = run_report(quick=args.quick, out_dir=args.out, parts=parts, arch=args.arch)
    failed = [c for s in sections if s.key == "stability" for c in s.headline["cases"] if not c.passed]
    return 1 if failed else 0


def _part_runner(key: str):
    def run(args) -> int:
        from .common import REPO, BenchContext
        from .report import NEEDS_WORLD, PARTS, run_parts

        out = Path(args.out) if args.out else REPO / "out" / "bench"
        ctx = BenchContext(quick=args.quick, markdown_dir=out, figure_dir=out / "benchmarks", arch=args.arch)
        (section,) = run_parts(ctx, [key]) if key in NEEDS_WORLD else [PARTS[key][0].run(ctx)]
        print(f"\n## {section.title}\n\n{section.markdown}")
        return 0

    return run


def _run_meshes(args) -> int:
    from .common import REPO, BenchContext
    from .meshes import run

    out = Path(args.out) if args.out else REPO / "out" / "bench"
    if args.folder is not None:
        import os

        os.environ["TAICHI_FRAC_SHARED_MESHES"] = str(args.folder)  # read by meshes.shared_meshes_dir
    section = run(BenchContext(quick=args.quick, markdown_dir=out, figure_dir=out / "benchmarks", arch=args.arch))
    print(f"\n## {section.title}\n\n{section.markdown}")
    return 0


def _run_dynamics(args) -> int:
    from .dynamics import run_dynamics

    return run_dynamics(args)


def _run_sweep(args) -> int:
    from .sweep import run_command

    return run_command(args)


def register(subparsers) -> None:
    from .dynamics import add_arguments as add_dynamics_arguments



def build_parser() -> argparse.ArgumentParser:
    from .dynamics import add_arguments as add_dynamics_arguments

    p = argparse.ArgumentParser(prog="taichi-frac bench", description=__doc__.split("\n\n")[0].replace("``", "'"))
    p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    targets = p.add_subparsers(dest="target", metavar="TARGET")
    r = targets.add_parser("report", help="run every part but those with their own page (pieces, startup, "
                                          "physics); write "
                                          "docs/benchmarks.md, its plots and out/benchmarks_summary.md")
    r.add_argument("--quick", action="store_true", help="fast smoke version, written under out/bench_quick/")
    r.add_argument("--out", type=Path, help="folder for benchmarks.md and benchmarks/*.png (default: docs/, "
                                             "or out/bench_quick/ with --quick)")
    r.add_argument("--parts", help="comma-separated subset: tables,grouping,sph,stress_models,scaling,stability "
                                   "(pieces, startup and physics write their own pages: taichi-frac bench "
                                   "physics --out docs)")
    r.add_argument("--arch", default="cpu")
    r.set_defaults(func=_run_report)
    from .report import PARTS

    for key, (_, help_text) in PARTS.items():
        t = targets.add_parser(key, help=help_text)
        t.add_argument("--quick", action="store_true", help="fewer frames / sizes (smoke test)")
        t.add_argument("--out", type=Path, help="folder for the plots (default out/bench/)")
        t.add_argument("--arch", default="cpu")
        t.set_defaults(func=_part_runner(key))
    w = targets.add_parser("sweep", help="variant sweeps on Dask: throughput against one run after another, "
                                         "fragment counts over 64 seeds; writes docs/benchmarks/sweep.md")
    w.add_argument("--quick", action="store_true", help="fewer variants and frames, written under out/bench_quick/")
    w.add_argument("--out", type=Path, help="folder for sweep.md and its plot (default docs/benchmarks/)")
    w.add_argument("--parts", help="comma-separated subset: throughput,spread")
    w.set_defaults(func=_run_sweep)
    m = targets.add_parser("meshes", help="artists' meshes: particles vs target, volume and extents kept, "
                                          "prepare time, a 1 s drop (writes docs/benchmarks/meshes.md)")
    m.add_argument("--quick", action="store_true", help="smaller stress cases, written under --out only")
    m.add_argument("--folder", type=Path, help="the meshes to run: every surface file in it (default ../shared/meshes)")
    m.add_argument("--out", type=Path, help="folder for the quick report and generated inputs (default out/bench/)")
    m.add_argument("--arch", default="cpu")
    m.set_defaults(func=_run_meshes)
    d = targets.add_parser("dynamics", help="the rigid-body table: 13 rings two- vs single-scale, a fragment pile")
    add_dynamics_arguments(d)
    d.set_defaults(func=_run_dynamics)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])
    return p


def main(argv) -> int:
    """Run ``taichi-frac bench ARGV``; returns the exit code."""
    args = build_parser().parse_args(argv)
    return args.func(args)
