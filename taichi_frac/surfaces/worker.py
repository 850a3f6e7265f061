"""A piece-surface worker process: forked from the run's process (``pool.py``), or
``python -m taichi_frac.surfaces.worker PARENT_PID REQUESTS_FD ANSWERS_FD`` where there is
no fork.

It holds a :class:`~taichi_frac.surfaces.stage.SurfaceStage` and answers the requests read
from one pipe with results written to another, one pickled frame each way (an 8-byte
length, then the pickle): ``(task id, "add_body", (model, surface, shading key))`` or
``(task id, "cut", CutRequest)`` in, ``(task id, True, result)`` or ``(task id, False, the
error's traceback)`` out; ``(task id, "reset", None)`` (no answer) starts a new run's
stage. It ends at the end of its input,
and with its parent however that ends (a parent-death signal); Ctrl-C in the terminal is
the parent's to handle.
"""

from __future__ import annotations

import os
import pickle
import signal
import struct
import sys
import traceback

_HEADER = struct.Struct("<Q")


def read_frame(stream):
    """One pickled object from ``stream``, or None at its end."""
    header = stream.read(_HEADER.size)
    if len(header) < _HEADER.size:
        return None
    (size,) = _HEADER.unpack(header)
    return pickle.loads(stream.read(size))


def write_frame(stream, obj) -> None:
    """``obj`` pickled onto ``stream`` as one frame, flushed."""
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)))
    stream.write(data)
    stream.flush()


def main(parent_pid: int, requests_fd: int, answers_fd: int) -> int:
    from ..geometry.workers import die_with_parent

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent_pid)
    serve(os.fdopen(requests_fd, "rb"), os.fdopen(answers_fd, "wb"))
    return 0


def serve(requests, answers) -> None:
    """Answer the requests read from ``requests`` on ``answers`` until the input ends."""
    from ..blas import one_blas_thread
    from .stage import SurfaceStage

    stage = SurfaceStage()
    # (the workers share the cores with each other and the frames: see blas.py)
    with one_blas_thread():
        while (request := read_frame(requests)) is not None:
            task, kind, payload = request
            if kind == "reset":  # (a new run: nothing of the last run's solids; no answer)
                stage = SurfaceStage()
                continue
            try:
                result = stage.add_body(*payload) if kind == "add_body" else stage.cut(payload)
                write_frame(answers, (task, True, result))
            except Exception:  # noqa: BLE001 (the parent raises it, with this traceback)
                write_frame(answers, (task, False, traceback.format_exc()))


if __name__ == "__main__":
    sys.exit(main(*(int(a) for a in sys.argv[1:4])))
