"""Runs INSIDE Blender (.venv-blender/bin/python): install the add-on zip and check what an
artist relies on, each against numbers known in advance (variants.py's closed-form motion,
the caches' layer data, hand-counted selections). Prints each failure and exits 1 if any.

    .venv-blender/bin/python tests/blender/check_features.py ADDON.zip SPEC.json

SPEC.json (written by tests/test_blender_addon_features.py) names the caches and describes
their pieces. Sections: re-import in place, retiming and frame range, collections and
lineage, the panel's selection and stress view, materials, error paths.
"""

from __future__ import annotations

import json
import math
import shutil
import sys
from pathlib import Path

import bpy
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import synthetic  # noqa: E402

failures: list[str] = []
TOL = 1e-5  # [m] float32 keys and matrices


def check(condition, message):
    if not condition:
        failures.append(message)
    return condition


def new_scene(name, fps=24):
    scene = bpy.data.scenes.new(name)
    scene.render.fps, scene.render.fps_base = fps, 1.0
    return scene


def run_import(scene, path, **options):
    """The operator on ``scene``; returns (result set, error text or None)."""
    with bpy.context.temp_override(scene=scene):
        try:
            return bpy.ops.import_scene.taichi_frac(filepath=str(path), **options), None
        except RuntimeError as exc:  # an ERROR report reaches a script as RuntimeError
            return {"CANCELLED"}, str(exc)


def fragments(scene):
    return {o.taichi_frac.prim_path.rsplit("/", 1)[-1]: o for o in scene.objects if o.taichi_frac.prim_path}


def pose_of(piece, t):
    position = np.asarray(piece["start"]) + np.asarray(piece["velocity"]) * t
    return synthetic.world_matrix(position, synthetic.axis_angle_quat((0, 0, 1), piece["spin"] * t))


def alive(piece, cache_frame):
    return piece["birth"] <= cache_frame and (piece["death"] is None or cache_frame < piece["death"])


