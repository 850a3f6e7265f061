"""Speed vs error of the contact stress analysis: the command-line front of
``benchmarks.sph`` (its docstring describes the block, the load and the error).

    .venv/bin/python benchmarks/bench_stress.py [--arch cpu] [--repeat 3] [--sizes 10,17,27,43] [--no-tets]

Same as ``taichi-frac bench sph`` without the plots; ``taichi-frac bench report`` includes it.
"""

import os

os.environ.setdefault("TI_LOG_LEVEL", "error")

from benchmarks.sph import main  # noqa: E402

if __name__ == "__main__":
    main()
