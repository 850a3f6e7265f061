"""``taichi-frac bench TARGET``: the benchmark report and timed measurements.

The benchmarks are not part of the installed package: they live in a source checkout
(``benchmarks/`` beside ``taichi_frac/``), which this command finds and runs. Its targets
and options are the checkout's own (``taichi-frac bench --help`` there).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def checkout_root() -> Path | None:
    """The source checkout this package runs from, when it has its ``benchmarks/`` folder."""
    root = Path(__file__).resolve().parents[2]
    return root if (root / "benchmarks" / "__init__.py").is_file() else None


def _run(args) -> int:
    root = checkout_root()
    if root is None:
        print("taichi-frac bench: the benchmarks are not installed with the package; run it from a source "
              "checkout (git clone the project, pip install -e . there, and run taichi-frac bench there)",
              file=sys.stderr)
        return 2
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    from benchmarks.cli import main

    return main((["--help"] if args.bench_help else []) + args.bench_args)


def register(subparsers) -> None:
    # The targets are parsed by the checkout's own parser (benchmarks/cli.py), so no other
    # command pays for importing the benchmarks.
    p = subparsers.add_parser("bench", help="benchmark report and timed measurements (report, dynamics, meshes, "
                                            "...; from a source checkout)", add_help=False,
                              description=__doc__.split("\n\n")[0].replace("``", "'"))
    p.add_argument("-h", "--help", dest="bench_help", action="store_true", help="the checkout's targets and options")
    p.add_argument("bench_args", nargs=argparse.REMAINDER)
    p.set_defaults(func=_run)