def check_poses(label, scene, description, scene_frames, to_cache_time):
    """World matrix and visibility of every object at ``scene_frames`` against the closed form
    at the cache time ``to_cache_time(frame)`` [s]."""
    objects = fragments(scene)
    pieces = {p["name"]: p for p in description["pieces"]}
    checked = 0
    for frame in scene_frames:
        scene.frame_set(frame)
        t = to_cache_time(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for name, obj in objects.items():
            if obj.taichi_frac.stale or name not in pieces:
                continue
            # the cache frame whose state is held at time t (visibility changes on frames)
            cache_frame = math.floor(t * description["fps"] + 1e-9)
            visible = alive(pieces[name], cache_frame)
            check(obj.hide_render == (not visible), f"{label}/{name}: frame {frame} visible={not obj.hide_render}, "
                                                    f"expected {visible}")
            if not visible:
                continue
            actual = np.array(obj.evaluated_get(depsgraph).matrix_world, dtype=np.float64)
            error = np.abs(actual - pose_of(pieces[name], t)).max()
            check(error < TOL, f"{label}/{name}: frame {frame} matrix error {error:.3g}")
            checked += 1
    return checked


# ------------------------------------------------------------------------------ sections
def section_reimport(spec):
    """First import: collections per body, lineage pointers, skipped flash. Then the artist's
    edits, a re-simulated cache at the same path, re-import: edits kept, pieces replaced."""
    sim, v1, v2 = Path(spec["sim"]), Path(spec["v1"]), Path(spec["v2"])
    shutil.copy(v1, sim)
    scene = new_scene("reimport")
    result, error = run_import(scene, sim)
    check(result == {"FINISHED"}, f"import v1: {result} {error}")
    top = [c for c in scene.collection.children if c.get("taichi_frac_cache")]
    check(len(top) == 1 and top[0].name == "sim", f"top collections {[c.name for c in top]}")
    top = top[0]
    check(sorted(c.name for c in top.children) == ["plate", "slab"], f"body collections {[c.name for c in top.children]}")
    check(sorted(o.name for o in top.children["slab"].objects) == ["shard_a", "shard_b", "slab", "sliver_1", "sliver_2"],
          f"slab collection {[o.name for o in top.children['slab'].objects]}")
    objects = fragments(scene)
    check("flash" not in objects, "flash (born and broken in frame 30) was imported")
    check(set(objects) == {"slab", "shard_a", "shard_b", "sliver_1", "sliver_2", "plate"}, f"objects {sorted(objects)}")
    expected_generation = {"slab": 0, "plate": 0, "shard_a": 1, "shard_b": 1, "sliver_1": 2, "sliver_2": 2}
    for name, generation in expected_generation.items():
        check(objects[name].taichi_frac.generation == generation, f"{name}: generation {objects[name].taichi_frac.generation}")
    # lineage is a pointer: renaming the parent keeps it
    objects["slab"].name = "Base"
    check(objects["shard_a"].taichi_frac.parent is objects["slab"] and objects["shard_a"].taichi_frac.parent.name == "Base",
          f"shard_a parent {objects['shard_a'].taichi_frac.parent}")
    check(objects["sliver_1"].taichi_frac.parent is objects["shard_b"], "sliver_1 parent")
    check(objects["plate"].taichi_frac.parent is None, "plate has a parent")
    actions = [a for a in bpy.data.actions if "taichi_frac_cache" in a]
    check(len(actions) == 1 and len(actions[0].slots) == len(objects),
          f"one action with a slot per object: {[(a.name, len(a.slots)) for a in actions]}")
    slots = [o.animation_data.action_slot for o in objects.values()]
    check(all(s is not None for s in slots) and len({s.handle for s in slots}) == len(slots), "a slot per object")
    check_selection(scene)
    check_stress_view(scene)

    # The artist's edits.
    outer = bpy.data.materials["slab_outer"]
    outer.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.0, 1.0, 0.0, 1.0)
    hero = objects["shard_a"]
    hero.name = "Hero"
    hero.modifiers.new("Bevel", "BEVEL")
    artist = bpy.data.materials.new("ArtistGlass")
    objects["sliver_1"].data.materials[0] = artist
    hero_mesh = hero.data
    heroes = bpy.data.collections.new("Heroes")  # sliver_1 moved out of the import's collections
    scene.collection.children.link(heroes)
    sliver_1 = objects["sliver_1"]
    heroes.objects.link(sliver_1)
    top.children["slab"].objects.unlink(sliver_1)

    shutil.copy(v2, sim)  # the re-simulation overwrites the file
    result, error = run_import(scene, sim)
    check(result == {"FINISHED"}, f"re-import v2: {result} {error}")
    objects = fragments(scene)
    check(set(objects) == {"slab", "shard_a", "sliver_1", "shard_c", "plate"}, f"after v2: {sorted(objects)}")
    check(len([o for o in scene.objects if o.taichi_frac.prim_path]) == 5, "duplicated objects after re-import")
    check(len([c for c in scene.collection.children if c.get("taichi_frac_cache")]) == 1, "re-import made a new collection")
    check(objects["shard_a"] is hero and hero.name == "Hero" and hero.data is hero_mesh, "Hero not updated in place")
    check([m.type for m in hero.modifiers] == ["BEVEL"], f"Hero modifiers {[m.type for m in hero.modifiers]}")
    co = np.empty(len(hero.data.vertices) * 3, dtype=np.float32)
    hero.data.vertices.foreach_get("co", co)
    vertices, _ = synthetic.box_mesh(tuple(spec["v2_pieces"]["shard_a"]["half"]))
    check(np.abs(co - vertices.reshape(-1)).max() < 1e-6, "Hero's mesh not replaced by v2's")
    check(tuple(bpy.data.materials["slab_outer"].node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value)
          == (0.0, 1.0, 0.0, 1.0), "edited material overwritten")
    check(bpy.data.materials.get("slab_outer.001") is None, "materials duplicated")
    check(objects["sliver_1"].data.materials[0] == artist, "artist's material on sliver_1 lost")
    check(objects["sliver_1"] is sliver_1 and list(sliver_1.users_collection) == [heroes],
          f"moved sliver_1 not updated where it is: {[c.name for c in objects['sliver_1'].users_collection]}")
    check("shard_c" in [o.name for o in top.children["slab"].objects], "new piece not in its body's collection")
    check(objects["sliver_1"].taichi_frac.parent is hero, "sliver_1's parent in v2 is shard_a (Hero)")
    check(bpy.data.objects.get("shard_b") is None and bpy.data.objects.get("sliver_2") is None, "gone pieces not removed")
    actions = [a for a in bpy.data.actions if "taichi_frac_cache" in a]
    check(len(actions) == 1, f"actions after re-import {[a.name for a in actions]}")
    v2_desc = {"fps": spec["fps"], "pieces": list(spec["v2_pieces"].values())}
    n = check_poses("v2", scene, v2_desc, range(0, 41, 4), lambda f: f / spec["fps"])
    check(n > 20, f"only {n} v2 poses checked")

    # Back to v1, hiding what is gone.
    shutil.copy(v1, sim)
    result, error = run_import(scene, sim, missing="HIDE")
    check(result == {"FINISHED"}, f"re-import v1: {result} {error}")
    objects = fragments(scene)
    shard_c = objects.get("shard_c")
    check(shard_c is not None and shard_c.taichi_frac.stale and shard_c.hide_render and shard_c.hide_viewport,
          "shard_c not hidden as stale")
    check({"shard_b", "sliver_2"} <= set(objects), "v1's pieces not back")
    print("re-import: checked")


