"""Runs INSIDE Blender (.venv-blender/bin/python, bpy 5.0): install the add-on zip as an
extension, import synthetic caches through its operator and compare every object with the
closed-form motion of synthetic.py. Prints each failure and exits 1 if there is any.

    .venv-blender/bin/python tests/blender/check_import.py ADDON.zip CACHE.usdc [CACHE2 ...]

Run with BLENDER_USER_RESOURCES pointing at a scratch folder (the extension is installed
there, not in the user's Blender).
"""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import synthetic  # noqa: E402

MATRIX_TOL = 1e-5     # [m] and rotation-matrix entries; float32 keys and matrices: ~1e-7 x 3 m
VERTEX_TOL = 1e-5     # [m]
failures: list[str] = []


def check(condition, message):
    if not condition:
        failures.append(message)


def install(zip_path):
    result = bpy.ops.extensions.package_install_files(
        filepath=str(zip_path), repo="user_default", enable_on_install=True
    )
    check(result == {"FINISHED"}, f"extension install returned {result}")
    check(hasattr(bpy.ops.import_scene, "taichi_frac"), "operator import_scene.taichi_frac not registered")
    check(hasattr(bpy.types, "IMPORT_SCENE_FH_taichi_frac"), "FileHandler (drag and drop) not registered")
    draw_funcs = bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize()
    check(any(getattr(f, "__name__", "") == "menu_func_import" for f in draw_funcs), "no File > Import entry")


def import_cache(path):
    before = set(bpy.data.collections)
    result = bpy.ops.import_scene.taichi_frac(filepath=str(path))
    check(result == {"FINISHED"}, f"{path}: import returned {result}")
    new = [c for c in bpy.data.collections if c not in before and c.get("taichi_frac_cache")]
    check(len(new) == 1, f"{path}: expected one new cache collection, got {len(new)}")
    return new[0]


def check_cache(path):
    label = Path(path).name
    collection = import_cache(path)
    scene = bpy.context.scene
    check(scene.frame_start == synthetic.START_FRAME, f"{label}: frame_start {scene.frame_start}")
    check(scene.frame_end == synthetic.END_FRAME, f"{label}: frame_end {scene.frame_end}")
    fps = scene.render.fps / scene.render.fps_base
    check(abs(fps - synthetic.FPS) < 1e-9, f"{label}: fps {fps}")

    objects = {}
    for obj in collection.all_objects:
        objects[obj.taichi_frac.prim_path.rsplit("/", 1)[-1]] = obj
    check(sorted(objects) == sorted(synthetic.FRAGMENTS), f"{label}: objects {sorted(objects)}")

    for name, obj in objects.items():
        birth, death, parent, half = synthetic.FRAGMENTS[name]
        vertices, faces = synthetic.box_mesh(half)
        mesh = obj.data
        co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        check(co.shape == vertices.reshape(-1).shape and np.abs(co - vertices.reshape(-1)).max() < VERTEX_TOL,
              f"{label}/{name}: body-frame vertices differ")
        check(len(mesh.polygons) == len(faces), f"{label}/{name}: {len(mesh.polygons)} faces")
        for i, polygon in enumerate(mesh.polygons):
            material = mesh.materials[polygon.material_index]
            expected = "inner" if i in synthetic.INNER_FACES[name] else "outer"
            check(material["taichi_frac_prim"].endswith("/" + expected),
                  f"{label}/{name}: face {i} has material {material.name}, expected {expected}")
        # No input normals: every corner carries its face's flat normal (custom normals are
        # stored compressed in Blender: ~1e-4).
        corner = np.array([tuple(n.vector) for n in mesh.corner_normals]).reshape(-1, 3, 3)
        tri = vertices[faces]
        flat = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        flat /= np.linalg.norm(flat, axis=1, keepdims=True)
        check(np.abs(corner - flat[:, None, :]).max() < 1e-3, f"{label}/{name}: corner normals not flat")
        stress = np.empty(len(mesh.polygons), dtype=np.float32)
        mesh.attributes["peak_principal_stress"].data.foreach_get("value", stress)
        expected_stress = synthetic.face_stress(name, len(faces))
        check(np.allclose(stress, expected_stress, rtol=1e-6), f"{label}/{name}: face stress {stress}")
        props = obj.taichi_frac
        check(props.cache_birth_frame == birth and props.birth_frame == birth, f"{label}/{name}: birth {props.birth_frame}")
        check(props.cache_death_frame == props.death_frame == (-1 if death is None else death), f"{label}/{name}: death")
        check(abs(props.peak_stress - synthetic.peak_stress(name)) < 1e-6 * synthetic.peak_stress(name),
              f"{label}/{name}: peak stress {props.peak_stress}")
        check(props.parent == (None if parent is None else objects[parent]), f"{label}/{name}: parent {props.parent}")
        check(props.has_impact == (parent is not None), f"{label}/{name}: has_impact")
        if parent is not None:
            # (float32 properties: 1e-7 relative)
            check(np.allclose(list(props.impact_force), synthetic.IMPACT["force"], rtol=1e-6, atol=1e-6),
                  f"{label}/{name}: impact force {list(props.impact_force)}")
            check(np.allclose(list(props.impact_point), synthetic.IMPACT["point"], atol=1e-7),
                  f"{label}/{name}: impact point {list(props.impact_point)}")

    checked_matrices = 0
    for frame in range(synthetic.START_FRAME, synthetic.END_FRAME + 1):
        for subframe in (0.0, 0.5):
            if subframe and frame == synthetic.END_FRAME:
                continue
            scene.frame_set(frame, subframe=subframe)
            depsgraph = bpy.context.evaluated_depsgraph_get()
            for name, obj in objects.items():
                visible = synthetic.alive(name, frame)
                if subframe == 0.0:
                    check(obj.hide_viewport == (not visible) and obj.hide_render == (not visible),
                          f"{label}/{name}: frame {frame} hide_viewport={obj.hide_viewport} "
                          f"hide_render={obj.hide_render}, expected visible={visible}")
                    check(obj.visible_get() == visible, f"{label}/{name}: frame {frame} visible_get() != {visible}")
                    check(obj.evaluated_get(depsgraph).hide_render == (not visible),
                          f"{label}/{name}: frame {frame} evaluated hide_render")
                if not visible:
                    continue  # a hidden object is not evaluated: its matrix is not meaningful
                if subframe == 0.0:
                    expected = synthetic.world_matrix(*synthetic.pose(name, frame))
                elif synthetic.alive(name, frame + 1):
                    # Half-way between two samples: USD interpolates translate linearly and orient
                    # by slerp; Blender's per-component lerp normalised gives the same midpoint.
                    (p0, q0), (p1, q1) = synthetic.pose(name, frame), synthetic.pose(name, frame + 1)
                    q1 = q1 if np.dot(q0, q1) >= 0 else -q1
                    q = (q0 + q1) / np.linalg.norm(q0 + q1)
                    expected = synthetic.world_matrix((p0 + p1) / 2, q)
                else:
                    continue
                actual = np.array(obj.evaluated_get(depsgraph).matrix_world, dtype=np.float64)
                error = np.abs(actual - expected).max()
                check(error < MATRIX_TOL, f"{label}/{name}: frame {frame + subframe} matrix error {error:.3g}")
                checked_matrices += 1
    print(f"{label}: {len(objects)} objects, {checked_matrices} world matrices checked")


def main(argv):
    zip_path, caches = argv[0], argv[1:]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    install(zip_path)
    for cache in caches:
        check_cache(cache)
    for failure in failures:
        print("FAIL:", failure)
    print(f"{len(failures)} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
