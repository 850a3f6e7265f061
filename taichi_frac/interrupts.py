"""Ctrl-C during a run: the first stops cleanly, a second exits at once.

Python turns SIGINT into a KeyboardInterrupt wherever the main thread is, and a library
that catches ``BaseException`` (or Taichi's kernel decorator, with a bare ``except:``)
can swallow it during start-up. So the command installs :func:`install` first: the first
Ctrl-C both raises KeyboardInterrupt and sets a flag that the simulation reads between
steps (:func:`check`), so it is honoured even when swallowed; a second Ctrl-C exits the
process at once with status 130 (the cache keeps its last checkpoint, which is always a
complete file: checkpoints are written atomically).

A library that catches and prints an exception raised in its own import (USD's module loader
prints a KeyboardInterrupt during ``import pxr`` as a warning with a traceback) imports under
:func:`deferred`: a Ctrl-C there only sets the flag, and the KeyboardInterrupt comes when the
import is done.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading

_requested = False
_previous = None
_installed = False
_deferring = 0


def _handler(signum, frame):
    global _requested
    if _requested:
        os.write(2, b"\ninterrupted again: exiting now; the cache keeps its last checkpoint\n")
        os._exit(130)
    _requested = True
    os.write(2, b"\ninterrupted: stopping at the next step and keeping the frames done "
                b"(Ctrl-C again to exit at once)\n")
    if not _deferring:
        raise KeyboardInterrupt


@contextlib.contextmanager
def deferred():
    """A block a first Ctrl-C does not interrupt: it is raised (KeyboardInterrupt) when the
    block ends. A second Ctrl-C still exits at once."""
    global _deferring
    _deferring += 1
    try:
        yield
    finally:
        _deferring -= 1
    if _deferring == 0:
        check()


def install() -> None:
    """Take over SIGINT (main thread only; elsewhere a no-op)."""
    global _requested, _previous, _installed
    if threading.current_thread() is not threading.main_thread() or _installed:
        return
    _requested = False
    _previous = signal.signal(signal.SIGINT, _handler)
    _installed = True


def restore() -> None:
    """Give SIGINT back to the handler that was there before :func:`install`."""
    global _requested, _installed
    if _installed:
        signal.signal(signal.SIGINT, _previous if _previous is not None else signal.default_int_handler)
    _installed = False
    _requested = False


def requested() -> bool:
    return _requested


def check() -> None:
    """Raise KeyboardInterrupt if a Ctrl-C came (even one a library swallowed)."""
    if _requested:
        raise KeyboardInterrupt