def check_selection(scene):
    """The panel's selection at frame 30 of v1: hand-counted sets."""
    scene.frame_set(30)
    with bpy.context.temp_override(scene=scene, view_layer=scene.view_layers[0]):
        def select(**kw):
            bpy.ops.taichi_frac.select_fragments(**kw)
            return sorted(o.taichi_frac.prim_path.rsplit("/", 1)[-1] for o in scene.objects if o.select_get())
        got = select(by="GENERATION", generation=2)
        check(got == ["sliver_1", "sliver_2"], f"generation 2 selects {got}")
        got = select(by="GENERATION", generation=1)  # shard_b broke at 24: hidden, not selectable
        check(got == ["shard_a"], f"generation 1 selects {got}")
        got = select(by="GENERATION", generation=0, extend=True)  # slab is gone by 30, plate stays
        check(got == ["plate", "shard_a"], f"generation 0 (extend) selects {got}")
        got = select(by="BIRTH", birth_min=20, birth_max=30)
        check(got == ["sliver_1", "sliver_2"], f"born 20-30 selects {got}")
    check(hasattr(bpy.types, "VIEW3D_PT_taichi_frac"), "sidebar panel not registered")
    sliver = fragments(scene)["sliver_1"]
    with bpy.context.temp_override(scene=scene, view_layer=scene.view_layers[0], active_object=sliver):
        texts = draw_panel()
    # variants.py: sliver_1 born at 24 from shard_b (broken at 24), impact force (0, 0, 1500) N,
    # peak stress 1 MPa; generation 2
    for expected in ("Generation 2", "Born at frame 24 (cache 24)", "Never breaks", "Peak stress 1 MPa",
                     "Impact force 1500 N"):
        check(expected in texts, f"panel lacks {expected!r}: {texts}")


class _Layout:
    """Stands in for a UILayout: records label texts, accepts anything else."""

    def __init__(self, texts):
        self.texts = texts

    def label(self, text="", **_):
        self.texts.append(text)

    def __getattr__(self, name):
        return lambda *args, **kw: _Layout(self.texts)

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)


def draw_panel():
    """The sidebar panel's draw with a recording layout; returns its labels."""
    texts = []

    class Panel:
        layout = _Layout(texts)

    bpy.types.VIEW3D_PT_taichi_frac.draw(Panel(), bpy.context)
    return texts


