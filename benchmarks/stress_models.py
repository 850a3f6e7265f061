"""Part: the three stress models (``fracture.stress_model``: "sph", "halfspace", "fem"), speed
against error.

1. **Cube against the exact half-space.** A cube of side L tetrahedralized by the project,
   particles at the tet centroids, the load (2e4, -1e4, -1e5) N at the centre of its top
   face, E = 70 GPa, nu = 0.2, the contact radius the nearest particle's. Reference: the
   exact stress of the same regularised load (``field.point_load_gradient_reference``).
   Errors over the interior particles 2h < r < L/3 from the load (h = 2 x spacing): L1 of
   the stress tensor and of the largest principal stress (the crack criterion). FEM also
   on larger and finer cubes: a half-space is the limit of a growing block.
2. **The ring under its landing impact** (scenes/single_ring.toml's ring, tilted as there,
   180 kN along the ground normal at its lowest point) against a converged reference: FEM on
   a mesh of 8x the tets. Errors: L1 of the largest principal stress over the whole ring
   (the reference's value at the nearest reference centroid), and the distance from each
   model's peak tensile point to the reference's. Time: one ``analyze_impact`` (crack
   count 1, whole field), the body's SPH lists and FEM factorisation already built (the
   simulation builds them once per body); the factorisation's own time beside it.
3. **The scenes**: the single ring's three controls and the 13 rings under each model,
   fragments and ms per frame.
"""

from __future__ import annotations

import time

import numpy as np

from .common import BenchContext, Section, load_average, md_table, pyplot
from .sph import best_time

E, NU = 70.0e9, 0.2
FORCE = np.array([2e4, -1e4, -1e5])
MODELS = ("sph", "halfspace", "fem")
LANDING_FORCE = 1.8e5  # [N] the single ring's landing peak (scenes/single_ring.toml)


def _l1(a, b):
    return float(np.sum(np.abs(a - b)) / np.sum(np.abs(b)))


def cube_rows(side, target, models=MODELS, repeat=2):
    """Rows (model, side [m], tets, stress L1, principal L1, ms per analysis, factor ms)."""
    from taichi_frac.fracture import body_stress
    from taichi_frac.fracture.fem import elastic_body, fem_response
    from taichi_frac.fracture.field import point_load_gradient_reference
    from taichi_frac.fracture.stress import largest_principal_stress, stress_from_gradient
    from taichi_frac.geometry.primitives import box
    from taichi_frac.geometry.tetra import tetrahedralize

    mesh = tetrahedralize(box((side, side, side)), target_tets=target)
    vertices = mesh.vertices - mesh.vertices.mean(axis=0)
    top = np.array([0.0, 0.0, vertices[:, 2].max()])
    down = np.array([0.0, 0.0, -1.0])
    rows = []
    exact = None
    result = None
    for model in models:
        if model == "fem":
            t_factor, body = best_time(lambda: elastic_body(vertices, mesh.tets, 2500.0, E, NU), 1)
            if result is None:  # fem first: the contact radius the other models use
                result = body_stress(vertices, mesh.tets, 2500.0, top, down, FORCE, E, NU, method="halfspace")
            radius = result.contact_radius
            t, (_, stress) = best_time(lambda: fem_response(body, top, down, FORCE, radius), repeat)
        else:
            t_factor = 0.0
            body_stress(vertices, mesh.tets, 2500.0, top, down, FORCE, E, NU, method=model)  # warm-up
            t, result = best_time(lambda: body_stress(vertices, mesh.tets, 2500.0, top, down, FORCE, E, NU,
                                                  method=model), repeat)
            stress = result.stress
        if exact is None:
            shear = E / (2 * (1 + NU))
            exact = stress_from_gradient(point_load_gradient_reference(
                result.centroids, top, down, FORCE, shear, NU, result.contact_radius[0]), E, NU)
            h = 2.0 * float(np.mean(np.cbrt(result.volumes)))
            r = np.linalg.norm(result.centroids - top, axis=1)
            interior = (r > 2 * h) & (r < side / 3)
            exact_peak = largest_principal_stress(exact)
        peak = largest_principal_stress(stress)
        rows.append((model, side, len(mesh.tets), _l1(stress[interior], exact[interior]),
                     _l1(peak[interior], exact_peak[interior]), 1e3 * t, 1e3 * t_factor))
    return rows


