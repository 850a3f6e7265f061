"""Part 2b: speed against error of the contact stress analysis (fracture/field.py, sph.py,
stress.py), plain and corrected (Bonet-Lok) SPH gradient.

Block: the unit cube x, y in [-1/2, 1/2], z in [0, 1]: a lattice of n^3 cells jittered by
+-0.2 spacing (``fracture_ring.jittered_block``, the block the stress test
checks; volumes = spacing^3), and blocks of tetgen tet centroids (what a real body gives;
volumes = tet volumes). Load: force (2e4, -1e4, -1e5) N at the centre of the top face,
E = 70 GPa, nu = 0.2, default h = 2 x spacing and contact radius = the nearest particle's.

Error: relative L2 (Frobenius) error of the SPH stress against the exact stress of the
same (regularised) displacement field -- its complex-step gradient through the same strain
and Hooke law -- over a set of particles S:
    e = sqrt(sum_S |sigma_sph - sigma_exact|_F^2 / sum_S |sigma_exact|_F^2)
    S = interior: >= 2h from the load and >= h (a full kernel support) from every face;
    S = +surface: >= 2h from the load, surface particles included;
    S = far: >= 0.25 m from the load (fixed region, shows convergence with resolution).
Times: best of ``repeat`` runs after a warm-up (kernels compiled). Then one impact's
analysis (field + neighbours + gradient + stress + principal) on the ~5,000-particle ring
of ``fracture_ring`` (torus R 0.1 m, r 0.025 m, tetgen), 1e4 N at the outer equator.

``benchmarks/bench_stress.py`` is the command-line front of this module.
"""

from __future__ import annotations

import time

import numpy as np

from tests.support import fracture_ring
from .common import BenchContext, Section, md_table, pyplot
from tests.support.fracture_ring import jittered_block

E, NU = 70.0e9, 0.2
FORCE = np.array([2e4, -1e4, -1e5])
TOP = np.array([0.0, 0.0, 1.0])
DOWN = np.array([0.0, 0.0, -1.0])
LATTICE_SIZES = (10, 17, 27, 43)
TET_TARGETS = (5000, 20000)


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
    """Rows (label, particles, neighbours per particle, gradient kind, errors dict, field s,
    neighbours s, gradient s, stress+principal s, total s), plain then corrected."""
    from taichi_frac.fracture import (contact_field, default_smoothing_length, displacement_gradient, neighbor_lists,
                            point_load_displacement, principal_stresses, stress_from_gradient)
    from taichi_frac.fracture.field import point_load_gradient_reference

    h = default_smoothing_length(vol)
    field = contact_field(pts, vol, TOP, DOWN, FORCE, E, NU)  # warm-up, default radius
    a = field.contact_radius
    shear = E / (2 * (1 + NU))
    exact = stress_from_gradient(point_load_gradient_reference(pts, TOP, DOWN, FORCE, shear, NU, a), E, NU)
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


def measure(sizes=LATTICE_SIZES, tet_targets=TET_TARGETS, repeat=3, progress=None):
    rows = []
    for n in sizes:
        rows += block_rows("lattice", *jittered_block(n), repeat)
        if progress:
            progress(f"sph: lattice {n}^3 done")
    for target in tet_targets:
        rows += block_rows("tets", *tet_block(target), repeat)
        if progress:
            progress(f"sph: tet block ~{target} done")
    return rows


def ring_impact(repeat=3):
    """One impact's contact_field on the fracture tests' ring: (particles, seconds, peak
    principal stress [Pa], correction fallbacks)."""
    from taichi_frac.fracture import contact_field

    model = fracture_ring.struck_ring_model()
    pts, vol = model.particle_position, model.tet_volume
    args = (pts, vol, fracture_ring.RING_CONTACT, fracture_ring.RING_NORMAL, fracture_ring.RING_FORCE, E, NU)
    contact_field(*args)  # warm-up
    t, f = best_time(lambda: contact_field(*args), repeat)
    return len(pts), t, float(f.principal_stress.max()), int(f.correction_fallback.sum())


def table(rows) -> str:
    return md_table(
        ["block", "particles", "neighbours", "gradient", "error interior", "error +surface",
         "error far (>= 0.25 m)", "field ms", "neighbours ms", "gradient ms", "stress+principal ms", "total ms"],
        [[label, f"{n:,}", f"{nbrs:.1f}", kind, f"{100 * err['interior']:.1f}%", f"{100 * err['+surface']:.1f}%",
          f"{100 * err['far']:.2f}%", f"{1e3 * tf:.2f}", f"{1e3 * tn:.2f}", f"{1e3 * tg:.2f}", f"{1e3 * ts:.2f}",
          f"{1e3 * tt:.1f}"] for label, n, nbrs, kind, err, tf, tn, tg, ts, tt in rows],
        "lrrlrrrrrrrr")