def check_stress_view(scene):
    objects = list(fragments(scene).values())
    with bpy.context.temp_override(scene=scene, view_layer=scene.view_layers[0], active_object=objects[0]):
        bpy.ops.taichi_frac.stress_view(show=True)
        heat = bpy.data.materials.get("taichi-frac stress")
        check(heat is not None, "no heat-map material")
        # variants.py: face stress 2e4 * face index, 12 faces -> the largest 2.2e5 Pa
        node = heat.node_tree.nodes["Normalise Stress"]
        check(abs(node.inputs["From Max"].default_value - 2.2e5) < 1.0, f"normalised by {node.inputs['From Max'].default_value}")
        attribute = next(n for n in heat.node_tree.nodes if n.type == "ATTRIBUTE")
        check(attribute.attribute_name == "peak_principal_stress" and attribute.attribute_type == "GEOMETRY",
              "heat map not driven by the face attribute")
        linked = {(link.from_node.type, link.to_node.type) for link in heat.node_tree.links}
        check({("ATTRIBUTE", "MAP_RANGE"), ("MAP_RANGE", "VALTORGB"), ("VALTORGB", "BSDF_PRINCIPLED")} <= linked,
              f"heat-map chain {linked}")
        for obj in objects:
            check(all(s.link == "OBJECT" and s.material == heat for s in obj.material_slots), f"{obj.name}: heat map not shown")
        before = {o.name: [m.name for m in o.data.materials] for o in objects}
        bpy.ops.taichi_frac.stress_view(show=False)
        for obj in objects:
            check(all(s.link == "DATA" for s in obj.material_slots), f"{obj.name}: links not restored")
            check([s.material.name for s in obj.material_slots] == before[obj.name], f"{obj.name}: materials not restored")


def section_retime(spec):
    """A 50 fps cache into a 24 fps scene, offset 10 frames, scene settings kept: keys at the
    right seconds; a piece alive only between two scene frames skipped."""
    scene = new_scene("retime", fps=24)
    scene.frame_start, scene.frame_end = 1, 77
    description = spec["retime_desc"]
    result, error = run_import(scene, spec["retime"], set_scene_settings=False, frame_offset=10.0)
    check(result == {"FINISHED"}, f"retime import: {result} {error}")
    check((scene.render.fps, scene.frame_start, scene.frame_end) == (24, 1, 77), "scene settings changed")
    objects = fragments(scene)
    check("blink" not in objects and {"mover", "late", "brief"} <= set(objects),
          f"retimed objects {sorted(objects)} (blink lives 22.48-22.96: never on a frame)")
    mover = objects["mover"]
    fcurves = {(fc.data_path, fc.array_index): fc for fc in
               mover.animation_data.action.layers[0].strips[0].channelbag(mover.animation_data.action_slot).fcurves}
    keys = np.array([tuple(k.co) for k in fcurves[("location", 0)].keyframe_points])
    cache_frames = np.arange(0, 101)
    check(len(keys) == len(cache_frames) and np.allclose(keys[:, 0], 10 + cache_frames * 24 / 50, atol=1e-4)
          and np.allclose(keys[:, 1], cache_frames / 50, atol=1e-6),
          f"mover keys: {keys[:3].tolist()} ... (expected frame 10 + c*0.48, x = c/50 s * 1 m/s)")
    n = check_poses("retime", scene, description, range(10, 59), lambda f: (f - 10) / 24)
    check(n > 80, f"only {n} retimed poses checked")
    check(abs(objects["brief"].taichi_frac.birth_frame - (10 + 27 * 0.48)) < 1e-5, f"brief birth {objects['brief'].taichi_frac.birth_frame}")

    # Frame range only (cache frames 20-60) with the cache's fps.
    scene = new_scene("range", fps=24)
    result, error = run_import(scene, spec["retime"], use_frame_range=True, frame_first=20, frame_last=60)
    check(result == {"FINISHED"}, f"range import: {result} {error}")
    check((scene.render.fps, scene.frame_start, scene.frame_end) == (50, 20, 60),
          f"range scene {scene.render.fps} {scene.frame_start}-{scene.frame_end}")
    mover = fragments(scene)["mover"]
    channelbag = mover.animation_data.action.layers[0].strips[0].channelbag(mover.animation_data.action_slot)
    frames = [k.co[0] for k in channelbag.fcurves.find("location", index=0).keyframe_points]
    check(frames[0] == 20 and frames[-1] == 60 and len(frames) == 41, f"range keys {frames[:2]}..{frames[-1:]}")
    n = check_poses("range", scene, description, range(20, 61, 5), lambda f: f / 50)
    check(n > 10, f"only {n} range poses checked")
    print("retime: checked")