def scene_ring(target):
    """The single ring's BodyModel at about ``target`` tets, and its world orientation (3,3)."""
    from taichi_frac.kinematics.quaternion import quaternion_matrix
    from taichi_frac.scenes import load_scene
    from .common import SCENES

    scene = load_scene(SCENES / "single_ring.toml", [f"ring.particles.target_particles={target}"])
    obj = scene.objects[0]
    model, _ = obj.prepare()
    return model, quaternion_matrix(obj.orientation), obj


def landing_load(model, rotation):
    """(contact point, inward normal, force) in the body frame: the ring's lowest point when
    oriented as in the scene, pushed up by LANDING_FORCE along the ground normal."""
    world = model.vertices @ rotation.T
    point = model.vertices[int(np.argmin(world[:, 2]))]
    up = rotation.T @ np.array([0.0, 0.0, 1.0])
    return point, up, LANDING_FORCE * up


def ring_rows(targets=(5000, 20000), reference_factor=8, repeat=2, progress=None):
    """Rows (model, tets, principal L1 vs reference, peak distance [m], ms per analysis,
    factor ms) and the reference's tet count, plus the 5k ring's fields for the picture."""
    from taichi_frac.fracture.cracks import analyze_impact
    from taichi_frac.fracture.fem import elastic_body_of, fem_response
    from taichi_frac.fracture.stress import largest_principal_stress
    from taichi_frac.options import FractureOptions, Material
    from scipy.spatial import cKDTree

    material = Material(density=2400.0, young_modulus=E, poisson_ratio=NU, tensile_strength=1e12)
    ref_model, rotation, _ = scene_ring(reference_factor * targets[0])
    point, normal, force = landing_load(ref_model, rotation)
    t0 = time.perf_counter()
    ref_body = elastic_body_of(ref_model, material)
    if progress:
        progress(f"stress models: reference ring {ref_model.tet_count:,} tets factorised in "
                 f"{time.perf_counter() - t0:.1f} s")
    nearest = np.argmin(np.linalg.norm(ref_model.particle_position - point, axis=1))
    _, ref_stress = fem_response(ref_body, point, normal, force, [ref_model.particle_radius[nearest]])
    ref_peak = largest_principal_stress(ref_stress)
    ref_top = ref_model.particle_position[int(np.argmax(ref_peak))]
    tree = cKDTree(ref_model.particle_position)
    rows, pictures = [], {}
    for target in targets:
        model, rotation, _ = scene_ring(target)
        point, normal, force = landing_load(model, rotation)
        if target == targets[0]:
            pictures["rotation"] = rotation
        _, which = tree.query(model.particle_position)
        options = {kind: FractureOptions(stress_model=kind, crack_count=1, crack_length=0.25) for kind in MODELS}
        t_factor, _ = best_time(lambda: elastic_body_of(model, material), 1)
        results = {kind: analyze_impact(model, point, normal, force, material, options[kind]) for kind in MODELS}
        times = {kind: np.inf for kind in MODELS}
        for _ in range(repeat):  # interleaved rounds: the machine's load hits every model alike
            for kind in MODELS:
                t, _ = best_time(lambda: analyze_impact(model, point, normal, force, material, options[kind]), 1)
                times[kind] = min(times[kind], t)
        for kind in MODELS:
            peak = results[kind].particle_principal_stress
            top = model.particle_position[int(np.argmax(peak))]
            rows.append((kind, model.tet_count, _l1(peak, ref_peak[which]), float(np.linalg.norm(top - ref_top)),
                         1e3 * times[kind], 1e3 * t_factor if kind == "fem" else 0.0))
            if target == targets[0]:
                pictures[kind] = (model, peak)
            if progress:
                progress(f"stress models: ring {model.tet_count:,} tets, {kind}: {1e3 * times[kind]:.1f} ms")
    return rows, ref_model.tet_count, pictures


