"""Time meshing + model building (never a test): prints a table.

    .venv/bin/python benchmarks/bench_prepare.py [--repeat 3] [--backend tetgen] [--wildmeshing]

Rows: the paper's ring at ~5,000 tets, a 20,000-tet glass wall and a 70,000-tet ring (the
size of the issue's "under 5 s" goal), each meshed without the on-disk cache; timings are
the best of --repeat runs. --wildmeshing adds the fTetWild backend on the ring for
comparison (slow: tens of seconds).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from taichi_frac.geometry.prepare import prepare_body  # noqa: E402
from taichi_frac.options import ParticleOptions  # noqa: E402

CASES = [
    ("paper ring (Table 1: 5,044 / 1,608 / 543)", "torus:major=0.1,minor=0.025", 5000),
    ("glass wall 0.6 x 0.5 x 0.03 m", "box:x=0.03,y=0.6,z=0.5", 20000),
    ("ring, 70,000 tets", "torus:major=0.1,minor=0.025", 70000),
]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--backend", default="tetgen")
    parser.add_argument("--wildmeshing", action="store_true", help="also time the wildmeshing backend on the ring")
    args = parser.parse_args()
    os.environ["TAICHI_FRAC_CACHE"] = tempfile.mkdtemp(prefix="bench_prepare_")
    runs = [(name, spec, n, args.backend) for name, spec, n in CASES]
    if args.wildmeshing:
        runs.append(("paper ring, wildmeshing", CASES[0][1], 5000, "wildmeshing"))
    header = (f"{'case':<42} {'backend':<11} {'target':>7} {'tets':>7} {'surface':>7} {'boundary':>8} "
              f"{'vol.err':>9} {'min dih':>7} {'slivers':>7} {'mesh s':>7} {'model s':>7} {'total s':>7}")
    print(header)
    print("-" * len(header))
    for name, spec, target, backend in runs:
        best = None
        for _ in range(args.repeat if backend == "tetgen" else 1):
            t0 = time.perf_counter()
            _, r = prepare_body(spec, particles=ParticleOptions(target_particles=target), backend=backend,
                                use_cache=False)
            total = time.perf_counter() - t0
            if best is None or total < best[0]:
                best = (total, r)
        total, r = best
        print(f"{name:<42} {backend:<11} {target:>7,} {r.tets:>7,} {r.surface_particles:>7,} {r.boundary_particles:>8,} "
              f"{r.volume_error:>+9.1e} {r.min_dihedral_deg:>7.2f} {r.sliver_count:>7} {r.timings['mesh']:>7.2f} "
              f"{r.timings['model']:>7.2f} {total:>7.2f}")
    print(f"\n{os.cpu_count()} CPU cores; times are wall clock, best of {args.repeat}, no cache.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
