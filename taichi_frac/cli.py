"""The ``taichi-frac`` command line.

Each subcommand lives in its own module under ``taichi_frac.commands`` and exposes
``register(subparsers)``, which adds its parser and sets ``func`` (returning an exit code).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from . import __version__

# Order is the order shown in --help.
COMMANDS = ("run", "info", "bench", "render", "sweep")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="taichi-frac",
        description=(
            "Brittle fracture for animation: shatter meshes from the stress an impact really "
            "causes (two-scale particles, Chen, Wang & Xie 2015), write USD caches for Blender."
        ),
        epilog="Run 'taichi-frac COMMAND --help' for a command's options.",
    )
    parser.add_argument("--version", action="version", version=f"taichi-frac {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f".commands.{name}", __package__)
        except ModuleNotFoundError as exc:
            if exc.name != f"{__package__}.commands.{name}":
                raise
            continue
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
