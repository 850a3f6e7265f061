"""The ``taichi-frac`` command line.

Each subcommand lives in its own module under ``taichi_frac.commands`` and exposes
``register(subparsers)``, which adds its parser and sets ``func`` (returning an exit code).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback

# Before numpy loads OpenBLAS, which reads them then. One BLAS thread: a run's BLAS calls
# are small (a ring's FEM factorisation, a piece's 3x3 inverse) and the cores are the
# frames' and the surface workers'; a second BLAS thread waiting for a busy core stalls the
# call (the glass walls' fracture analysis beside three workers: 6.9 s, against 0.9 s on one
# thread; whole runs 0.96-0.97x). The pieces do not depend on it: no BLAS product enters
# the physics (geometry/mass.py). Where a user asks for more threads, their idle threads
# sleep at once instead of spinning on sched_yield for about 2^28 cycles after each call.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_THREAD_TIMEOUT", "4")

from . import __version__, interrupts  # noqa: E402

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
    debug_help = "show the Python traceback of an error (for reporting a bug)"
    parser.add_argument("--debug", action="store_true", help=debug_help)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f".commands.{name}", __package__)
        except ModuleNotFoundError as exc:
            if exc.name != f"{__package__}.commands.{name}":
                raise
            continue
        module.register(sub)
    for command in sub.choices.values():  # (also after the command: taichi-frac run S --debug)
        command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=debug_help)
    return parser


def _user_errors() -> tuple:
    """The package's errors about its input: printed as one line, exit status 2."""
    from .geometry.validate import MeshError
    from .options import OptionError
    from .runtime import ArchError

    return OptionError, MeshError, ArchError


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def entry() -> None:
    """The ``taichi-frac`` command: :func:`main`, then out without the interpreter's teardown.

    Freeing a finished run's modules (Taichi's and LLVM's, USD's, SciPy's) took about 0.2 s
    of every command. So the exit handlers run first (the surface workers are ended and
    waited for), Taichi's runtime is finalised (it writes its offline cache of compiled
    kernels then), the streams are flushed, and the process leaves with ``os._exit``."""
    try:
        code = main()
    except SystemExit as stop:  # (argparse's --help and usage errors)
        code = stop.code
    if not isinstance(code, int):
        if code is not None:
            print(code, file=sys.stderr)
        code = 0 if code is None else 1
    leave(code)


def leave(code: int) -> None:
    """Exit with ``code`` after the exit handlers and Taichi's finalisation, skipping the
    interpreter's teardown (see :func:`entry`)."""
    import atexit

    try:
        if "taichi_frac.runtime" in sys.modules:  # (a command that never loaded Taichi skips it)
            sys.modules["taichi_frac.runtime"].finish()
        atexit._run_exitfuncs()
    except Exception:  # noqa: BLE001 (said, and the exit goes on)
        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)


def main(argv: list[str] | None = None) -> int:
    interrupts.install()  # before the slow imports: a Ctrl-C during start-up is never lost
    try:
        return _main(argv)
    except KeyboardInterrupt:  # (while the parser's modules load)
        print("\ntaichi-frac: interrupted", file=sys.stderr)
        return 130
    except Exception:
        # A Ctrl-C that lands inside an extension module's import comes back as that
        # import's own error (Taichi's core: "ImportError: initialization failed").
        if interrupts.requested():
            print("\ntaichi-frac: interrupted", file=sys.stderr)
            return 130
        raise
    finally:
        interrupts.restore()


def _main(argv: list[str] | None) -> int:
    # stdout is the command's result (a --json object): Taichi's version banner, printed there
    # by whichever module imports Taichi first (the parser's modules may), is turned off (its
    # other messages go to stderr: see runtime).
    os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "false")
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    prefix = f"taichi-frac {args.command}"
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"\n{prefix}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the one place that turns errors into exit codes
        if interrupts.requested():  # (the Ctrl-C surfaced as a library's own error)
            print(f"\n{prefix}: interrupted", file=sys.stderr)
            return 130
        if args.debug:
            traceback.print_exc()
        user = isinstance(exc, _user_errors())
        from .simulation import NonFinitePoseError

        if user or isinstance(exc, NonFinitePoseError):
            print(f"{prefix}: error: {_one_line(exc)}", file=sys.stderr)
            return 2 if user else 1
        print(f"{prefix}: internal error: {type(exc).__name__}: {_one_line(exc)}"
              + ("" if args.debug else " (run again with --debug for the traceback, and report it)"),
              file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
