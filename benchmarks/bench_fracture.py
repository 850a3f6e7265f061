"""Benchmark one impact on the ~5,000-particle ring: stress analysis (field, gradient,
stress, cracks), the fragment split, and building the fragments' BodyModels.

    .venv/bin/python benchmarks/bench_fracture.py [--arch cpu] [--repeat 3]

Impacts 2 and 3 hit other points of the ring with other crack counts: their time shows
that nothing compiles after the first impact (the Taichi kernels take ndarrays, compiled
once per dtype/ndim); the compiled-kernel count is printed after each impact to prove it.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

os.environ.setdefault("TI_LOG_LEVEL", "error")

from taichi_frac import runtime  # noqa: E402


def compiled_kernel_count() -> int:
    """Compiled instances of every Taichi kernel in the fracture modules."""
    import taichi as ti

    from taichi_frac.fracture import field, sph, stress

    total = 0
    for mod in (field, sph, stress):
        for obj in vars(mod).values():
            impl = getattr(obj, "_primal", None)
            if isinstance(impl, ti.lang.kernel_impl.Kernel):
                total += len(impl.compiled_kernels)
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    runtime.init(args.arch)

    from tests.support.fracture_ring import struck_ring_model
    from taichi_frac.fracture.cracks import analyze_impact
    from taichi_frac.fracture.fragments import make_fragments, split_body
    from taichi_frac.options import FractureOptions, Material, ParticleOptions

    model = struck_ring_model()
    material = Material(name="ring", density=2400.0, young_modulus=70e9, poisson_ratio=0.2, tensile_strength=1e6)
    print(f"ring: {model.tet_count} physics particles, {model.surface_particle_count} surface, "
          f"{model.boundary_particle_count} boundary, {len(model.bonds)} bonds; arch {args.arch}")
    angles = np.radians([0.0, 120.0, 240.0, 60.0, 180.0, 300.0])
    rows = []
    for k in range(args.repeat):
        a = angles[k % len(angles)]
        point = np.array([0.125 * np.cos(a), 0.125 * np.sin(a), 0.0])
        normal = -point / np.linalg.norm(point)
        opts = FractureOptions(crack_count=1 + 2 * k, crack_length=0.3, seed=k)
        t0 = time.perf_counter()
        analysis = analyze_impact(model, point, normal, 1e4 * normal, material, opts)
        t1 = time.perf_counter()
        split = split_body(model, analysis, opts)
        t2 = time.perf_counter()
        frags = make_fragments(model, split, np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3), np.zeros(3),
                               material, ParticleOptions(), options=opts)
        t3 = time.perf_counter()
        rows.append((k + 1, opts.crack_count, (t1 - t0) * 1e3, (t2 - t1) * 1e3, (t3 - t2) * 1e3, len(frags),
                     compiled_kernel_count()))
    print(f"{'impact':>6} {'n':>3} {'analyze ms':>11} {'split ms':>9} {'fragments ms':>13} {'pieces':>7} "
          f"{'kernels compiled':>17}")
    for r in rows:
        print(f"{r[0]:>6} {r[1]:>3} {r[2]:>11.1f} {r[3]:>9.1f} {r[4]:>13.1f} {r[5]:>7} {r[6]:>17}")


if __name__ == "__main__":
    main()
