"""One BLAS thread for a run's processes.

After each call, OpenBLAS (numpy's and scipy's) keeps its worker threads spinning on
``sched_yield`` for a while before they sleep. A run calls BLAS on small matrices (a
crack fit's least squares, a few hundred rows at most) over and over, in the frame loop
and in every piece-surface worker, so the spinning threads took CPU from the frames and
the cuts beside them: on 2 cores, the 13 rings' run measured about a sixth of its CPU time
less, and 12 % less wall time, with one BLAS thread per process (the benchmark report's
start-up page times the run as it is now).
"""

from __future__ import annotations


def single_blas_thread():
    """Limit the BLAS libraries loaded in this process to one thread: returns a
    ``threadpoolctl.threadpool_limits``, whose ``restore_original_limits()`` (or ``with``
    block's end) gives them back their thread counts."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")