def run(ctx: BenchContext, sizes=None, tet_targets=None, repeat=None, ring=True) -> Section:
    from taichi_frac import runtime

    runtime.init(ctx.arch)
    t0 = time.perf_counter()
    sizes = sizes if sizes is not None else ((8, 12) if ctx.quick else LATTICE_SIZES)
    tet_targets = tet_targets if tet_targets is not None else (() if ctx.quick else TET_TARGETS)
    repeat = repeat if repeat is not None else (1 if ctx.quick else 3)
    rows = measure(sizes, tet_targets, repeat, ctx.progress)
    parts = [
        "Speed against error of one contact's stress analysis (`fracture/field.py`, `sph.py`, `stress.py`): "
        f"a unit block loaded at the centre of its top face by {FORCE.tolist()} N, E = {E / 1e9:g} GPa, "
        f"nu = {NU}. Error: relative L2 error of the SPH stress against the exact stress of the same "
        "displacement field (its complex-step gradient), over the **interior** (>= 2h from the load, >= h from "
        "every face), **+surface** (>= 2h from the load) and **far** (>= 0.25 m from the load) particles. "
        "Lattice: `jittered_block` of `tests/support/fracture_ring.py` (the stress test's block); tets: tetgen "
        f"centroids. Times: best of {repeat} after a warm-up.",
        "",
        table(rows),
    ]
    headline = {}
    if ring:
        n, t, peak, fallbacks = ring_impact(repeat)
        parts += ["", f"One impact on the fracture tests' ring ({n:,} particles, 1e4 N at the outer equator): "
                      f"`contact_field` (field + neighbours + corrected gradient + stress + principal) "
                      f"{1e3 * t:.1f} ms; peak principal stress {peak / 1e6:.2f} MPa; correction fallbacks "
                      f"{fallbacks}."]
        headline["ring_ms"] = 1e3 * t
    path, link = _plot(ctx, rows)
    parts += ["", f"![SPH stress error against particles and time]({link})", "",
              f"*Part time: {time.perf_counter() - t0:.0f} s.*"]
    lattice = [r for r in rows if r[0] == "lattice"]
    if lattice:
        biggest = max(r[1] for r in lattice)
        headline["lattice"] = {r[3]: (r[1], r[4]["interior"], r[9]) for r in lattice if r[1] == biggest}
    return Section("sph", "SPH stress error against particle count and time", "\n".join(parts), [path],
                   headline | {"rows": rows})


def _plot(ctx, rows):
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.8))
    for (label, kind), style in zip([(lb, k) for lb in ("lattice", "tets") for k in ("plain", "corrected")],
                                    ("o--", "o-", "s--", "s-")):
        sel = [r for r in rows if r[0] == label and r[3] == kind]
        if not sel:
            continue
        n = np.array([r[1] for r in sel])
        err = np.array([100 * r[4]["interior"] for r in sel])
        total = np.array([1e3 * r[9] for r in sel])
        ax1.loglog(n, err, style, label=f"{label}, {kind}")
        ax2.loglog(total, err, style, label=f"{label}, {kind}")
    ax1.set_xlabel("particles")
    ax1.set_ylabel("interior stress error [%]")
    ax1.set_title("error against particle count")
    ax2.set_xlabel("analysis time [ms]")
    ax2.set_ylabel("interior stress error [%]")
    ax2.set_title("error against time")
    ax1.legend(fontsize=8)
    return ctx.save_figure(fig, "sph_stress.png")


def main(argv=None) -> None:
    """``benchmarks/bench_stress.py``: print the table."""
    import argparse

    from taichi_frac import runtime

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--sizes", default=",".join(map(str, LATTICE_SIZES)), help="lattice cells per side")
    parser.add_argument("--no-tets", action="store_true", help="skip the tetgen block and ring")
    args = parser.parse_args(argv)
    runtime.init(args.arch)
    rows = measure([int(s) for s in args.sizes.split(",")], () if args.no_tets else TET_TARGETS, args.repeat)
    print(f"arch {args.arch}; E {E:g} Pa, nu {NU}; force {FORCE.tolist()} N at the top centre")
    print(table(rows))
    if not args.no_tets:
        n, t, peak, fallbacks = ring_impact(args.repeat)
        print(f"\nring: {n:,} particles, one impact's contact_field (field + neighbours + corrected gradient + "
              f"stress + principal): {1e3 * t:.1f} ms; peak principal stress {peak / 1e6:.2f} MPa; "
              f"correction fallbacks {fallbacks}")
