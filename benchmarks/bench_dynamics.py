"""Same as ``taichi-frac bench dynamics`` (kept beside the other bench scripts)."""

import sys

from taichi_frac.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "dynamics", *sys.argv[1:]]))