def scene_rows(ctx: BenchContext, frames=None, rings=True):
    """Rows (scene, model, fragments, ms per frame mean) for the single ring's controls and
    the 13 rings, every breakable object switched to each model."""
    from taichi_frac.scenes import load_scene
    from .common import SCENES
    from .tables import run_scene

    from taichi_frac.simulation import Simulation

    for kind in MODELS:  # compile each model's kernels outside the timed runs
        scene = load_scene(SCENES / "single_ring.toml", ["simulation.duration=0.8", "ring.fracture.crack_count=2",
                                                                  f"ring.fracture.stress_model={kind}"])
        Simulation(scene, output=False, world=ctx.world()).run()
    rows = []
    cases = [("single ring, crack_count " + str(n), "single_ring", [f"ring.fracture.crack_count={n}"])
             for n in (1, 2, 4)]
    if rings:
        cases.append(("13 rings", "thirteen_rings", []))
    for label, name, overrides in cases:
        base = load_scene(SCENES / f"{name}.toml", overrides)
        for kind in MODELS:
            switch = [f"{o.name}.fracture.stress_model={kind}" for o in base.breakable_objects]
            scene = load_scene(SCENES / f"{name}.toml", overrides + switch)
            _, summary, _ = run_scene(ctx, scene, f"{label}, {kind}", frames=frames)
            rows.append((label, kind, summary.fragments, summary.ms_per_frame["mean"],
                         1e3 * summary.stage_seconds["fracture_analysis"] / max(summary.frames, 1)))
            ctx.progress(f"stress models: {label}, {kind}: {summary.fragments} fragments, "
                         f"{summary.ms_per_frame['mean']:.1f} ms/frame")
    return rows


def run(ctx: BenchContext, scenes: bool = True) -> Section:
    from taichi_frac import runtime

    runtime.init(ctx.arch)
    t0 = time.perf_counter()
    load_start = load_average()
    repeat = 1 if ctx.quick else 5
    cubes = [(0.2, 5000), (0.2, 20000)] if not ctx.quick else [(0.2, 2000)]
    fem_cubes = [] if ctx.quick else [(0.4, 20000), (0.4, 40000)]
    cube = []
    for side, target in cubes:
        cube += cube_rows(side, target, repeat=repeat)
        ctx.progress(f"stress models: cube {side} m, ~{target} tets done")
    for side, target in fem_cubes:
        cube += cube_rows(side, target, models=("halfspace", "fem"), repeat=repeat)
        ctx.progress(f"stress models: cube {side} m, ~{target} tets done")
    ring, ref_tets, pictures = ring_rows((2000,) if ctx.quick else (5000, 20000), repeat=repeat,
                                         progress=ctx.progress)
    scene = scene_rows(ctx, frames=10 if ctx.quick else None) if scenes else []
    parts = [
        "The three stress models of `fracture.stress_model` (docs/guide/stress-models.md). The machine was "
        f"shared with other jobs while this ran (load average at the start {load_start}, at the end "
        f"{load_average()}): times compare models within one table (the ring's are interleaved rounds), "
        "not across reports.",
        "",
        f"**Cube against the exact half-space**: load {FORCE.tolist()} N at the top centre, E = {E / 1e9:g} GPa, "
        f"nu = {NU}; L1 errors over the particles 2h < r < L/3 from the load (h = 2 x spacing). `halfspace` "
        "is that exact field by construction; FEM converges toward it as the block grows and the mesh refines. "
        "ms: one analysis (`body_stress`; FEM: the solve, its factorisation beside it, once per body).",
        "",
        md_table(["model", "cube side [m]", "tets", "stress L1 error", "largest principal L1 error",
                  "ms per analysis", "factorisation ms"],
                 [[m, f"{s:g}", f"{n:,}", f"{100 * e:.1f}%", f"{100 * p:.1f}%", f"{t:.1f}",
                   f"{f:.0f}" if m == "fem" else ""] for m, s, n, e, p, t, f in cube], "lrrrrrr"),
        "",
        f"**The ring under its landing impact** ({LANDING_FORCE / 1e3:.0f} kN at its lowest point, tilted as in "
        f"`scenes/single_ring.toml`) against FEM on a {ref_tets:,}-tet mesh of the same ring: L1 error of the "
        "largest principal stress over the whole ring, distance of each model's peak tensile point from the "
        "reference's, ms per `analyze_impact` (whole field, crack count 1; SPH lists and FEM factorisation "
        "built once per body, their time beside it).",
        "",
        md_table(["model", "tets", "largest principal L1 error", "peak point off by [mm]", "ms per analysis",
                  "factorisation ms"],
                 [[m, f"{n:,}", f"{100 * e:.0f}%", f"{1e3 * d:.0f}", f"{t:.1f}", f"{f:.0f}" if m == "fem" else ""]
                  for m, n, e, d, t, f in ring], "lrrrrr"),
    ]
    if scene:
        parts += ["", "**The scenes under each model** (every breakable object switched; the scene files' "
                      "strengths as they are): fragments at the end, mean ms per frame, and of it the fracture "
                      "analysis's ms per frame (including FEM factorisations of pieces first struck).", "",
                  md_table(["scene", "model", "fragments", "ms per frame", "analysis ms per frame"],
                           [[lb, m, f, f"{ms:.2f}", f"{a:.2f}"] for lb, m, f, ms, a in scene], "llrrr")]
    plot_path, link = _plot(ctx, cube, ring)
    picture_path, picture_link = heat_map(ctx, pictures)
    parts += ["", f"![stress models: error against time]({link})", "",
              f"![largest principal stress on the ring, three models]({picture_link})", "",
              f"*Part time: {time.perf_counter() - t0:.0f} s.*"]
    markdown = "\n".join(parts)
    if not ctx.quick:  # the section as its own file beside its pictures, for the report to link
        page = markdown.replace(link, plot_path.name).replace(picture_link, picture_path.name)
        (plot_path.parent / "stress_models.md").write_text("# Stress models: speed against error\n\n" + page + "\n")
    return Section("stress_models", "Stress models: speed against error", markdown,
                   [plot_path, picture_path], {"cube": cube, "ring": ring, "scenes": scene})