def imported_bsdfs(spec, key):
    """Import spec[key] into a new scene; its materials' Principled BSDF inputs by prim name."""
    scene = new_scene(key)
    result, error = run_import(scene, spec[key])
    check(result == {"FINISHED"}, f"{key} import: {result} {error}")
    top = next(c for c in scene.collection.children if c.get("taichi_frac_cache"))
    return {prim.rsplit("/", 1)[-1]: m.node_tree.nodes["Principled BSDF"].inputs
            for prim, m in top["taichi_frac_materials"].items()}


def section_materials(spec):
    """UsdPreviewSurface -> Principled BSDF: glass (opacity with threshold 0), a cut-out
    (threshold > 0), and inputs left out."""
    probe = bpy.data.materials.new("probe")
    if probe.node_tree is None:  # (Blender < 5 makes the tree only when asked)
        probe.use_nodes = True
    default_ior = probe.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value
    made = imported_bsdfs(spec, "glass")
    glass = made["outer"]
    check(abs(glass["Transmission Weight"].default_value - 0.9) < 1e-6, f"transmission {glass['Transmission Weight'].default_value}")
    check(abs(glass["IOR"].default_value - 1.52) < 1e-6 and glass["Alpha"].default_value == 1.0, "glass IOR / alpha")
    check(abs(glass["Roughness"].default_value - 0.05) < 1e-6, "glass roughness")
    check(np.allclose(tuple(glass["Base Color"].default_value), (0.9, 0.95, 1.0, 1.0), atol=1e-6), "glass colour")
    cut = made["inner"]
    check(cut["Alpha"].default_value == 0.0 and cut["Transmission Weight"].default_value == 0.0,
          "cut-out below its threshold must be cut away (alpha 0), not transmissive")
    check(abs(cut["IOR"].default_value - default_ior) < 1e-6, "a cut-out's ior must not be applied")

    made = imported_bsdfs(spec, "subset")
    half = made["outer"]
    check(abs(half["Transmission Weight"].default_value - 0.5) < 1e-6 and abs(half["IOR"].default_value - default_ior) < 1e-6,
          "opacity 0.5 without ior: transmission 0.5, Blender's IOR")
    kept = made["inner"]
    check(kept["Alpha"].default_value == 1.0 and kept["Transmission Weight"].default_value == 0.0,
          "cut-out above its threshold: opaque")
    print("materials: checked")


def section_heat_render(spec):
    """The heat map rendered (Cycles, 1 sample, black world, no light: each pixel is the
    emission, 0.5 x the ramp's colour): the tile's top face is two triangles with face
    stress 2.0e5 and 2.2e5 Pa, shown red at 4.4e5, so their pixels are the ramp at 10/22 and
    11/22 (blue-green to yellow: distinct colours)."""
    scene = new_scene("heat")
    result, error = run_import(scene, spec["tile"])
    check(result == {"FINISHED"}, f"tile import: {result} {error}")
    tile = fragments(scene)["tile"]
    with bpy.context.temp_override(scene=scene, view_layer=scene.view_layers[0], active_object=tile):
        bpy.ops.taichi_frac.stress_view(show=True, stress_max=4.4e5)
    heat = tile.material_slots[0].material
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    camera.data.type, camera.data.ortho_scale = "ORTHO", 1.2
    camera.location = (0.0, 0.0, 5.0)  # looking down -z, +y up in the picture
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.world = bpy.data.worlds.new("black")
    scene.world.color = (0.0, 0.0, 0.0)
    for node in (scene.world.node_tree.nodes if scene.world.node_tree else ()):
        if node.type == "BACKGROUND":  # (a new world may come with a lit grey background)
            node.inputs["Strength"].default_value = 0.0
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.cycles.device = "CPU"
    scene.render.resolution_x = scene.render.resolution_y = 32
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(Path(spec["tile"]).with_name("heat.exr"))
    scene.frame_set(0)
    bpy.ops.render.render(write_still=True, scene=scene.name)
    image = bpy.data.images.load(scene.render.filepath)
    pixels = np.array(image.pixels[:], dtype=np.float64).reshape(32, 32, 4)  # rows from the bottom

    def pixel(x, y):  # world (x, y) on the top face -> the pixel there
        return pixels[int((y + 0.6) / 1.2 * 32), int((x + 0.6) / 1.2 * 32), :3]

    for (x, y), face in (((0.3, -0.3), 10), ((-0.3, 0.3), 11)):  # triangles (1,5,7) and (1,7,3)
        expected = 0.5 * np.array(_ramp(heat, 2e4 * face / 4.4e5))
        got = pixel(x, y)
        check(np.abs(got - expected).max() < 2e-3, f"heat-map pixel of face {face}: {got}, expected {expected}")
    check(np.abs(pixel(0.3, -0.3) - pixel(-0.3, 0.3)).max() > 0.05, "the two faces' colours do not differ")
    print("heat render: checked")


