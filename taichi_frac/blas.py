"""How many threads the BLAS libraries loaded in a process (numpy's, scipy's OpenBLAS) run.

One, wherever a result or a run's pace must not depend on them:

- a threaded BLAS splits a long product among its threads and sums the parts in another
  order, so a solver's answer changes in its last bits with the machine's core count (the
  crack fit's least squares, and then which cut it keeps);
- on a machine whose cores are busy (the piece-surface workers cutting beside the frames)
  OpenBLAS's small solves with a matrix right-hand side wait for a helper thread to be
  scheduled: a 3x3 inverse took 2.4 ms instead of 2 us, 5,000 of them (a plate's shape
  function gradients, ``fracture.fem``) 7.7 s instead of a millisecond.
"""

from __future__ import annotations

import sys


def one_blas_thread():
    """A context in which the BLAS libraries loaded run one thread each."""
    return _blas_libraries().limit(limits=1, user_api="blas")


_controller = None  # threadpoolctl's list of the libraries loaded, and how many modules were then
_modules_then = -1


def _blas_libraries():
    # (listed again once more modules are imported, which may have loaded another BLAS, a
    # solver's; limiting through the list costs about 10 us, listing about 1.4 ms)
    global _controller, _modules_then
    if _controller is None or len(sys.modules) != _modules_then:
        import scipy.optimize  # noqa: F401 (its BLAS loaded first: the solvers use it)
        from threadpoolctl import ThreadpoolController

        _controller, _modules_then = ThreadpoolController(), len(sys.modules)
    return _controller
