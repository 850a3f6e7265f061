"""Speed vs error of the contact stress analysis (fracture/field.py, sph.py, stress.py).

    .venv/bin/python benchmarks/bench_stress.py [--arch cpu] [--repeat 3] [--sizes 10,17,27,43]

Block: the unit cube x, y in [-1/2, 1/2], z in [0, 1], particles on a lattice of n^3 cells
jittered by +-0.2 spacing (volumes = spacing^3), plus blocks of tetgen tet centroids
(what a real body gives; volumes = tet volumes). Load: force (2e4, -1e4, -1e5) N at the centre of the top face,
E = 70 GPa, nu = 0.2, default h = 2 x spacing and contact radius = the nearest particle's.

Error metric: relative L2 (Frobenius) error of the SPH stress against the exact stress of
the same (regularised) displacement field -- its complex-step gradient through the same
strain and Hooke law -- over a set of particles S:
    e = sqrt(sum_S |sigma_sph - sigma_exact|_F^2 / sum_S |sigma_exact|_F^2)
    S = interior: >= 2h from the load and >= h (a full kernel support) from every face;
    S = +surface: >= 2h from the load, surface particles included;
    S = far: >= 0.25 m from the load (fixed region, shows convergence with resolution).
Times: best of --repeat runs after a warm-up (kernels compiled), one core budget shared.
Then one impact's analysis (field + neighbours + gradient + stress + principal) on the
~5,000-particle ring of tests/_fracture_ring.py (torus R 0.1 m, r 0.025 m, tetgen), 1e4 N
at the outer equator.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

os.environ.setdefault("TI_LOG_LEVEL", "error")

from taichi_frac import runtime  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
from _fracture_ring import jittered_block  # noqa: E402  (the stress test's block)

E, NU = 70.0e9, 0.2
FORCE = np.array([2e4, -1e4, -1e5])
TOP = np.array([0.0, 0.0, 1.0])
DOWN = np.array([0.0, 0.0, -1.0])





def tet_particles(mesh, target):
    from taichi_frac.geometry.tetra import tetrahedralize

    tm = tetrahedralize(mesh, target_tets=target)
    corners = tm.vertices[tm.tets]
    centroids = corners.mean(axis=1)
    d = corners[:, 1:] - corners[:, :1]
    volumes = np.abs(np.einsum("ni,ni->n", d[:, 0], np.cross(d[:, 1], d[:, 2]))) / 6.0
    return centroids, volumes


def tet_block(target):
    from taichi_frac.geometry.primitives import box

    pts, vol = tet_particles(box((1.0, 1.0, 1.0)), target)
    pts = pts - [0.0, 0.0, pts[:, 2].min() - 0.0]
    lo, hi = pts.min(0), pts.max(0)
    pts = pts - (lo + hi) / 2 + [0, 0, 0.5]  # centre x, y; z in [~0, ~1]
    return pts, vol


def face_distance(pts):
    return np.min(np.stack([pts[:, 0] + 0.5, 0.5 - pts[:, 0], pts[:, 1] + 0.5,
                            0.5 - pts[:, 1], pts[:, 2], 1 - pts[:, 2]], axis=1), axis=1)


def best_time(fn, repeat):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def block_rows(label, pts, vol, repeat):
    from taichi_frac.fracture import (contact_field, default_smoothing_length,
                                      displacement_gradient, neighbor_lists,
                                      point_load_displacement, principal_stresses,
                                      stress_from_gradient)
    from taichi_frac.fracture.field import point_load_gradient_reference

    h = default_smoothing_length(vol)
    field = contact_field(pts, vol, TOP, DOWN, FORCE, E, NU)  # warm-up, default radius
    a = field.contact_radius
    shear = E / (2 * (1 + NU))
    exact = stress_from_gradient(point_load_gradient_reference(pts, TOP, DOWN, FORCE, shear, NU, a),
                                 E, NU)
    dist = np.linalg.norm(pts - TOP, axis=1)
    sets = {"interior": (dist >= 2 * h) & (face_distance(pts) >= h),
            "+surface": dist >= 2 * h, "far": dist >= 0.25}
    t_field, disp = best_time(lambda: point_load_displacement(pts, TOP, DOWN, FORCE, shear, NU, a), repeat)
    t_nbr, (off, idx) = best_time(lambda: neighbor_lists(pts, h), repeat)
    rows = []
    for corrected in (False, True):
        t_grad, grad = best_time(lambda: displacement_gradient(pts, vol, disp, off, idx, h, corrected), repeat)
        t_stress, stress = best_time(lambda: stress_from_gradient(grad, E, NU), repeat)
        t_princ, _ = best_time(lambda: principal_stresses(stress), repeat)
        errors = {k: np.linalg.norm(stress[m] - exact[m]) / np.linalg.norm(exact[m]) for k, m in sets.items()}
        total = t_field + t_nbr + t_grad + t_stress + t_princ
        rows.append((label, len(pts), len(idx) / len(pts), "corrected" if corrected else "plain",
                     errors, t_field, t_nbr, t_grad, t_stress + t_princ, total))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--sizes", default="10,17,27,43", help="lattice cells per side")
    parser.add_argument("--no-tets", action="store_true", help="skip the tetgen block and ring")
    args = parser.parse_args()
    runtime.init(args.arch)

    rows = []
    for n in [int(s) for s in args.sizes.split(",")]:
        rows += block_rows("lattice", *jittered_block(n), args.repeat)
    if not args.no_tets:
        for target in (5000, 20000):
            rows += block_rows("tets", *tet_block(target), args.repeat)

    print(f"arch {args.arch}; E {E:g} Pa, nu {NU}; force {FORCE.tolist()} N at the top centre")
    print("| block | particles | neighbours | gradient | error interior | error +surface | "
          "error far (>= 0.25 m) | field ms | neighbours ms | gradient ms | stress+principal ms | total ms |")
    print("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for label, n, nbrs, kind, err, tf, tn, tg, ts, tt in rows:
        print(f"| {label} | {n:,} | {nbrs:.1f} | {kind} | {100 * err['interior']:.1f}% | "
              f"{100 * err['+surface']:.1f}% | {100 * err['far']:.2f}% | {1e3 * tf:.2f} | "
              f"{1e3 * tn:.2f} | {1e3 * tg:.2f} | {1e3 * ts:.2f} | {1e3 * tt:.1f} |")

    if not args.no_tets:
        from taichi_frac.fracture import contact_field

        # The fracture tests' ring (tetgen, ~5,000 tets), the one bench_fracture.py uses.
        from _fracture_ring import RING_CONTACT, RING_FORCE, RING_NORMAL, ring_model

        model = ring_model()
        pts, vol = model.particle_position, model.tet_volume
        contact, normal, force = RING_CONTACT, RING_NORMAL, RING_FORCE
        contact_field(pts, vol, contact, normal, force, E, NU)  # warm-up
        t, f = best_time(lambda: contact_field(pts, vol, contact, normal, force, E, NU), args.repeat)
        print(f"\nring: {len(pts):,} particles, one impact's contact_field (field + neighbours + "
              f"corrected gradient + stress + principal): {1e3 * t:.1f} ms; peak principal "
              f"stress {f.principal_stress.max() / 1e6:.2f} MPa; correction fallbacks "
              f"{int(f.correction_fallback.sum())}")


if __name__ == "__main__":
    main()