def _ramp(material, fraction):
    ramp = next(n for n in material.node_tree.nodes if n.type == "VALTORGB")
    return tuple(ramp.color_ramp.evaluate(fraction))[:3]


def section_errors(spec):
    """Each failure reaches the user as one line, never a traceback; an incomplete cache
    imports with a warning naming its last complete frame."""
    scene = new_scene("errors")
    for key, expected in (("missing", "no such file"), ("corrupt", "not a readable USD file"),
                          ("truncated", "not a readable USD file"), ("foreign", "not a taichi-frac cache"),
                          ("newer", "newer taichi-frac"), ("folder", "is a folder")):
        result, error = run_import(scene, spec[key])
        check(result == {"CANCELLED"} and error is not None and expected in error and "Traceback" not in error,
              f"{key}: {result} {error!r} (expected an error saying {expected!r})")
    check(not [o for o in scene.objects], "a failed import left objects")

    addon = next(m for n, m in sys.modules.items() if n.endswith("taichi_frac_blender"))  # (bl_ext.<repo>.)
    with bpy.context.temp_override(scene=scene):
        result = addon.run_import(bpy.context, spec["incomplete"])
    check(len(result.warnings) == 1 and "frames up to 20" in result.warnings[0] and "incomplete" in result.warnings[0],
          f"incomplete warning {result.warnings}")
    check(scene.frame_end == 20, f"incomplete cache's range ends at {scene.frame_end}")

    # Dropped on the viewport: a foreign USD file goes to Blender's own importer.
    drop = new_scene("drop")
    operator = bpy.types.IMPORT_SCENE_OT_taichi_frac
    reports = []

    class Dropped:  # what invoke reads of the operator when a file is dropped
        filepath = spec["foreign"]

        def report(self, kind, text):
            reports.append((kind, text))

        def execute(self, context):
            raise AssertionError("a foreign file reached the taichi-frac importer")

    with bpy.context.temp_override(scene=drop):
        result = operator.invoke(Dropped(), bpy.context, None)
    check(result == {"FINISHED"} and [o.name.split(".")[0] for o in drop.objects] == ["Cube"],
          f"foreign drop: {result}, objects {[o.name for o in drop.objects]}")
    check(any("Blender's USD importer" in text for _, text in reports), f"drop reports {reports}")

    class DroppedCorrupt(Dropped):  # unreadable: this importer says why, not Blender's
        filepath = spec["corrupt"]

        def execute(self, context):
            return {"OURS"}

    with bpy.context.temp_override(scene=drop):
        check(operator.invoke(DroppedCorrupt(), bpy.context, None) == {"OURS"}, "a corrupt drop left to Blender")
    print("errors: checked")


def main(argv):
    zip_path, spec_path = argv
    spec = json.loads(Path(spec_path).read_text())
    result = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
    check(result == {"FINISHED"}, f"extension install returned {result}")
    for section in (section_reimport, section_retime, section_materials, section_heat_render, section_errors):
        try:
            section(spec)
        except Exception as exc:  # one section's crash must not hide the others' results
            import traceback

            traceback.print_exc()
            failures.append(f"{section.__name__} raised {type(exc).__name__}: {exc}")
    for failure in failures:
        print("FAIL:", failure)
    print(f"{len(failures)} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
