"""Running one preparation step under a time bound that names the step when it runs out.

The mesh libraries (MeshFix, manifold3d, TetGen, the quadric simplifier) are native code
that Python cannot interrupt, so a bounded step runs in a forked child process (the child
shares the parent's memory copy-on-write, so starting it costs milliseconds, not an
interpreter start-up) and is killed when its time is up. The child dies with its parent
(``workers.die_with_parent``): a killed run leaves no worker behind. Where fork is not
available the step runs inline and the bound is checked after it returns.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import time
from dataclasses import dataclass, field

from .validate import MeshError

#: Wall-clock bound for everything ``prepare_body`` does to one surface [s].
DEFAULT_PREPARE_SECONDS = 60.0


class StepShareExceeded(MeshError):
    """A step ran past its share of the bound (:meth:`StepClock.run_within`); time is left."""


@dataclass
class StepClock:
    """A deadline shared by the steps of one preparation, and how long each step took.

    Attributes:
        name: what messages call the mesh (the file name).
        seconds: the whole preparation's bound [s] (None: unbounded).
        step_seconds: wall time of each step that ran [s], in order.
        crash_hint: what the message of a crashed step suggests.
    """

    name: str = "mesh"
    seconds: float | None = DEFAULT_PREPARE_SECONDS
    start: float = field(default_factory=time.perf_counter)
    step_seconds: dict = field(default_factory=dict)
    crash_hint: str = "repair the mesh in a modelling tool or try backend='wildmeshing'"

    def remaining(self) -> float | None:
        if self.seconds is None:
            return None
        return self.seconds - (time.perf_counter() - self.start)

    def ran_out(self, step: str):
        return MeshError(f"{self.name!r}: step '{step}' ran out of time: the preparation's bound of "
                         f"{self.seconds:.0f} s was used up ({self._spent()}); simplify the mesh in a "
                         "modelling tool, or raise the bound (prepare_body(time_limit=...), taichi-frac info --time-limit)")

    def _spent(self) -> str:
        spent = ", ".join(f"{k} {v:.1f} s" for k, v in self.step_seconds.items())
        return f"time spent: {spent}" if spent else "no step finished"

    def check(self, step: str) -> None:
        """Raise if the bound is used up (call after a step that ran inline)."""
        left = self.remaining()
        if left is not None and left <= 0:
            raise self.ran_out(step)

    def run(self, step: str, function, *args, **kwargs):
        """``function(*args, **kwargs)`` in a forked child, killed when the bound runs out.
        Exceptions raised in the child are raised here; a crash of the child names the step."""
        return self.run_within(step, None, function, *args, **kwargs)

    def run_within(self, step: str, share: float | None, function, *args, **kwargs):
        """:meth:`run` with the step also stopped after ``share`` seconds (None: only the
        whole bound); running out of the share raises :class:`StepShareExceeded`, which a
        caller can answer with a fallback in the time left."""
        t0 = time.perf_counter()
        try:
            return self._run(step, function, args, kwargs, share)
        finally:
            self.step_seconds[step] = self.step_seconds.get(step, 0.0) + time.perf_counter() - t0

    def inline(self, step: str, function, *args, **kwargs):
        """Run a numpy step in this process, then check the bound."""
        t0 = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            self.step_seconds[step] = self.step_seconds.get(step, 0.0) + time.perf_counter() - t0
            self.check(step)

    def _run(self, step, function, args, kwargs, share=None):
        left = self.remaining()
        if left is not None and left <= 0:
            raise self.ran_out(step)
        by_share = share is not None and (left is None or share < left)
        if by_share:
            left = share
        if "fork" not in multiprocessing.get_all_start_methods():
            result = function(*args, **kwargs)
            self.check(step)
            return result
        context = multiprocessing.get_context("fork")
        receive, send = context.Pipe(duplex=False)
        # Not a daemon, so a step may start its own bounded steps; the finally below always
        # stops it.
        child = context.Process(target=_child, args=(send, os.getpid(), function, args, kwargs))
        child.start()
        send.close()
        try:
            if not receive.poll(left):
                if by_share:
                    raise StepShareExceeded(f"{self.name!r}: step '{step}' ran past its share of {share:.1f} s")
                raise self.ran_out(step)
            try:
                ok, payload = pickle.loads(receive.recv_bytes())
            except EOFError:
                child.join(5)
                raise MeshError(f"{self.name!r}: step '{step}' crashed (exit code {child.exitcode}); "
                                f"{self.crash_hint}") from None
        finally:
            receive.close()
            if child.is_alive():
                child.kill()
            child.join()
        if not ok:
            raise payload
        return payload


def _child(send, parent_pid, function, args, kwargs) -> None:
    from .workers import die_with_parent

    die_with_parent(parent_pid)
    try:
        message = (True, function(*args, **kwargs))
    except BaseException as exc:  # sent back and raised in the parent
        message = (False, exc)
    try:
        data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception as exc:
        data = pickle.dumps((False, MeshError(f"step result could not be sent back: {exc}")))
    send.send_bytes(data)
    send.close()
    os._exit(0)  # skip the parent's atexit handlers (Taichi's) in the child
