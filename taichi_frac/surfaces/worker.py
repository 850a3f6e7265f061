"""A piece-surface worker process: forked from the run's process (``pool.py``), or
``python -m taichi_frac.surfaces.worker PARENT_PID REQUESTS_FD ANSWERS_FD THREADS`` where
there is no fork. ``THREADS``: how many threads its booleans run (``start_boolean_threads``;
0: the library's default).

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


def main(parent_pid: int, requests_fd: int, answers_fd: int, threads: int) -> int:
    from ..geometry.workers import die_with_parent

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent_pid)
    serve(os.fdopen(requests_fd, "rb"), os.fdopen(answers_fd, "wb"), threads)
    return 0


def boolean_threads(workers: int) -> int:
    """How many threads each of ``workers`` workers' booleans run: one where the workers
    outnumber the cores this process may run on two to one or more (the default on up to
    two cores), else 0, the library's own pool (a thread per core: where a few large cuts
    run on many cores, they use them)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return 1 if workers >= 2 * cores else 0


def start_boolean_threads(threads: int) -> None:
    """Start manifold3d's thread pool (oneTBB's) in this process with ``threads`` threads, before
    its first boolean. oneTBB sizes the pool once, by the CPUs the process may then run on: the
    process runs on ``threads`` of them while a first boolean starts the pool, then on all
    again. Four workers on two cores with a pool as large as the machine each spend the
    cores' time spinning between small booleans: the 13 rings' cuts took 6.3 s of the
    workers' CPU so, 5.8 s with one thread each, and the run 2 % longer. Nothing for 0 (the
    library's default), nor on a platform that cannot set a process's CPUs."""
    if threads <= 0 or not hasattr(os, "sched_setaffinity"):
        return
    cpus = os.sched_getaffinity(0)
    if threads >= len(cpus):
        return
    import manifold3d as m3

    os.sched_setaffinity(0, sorted(cpus)[:threads])
    try:
        cube = m3.Manifold.cube((1.0, 1.0, 1.0))
        (cube - cube.translate((0.5, 0.5, 0.5))).num_tri()
    finally:
        os.sched_setaffinity(0, cpus)


def serve(requests, answers, threads: int = 0) -> None:
    """Answer the requests read from ``requests`` on ``answers`` until the input ends, the
    booleans on ``threads`` threads (0: the library's default)."""
    from ..blas import one_blas_thread
    from .stage import SurfaceStage

    start_boolean_threads(threads)
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
    sys.exit(main(*(int(a) for a in sys.argv[1:5])))
