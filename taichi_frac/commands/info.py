"""``taichi-frac info``: mesh a solid and print its two-scale model's sizes (Table 1).

Prints the paper's Table 1 columns (physics particles, physics surface particles, boundary
particles) plus tets, volume error, min dihedral angle, mass properties and timings.
"""

from __future__ import annotations

import argparse
import json
import sys

EPILOG = """\
examples:
  taichi-frac info torus                            the paper's ring (R 0.1 m, r 0.025 m)
  taichi-frac info torus:major=0.1,minor=0.025 --particles 5000
  taichi-frac info box:x=1,y=1,z=0.01 --material soda_lime_glass
  taichi-frac info teapot.obj --units cm --repair --json
  taichi-frac info part.msh                         a tet mesh, used as is

primitives (sizes in metres): torus|ring:major=,minor=  box:x=,y=,z=  sphere:radius=
  cylinder:radius=,height=
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "info",
        help="mesh a solid and report its particle counts, mesh quality and mass properties",
        description=__doc__.split("\n\n")[0].replace("``", "'"),
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("source", metavar="MESH_OR_PRIMITIVE",
                   help="surface file (OBJ/STL/PLY/OFF/glTF/GLB), tet mesh (.msh/.vtk/.vtu/.mesh) or primitive spec")
    p.add_argument("--particles", type=int, default=5000, metavar="N",
                   help="target number of physics particles (= tets) (default: 5000)")
    p.add_argument("--max-volume", type=float, default=None, metavar="M3",
                   help="mesh with this maximum tet volume [m^3] instead of a target count")
    p.add_argument("--group-size", type=int, default=4, metavar="n",
                   help="surface particles merged into one boundary particle (paper: 4; default: 4)")
    p.add_argument("--drop-leftovers", action="store_true",
                   help="drop surface particles that cannot be grouped instead of keeping them alone")
    p.add_argument("--units", choices=("m", "cm", "mm"), default="m", help="unit of the file's coordinates (default: m)")
    p.add_argument("--scale", type=float, default=1.0, help="extra scale factor on the coordinates (default: 1)")
    p.add_argument("--repair", action="store_true", help="repair holes, flipped faces and self-intersections first")
    p.add_argument("--thickness", type=float, default=None, metavar="M",
                   help="make an open sheet a closed shell this thick [m] (a pane, a sign, a leaf)")
    p.add_argument("--up-axis", choices=("z", "y"), default="z",
                   help="up axis of an OBJ/PLY/STL/OFF file's coordinates; y is turned Z up (glTF/GLB: always y) "
                        "(default: z)")
    p.add_argument("--material", default="porcelain",
                   help="material preset for the mass: porcelain, soda_lime_glass, concrete (default: porcelain)")
    p.add_argument("--backend", choices=("tetgen", "wildmeshing"), default="tetgen",
                   help="tet mesher (default: tetgen)")
    p.add_argument("--time-limit", type=float, default=60.0, metavar="S",
                   help="wall-clock bound on loading, checking, repairing and meshing [s] (default: 60)")
    p.add_argument("--no-cache", action="store_true", help="do not read or write the on-disk tet cache")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.set_defaults(func=run)


def _table(report) -> str:
    from ..geometry.simplify import TET_EDGE_PER_SPACING

    t = report.timings
    com = ", ".join(f"{c:.6g}" for c in report.center_of_mass)
    inertia = report.inertia
    rows = [
        ("source", report.source),
        ("physics particles (tets)", f"{report.physics_particles:,}"),
        ("physics surface particles", f"{report.surface_particles:,}"),
        ("boundary particles", f"{report.boundary_particles:,}"
         + (f" ({report.dropped_surface_particles} surface particles dropped)" if report.dropped_surface_particles else "")),
        ("surface triangles in", "n/a (tet mesh)" if report.surface_triangles < 0 else f"{report.surface_triangles:,}"
         + (f" (tets fill a copy of {report.tet_surface_triangles:,})"
            if report.tet_surface_triangles not in (-1, report.surface_triangles) else "")),
        ("volume", f"{report.tet_volume:.6g} m^3 (surface {report.surface_volume:.6g} m^3, error {report.volume_error:+.2e})"),
        ("particle spacing", f"{report.particle_spacing:.3g} m (mean tet V^(1/3); a regular tet of that volume has "
                             f"edges {TET_EDGE_PER_SPACING:.2f} times as long)"),
        ("min dihedral angle", f"{report.min_dihedral_deg:.2f} deg ({report.sliver_count} tets below 5 deg)"),
        ("mass", f"{report.mass:.6g} kg"),
        ("centre of mass (source frame)", f"({com}) m"),
        ("inertia diag (about COM)", f"({inertia[0][0]:.6g}, {inertia[1][1]:.6g}, {inertia[2][2]:.6g}) kg m^2"),
        ("mesher", report.backend + (" (cached)" if report.cache_hit else "")),
        ("time", f"load {t.get('load', 0):.2f} s, mesh {t.get('mesh', 0):.2f} s, model {t.get('model', 0):.2f} s, "
                 f"total {t.get('total', 0):.2f} s"),
    ]
    if report.kept_volume_fraction is not None:
        rows.append(("kept of the input", f"{100 * report.kept_volume_fraction:.1f} % of its winding-number volume "
                                          f"({report.input_volume:.6g} m^3)"))
    if report.tet_extents:
        size = ", ".join(f"{e:.4g}" for e in report.tet_extents)
        rows.append(("extents (x, y, z)", f"({size}) m; up is +z (world), "
                                          f"{'turned from the file +y' if report.up_axis == 'y' else 'the file +z'}"))
    if report.input_extents and report.tet_extents:
        ratio = ", ".join(f"{t / i:.3f}" if i > 0 else "-" for t, i in zip(report.tet_extents, report.input_extents))
        rows.append(("extents kept (x, y, z)", ratio))
    if report.surface_deviation is not None:
        rows.append(("farthest surface point", f"{report.surface_deviation:.3g} m from the simulated solid"))
    if report.repair_steps:
        rows.append(("repair", "; ".join(report.repair_steps)))
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def _check_arguments(args) -> None:
    """What the mesher cannot take, refused before any work (OptionError)."""
    import math

    from ..geometry.meshio_in import unit_scale
    from ..geometry.primitives import parse_primitive_spec
    from ..options import OptionError
    from ..scenes.description import check_primitive_size

    if args.max_volume is not None and not (math.isfinite(args.max_volume) and args.max_volume > 0):
        raise OptionError(f"--max-volume {args.max_volume!r}: give a tet volume above 0 m^3, e.g. 1e-7")
    if args.thickness is not None and not (math.isfinite(args.thickness) and args.thickness > 0):
        raise OptionError(f"--thickness {args.thickness!r}: give a shell thickness above 0 m, e.g. 0.005")
    if not (math.isfinite(args.time_limit) and args.time_limit > 0):
        raise OptionError(f"--time-limit {args.time_limit!r}: give a number of seconds above 0, e.g. 300")
    factor = unit_scale(args.scale, args.units)
    if parse_primitive_spec(args.source) is not None:
        check_primitive_size(args.source, factor)


def run(args) -> int:
    from ..geometry.prepare import prepare_body
    from ..geometry.validate import MeshError
    from ..options import OptionError, ParticleOptions, SimulationOptions

    try:
        _check_arguments(args)
        particles = ParticleOptions(target_particles=args.particles, boundary_group_size=args.group_size,
                                    keep_leftovers=not args.drop_leftovers)
        _, report = prepare_body(args.source, scale=args.scale, units=args.units, material=args.material,
                                 particles=particles, repair=args.repair, max_volume=args.max_volume,
                                 backend=args.backend, use_cache=not args.no_cache, time_limit=args.time_limit,
                                 thickness=args.thickness, up_axis=args.up_axis,
                                 # (the boundary grouping a run gets: its default contact)
                                 surface_contact=SimulationOptions().surface_contact)
    except (MeshError, OptionError) as exc:
        print(f"taichi-frac info: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(report.as_dict()))
    else:
        print(_table(report))
    return 0
