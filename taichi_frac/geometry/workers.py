"""Worker processes that cannot outlive the process that started them.

A preparation step runs native code in a forked child (``bounded.StepClock``). If the parent
is killed (SIGKILL from a job scheduler or a time-out, SIGTERM, Ctrl-C) the child would keep
running and burn a core until it finishes. On Linux the child asks the kernel for a
parent-death signal (``prctl(PR_SET_PDEATHSIG, SIGKILL)``, through ctypes): the kernel kills
it the moment its parent thread exits, whatever killed the parent. A child started by a
child does the same, so a chain of workers goes down together. Elsewhere the child checks
its parent when it starts only.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

#: ``PR_SET_PDEATHSIG`` from <linux/prctl.h>.
_PR_SET_PDEATHSIG = 1


def die_with_parent(parent_pid: int) -> None:
    """Make this (child) process receive SIGKILL when its parent dies, and exit now if
    ``parent_pid`` is already gone (it died before the request was made)."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):
            pass  # no prctl in this C library: the parent's own clean-up still stops the child
    if os.getppid() != parent_pid:
        os._exit(1)
