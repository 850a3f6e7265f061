"""Surface contacts against the boundary grouping n (``particles.boundary_group_size``):
with surface contacts the spheres only find which patches may touch, so coarser spheres
(fewer of them, larger patches) cost less while the rest heights, which the patches set,
stay, and so does a landing's impulse (it acts at the patch's lowest point,
``collision.surface.LANDING_BAND``). What the coarser spheres do change is how a body of few
tets is covered, and the rolling resistance (a fraction of the sphere radius). Part of the
contact page (``contact.contact_section``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .common import BenchContext, md_table

#: The groupings compared, each with surface contacts, against sphere contacts at n = 4:
#: every body grouped by n (``surface_group_size`` 0), and ``DEFAULT`` (n = 4, and
#: ``ParticleOptions().surface_group_size`` for bodies large enough, ``model.group_sizes``).
DEFAULT = "default"
GROUPINGS = (4, 8, 12, DEFAULT)

#: Rounds of the unbroken 13 rings: each runs sphere contacts (n = 4) and every grouping
#: once, back to back; each grouping's ratio is the median of the rounds' ratios.
GROUPING_RING_RUNS = 7

#: Crack-seed shifts of the 13 rings with fracture (a subset of the contact table's), each
#: run once per mode, interleaved; the modes are compared on their mean.
GROUPING_SEED_SHIFTS = (0, 13, 26, 39)


def _grouping(n) -> tuple[int, int | None]:
    """A ``GROUPINGS`` entry as (boundary_group_size, surface_group_size; None: default)."""
    return (4, None) if n == DEFAULT else (n, 0)


def _label(n) -> str:
    """A ``GROUPINGS`` entry as the table names it."""
    if n != DEFAULT:
        return str(n)
    from taichi_frac.model import COARSE_MIN_SPHERES
    from taichi_frac.options import ParticleOptions

    coarse = ParticleOptions().surface_group_size
    return (f"4, and {coarse} for bodies of {COARSE_MIN_SPHERES * coarse}+ surface particles whose patches keep their "
            "facets (the default)")


def _grouped(scene, n, surface: bool):
    """``scene`` with every object grouped by the ``GROUPINGS`` entry ``n`` and the contact
    mode ``surface`` (two-scale)."""
    from .contact import _with_contact

    group, coarse = _grouping(n)
    extra = {} if coarse is None else {"surface_group_size": coarse}
    objects = [dataclasses.replace(o, particles=dataclasses.replace(o.particles, boundary_group_size=group, **extra))
               for o in scene.objects]
    return _with_contact(dataclasses.replace(scene, objects=objects), False, surface)


def _ring_ms(ctx: BenchContext, scene, fracture: bool, frames) -> tuple[float, int, int]:
    """One 13-ring run: mean ms/frame (first frame left out), collision spheres at the start,
    fragments."""
    from .tables import run_scene

    _, summary, counts = run_scene(ctx, scene, "13 rings, grouping", fracture=fracture, frames=frames)
    return float(summary.ms_per_frame["mean_after_first"]), int(counts["collision"]), int(summary.fragments)


def grouping_section(ctx: BenchContext, scene, frames=None, seed_scenes=None) -> str:
    """The table of surface contacts at each of ``GROUPINGS`` (markdown): the 13 rings'
    time without and with fracture against sphere contacts at n = 4, in one run, and the
    ring drop and the coarse cube stack against their references."""
    from .contact import LANDING_TILTS, _cube_on_cube, _landing, _ring_drop, landing_row

    reference = _ring_drop(ctx, single=True, surface=False)
    drops = {n: _ring_drop(ctx, False, True, *_grouping(n)) for n in GROUPINGS}
    cubes = {n: _cube_on_cube(ctx, False, True, 60, *_grouping(n)) for n in GROUPINGS}
    landings = {n: _landing(ctx, False, True, *_grouping(n)) for n in GROUPINGS}
    def variants_of(sc):  # sphere contacts at n = 4, then surface contacts at each grouping
        return {"sphere": _grouped(sc, 4, False)} | {n: _grouped(sc, n, True) for n in GROUPINGS}

    variants = variants_of(scene)
    off = {k: [] for k in variants}
    spheres = {}
    for _ in range(GROUPING_RING_RUNS):
        for k, sc in variants.items():
            ms, spheres[k], _ = _ring_ms(ctx, sc, False, frames)
            off[k].append(ms)
    base = np.asarray(off["sphere"])
    scenes = seed_scenes or [scene]
    on = {k: [] for k in variants}
    for sc in scenes:
        for k, variant in variants_of(sc).items():
            on[k].append(_ring_ms(ctx, variant, True, frames))
    on_ms = {k: float(np.mean([r[0] for r in on[k]])) for k in variants}
    rows = []
    for n in GROUPINGS:
        ratios = np.asarray(off[n]) / base
        d = drops[n]
        rows.append([
            _label(n), f"{spheres[n]:,}",
            f"{np.median(off[n]):.2f} ({np.median(ratios):.2f}x, {ratios.min():.2f}-{ratios.max():.2f})",
            f"{on_ms[n]:.1f} ({on_ms[n] / on_ms['sphere']:.2f}x) / {np.mean([r[2] for r in on[n]]):.0f}",
            f"{1e3 * (d['rest'] - 0.025):+.2f}",
            f"{100 * (d['rebound'] / max(reference['rebound'], 1e-12) - 1):+.1f} %",
            f"{100 * (d['impulse'] / max(reference['impulse'], 1e-12) - 1):+.1f} %",
            landing_row(landings[n]),
            f"{1e3 * cubes[n]:+.2f}",
        ])
    sets = f"{len(scenes)} seed sets" if len(scenes) > 1 else "the scene's seeds"
    header = ["n (surface contacts)", "13 rings: collision spheres",
              f"13 rings, fracture off: ms/frame, median of {GROUPING_RING_RUNS} rounds (ratio to sphere contacts "
              f"at n = 4, {np.median(base):.2f} ms: median of the rounds' ratios, least-most)",
              f"13 rings, fracture on: ms/frame, mean over {sets} (ratio to sphere contacts at n = 4, "
              f"{on_ms['sphere']:.1f} ms, {np.mean([r[2] for r in on['sphere']]):.0f} fragments) / fragments",
              "torus at rest, COM z − exact 25.0 mm [mm]", "ring drop: rebound vs single-scale",
              "ring drop: first-impact impulse vs single-scale",
              "torus landing without friction, tilted " + " / ".join(str(t) for t in LANDING_TILTS)
              + "°: first impact's normal impulse − closed form [%]",
              "0.1 m cube on a cube (60 tets each), COM z above the lower − exact 100.0 mm [mm]"]
    return md_table(header, rows)