def _plot(ctx, cube, ring):
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.8))
    styles = {"sph": "o-", "halfspace": "s-", "fem": "^-"}
    for kind in MODELS:
        sel = [r for r in cube if r[0] == kind]
        if sel:
            ax1.plot([r[5] for r in sel], [100 * r[4] for r in sel], styles[kind], label=kind)
            for r in sel:
                ax1.annotate(f"{r[1]:g} m, {r[2] // 1000}k", (r[5], 100 * r[4]), fontsize=6)
        sel = [r for r in ring if r[0] == kind]
        if sel:
            ax2.semilogx([r[4] for r in sel], [100 * r[2] for r in sel], styles[kind], label=kind)
            for r in sel:
                ax2.annotate(f"{r[1] // 1000}k tets", (r[4], 100 * r[2]), fontsize=6)
    ax1.set_xscale("log")
    ax1.set_yscale("symlog", linthresh=1.0)  # halfspace's error is 0: exact by construction
    ax1.set_xlabel("ms per analysis")
    ax1.set_ylabel("largest principal L1 error [%]")
    ax1.set_title("cube vs exact half-space")
    ax2.set_xlabel("ms per analysis")
    ax2.set_ylabel("largest principal L1 error [%]")
    ax2.set_title("ring landing vs fine FEM")
    ax1.legend(fontsize=8)
    return ctx.save_figure(fig, "stress_models.png")


def heat_map(ctx, pictures):
    """The ring's largest principal stress on its surface under the landing impact, one panel
    per model (each face coloured by its tet's value; one shared symmetric-log scale)."""
    plt = pyplot()
    from matplotlib import colors
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    pictures = dict(pictures)
    rotation = pictures.pop("rotation")
    fig = plt.figure(figsize=(12, 4))
    peaks = [p for _, p in pictures.values()]
    high = max(float(np.nanmax(np.abs(p))) for p in peaks)
    norm = colors.SymLogNorm(linthresh=high * 1e-3, vmin=-high, vmax=high)
    cmap = plt.get_cmap("coolwarm")
    for k, (kind, (model, peak)) in enumerate(pictures.items()):
        ax = fig.add_subplot(1, len(pictures), k + 1, projection="3d")
        world = model.vertices @ rotation.T  # as it lands, the contact at the bottom
        tri = world[model.surface_faces]
        values = peak[model.surface_face_tet]
        ax.add_collection3d(Poly3DCollection(tri, facecolors=cmap(norm(values)), edgecolor="none"))
        ax.view_init(elev=-15, azim=-60)
        lo, hi = world.min(axis=0), world.max(axis=0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo)
        ax.set_axis_off()
        ax.set_title(f"{kind}: peak {np.nanmax(peak) / 1e6:.0f} MPa", fontsize=9)
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=fig.axes, shrink=0.6,
                 label="largest principal stress [Pa]")
    return ctx.save_figure(fig, "stress_models_ring.png")
