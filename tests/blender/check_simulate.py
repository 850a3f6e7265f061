"""Runs INSIDE Blender (.venv-blender/bin/python, bpy 5.0): install the add-on zip, author a
scene with ``Object.taichi_frac_sim`` / ``Scene.taichi_frac_sim`` and simulate it with the
real ``taichi-frac run`` (TAICHI_FRAC_EXECUTABLE names it). Prints each failure and exits 1
if there is any; writes what the caller checks further to REPORT.json.

    .venv-blender/bin/python tests/blender/check_simulate.py ADDON.zip SECTION WORKDIR

SECTION: ``simulate`` (a porcelain cube at 12 m/s onto the ground beside a rigid sphere,
simulated with wait=True, then again: updated in place), ``offline`` (no run: a missing
executable, velocity from animation), ``cancel`` (a long run stopped after its first frames).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
import tomllib
from pathlib import Path

import bpy
import numpy as np

failures: list[str] = []
report: dict = {}


def check(condition, message):
    if not condition:
        failures.append(message)
    return condition


def install(zip_path):
    result = bpy.ops.extensions.package_install_files(filepath=str(zip_path), repo="user_default",
                                                      enable_on_install=True)
    check(result == {"FINISHED"}, f"extension install returned {result}")
    check(hasattr(bpy.ops.taichi_frac, "simulate"), "operator taichi_frac.simulate not registered")


def addon():
    """The installed add-on's package (its modules are used for the cancel section)."""
    name = next(m for m in sys.modules if m.endswith(".taichi_frac_blender") and m.startswith("bl_ext."))
    return sys.modules[name]


def empty_scene(workdir: Path, fps=24, frames=12):
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = fps, 1.0
    scene.frame_start, scene.frame_end = 1, 1 + frames
    scene.taichi_frac_sim.cache_path = str(workdir / "cache" / "shot.usdc")
    scene.taichi_frac_sim.particles = 400
    scene.taichi_frac_sim.ground = True
    return scene


def cube_and_sphere(scene):
    bpy.ops.mesh.primitive_cube_add(size=0.2, location=(0.0, 0.0, 0.3),
                                    rotation=(math.radians(45.0), math.radians(35.0), 0.0))
    cube = bpy.context.active_object
    cube.name = "Cube"
    sim = cube.taichi_frac_sim
    sim.role = "BREAKABLE"
    sim.material = "porcelain"
    sim.crack_count = 3
    sim.crack_length = 0.4
    sim.linear_velocity = (0.0, 0.0, -12.0)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.1, location=(0.6, 0.0, 0.3), segments=16, ring_count=8)
    sphere = bpy.context.active_object
    sphere.name = "Sphere"
    sphere.taichi_frac_sim.role = "RIGID"
    sphere.taichi_frac_sim.material = "concrete"
    return cube, sphere


def statue(scene):
    """A porcelain block landing flat at about 2.9 m/s (a 0.4 m drop), which holds: its peak
    stress reaches about 28 MPa of porcelain's 35 (it breaks from about 3.8 m/s)."""
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-0.6, 0.0, 0.2))
    block = bpy.context.active_object
    block.name = "Statue"
    block.scale = (0.1, 0.1, 0.15)
    block.taichi_frac_sim.role = "BREAKABLE"
    block.taichi_frac_sim.linear_velocity = (0.0, 0.0, -2.5)
    return block


def cube_world_corners(cube):
    return np.array([tuple(cube.matrix_world @ v.co) for v in cube.data.vertices])


def pieces_of(scene, cache_path):
    return [o for o in scene.objects if o.taichi_frac.prim_path and os.path.samefile(o.taichi_frac.cache_path,
                                                                                    cache_path)]


def section_simulate(workdir: Path):
    scene = empty_scene(workdir)
    scene.taichi_frac_sim.particles = 2000
    cube, sphere = cube_and_sphere(scene)
    block = statue(scene)
    corners = cube_world_corners(cube)
    start = time.perf_counter()
    result = bpy.ops.taichi_frac.simulate(wait=True)
    report["first_run_seconds"] = time.perf_counter() - start
    check(result == {"FINISHED"}, f"simulate returned {result}")
    cache = scene.taichi_frac_sim.cache_path
    check(os.path.exists(cache), f"no cache at {cache}")
    pieces = pieces_of(scene, cache)
    broken = [o for o in pieces if o.taichi_frac.generation >= 1]
    check(len(broken) >= 2, f"{len(broken)} broken pieces came back (expected 2 or more)")
    check(cube.hide_viewport and cube.hide_render, "the authored cube is not hidden in viewport and renders")
    # The rigid sphere and the block that held are in the cache too (moving): hidden as well.
    check(sphere.hide_viewport and sphere.hide_render, "the authored rigid sphere shows beside its cache copy")
    check(cube.taichi_frac_sim.result_state == "BROKE", f"cube result {cube.taichi_frac_sim.result_state}")
    # The block that held: the panel's numbers, from the run's stats file.
    held = block.taichi_frac_sim
    check(held.result_state == "UNBROKEN", f"statue result {held.result_state}")
    check(block.hide_viewport and block.hide_render, "the authored statue shows beside its cache copy")
    check(0.0 < held.result_peak_stress < held.result_strength == 35.0e6,
          f"statue peak {held.result_peak_stress} strength {held.result_strength}")
    check(held.result_frame >= scene.frame_start, f"statue peak frame {held.result_frame}")
    check(held.result_break_speed > held.result_impact_speed > 2.5,
          f"statue speeds {held.result_impact_speed} -> {held.result_break_speed}")
    check(abs(held.result_point[2]) < 0.12 and "MPa" in held.result_note, f"statue point {tuple(held.result_point)}")
    stats = json.loads(Path(os.path.splitext(scene.taichi_frac_sim.cache_path)[0] + ".stats.json").read_text())
    entry = next(e for e in stats["unbroken"] if e["name"] == "Statue")
    check(abs(entry["peak_stress"] - held.result_peak_stress) <= 1e-6 * entry["peak_stress"],
          "the panel's peak differs from the stats file's")
    report["statue"] = entry
    # The cube's cache body at the start frame is where the authored cube was: its mesh's
    # world corners match the authored corners (the export placed the centre of mass).
    root = [o for o in pieces if o.taichi_frac.generation == 0 and o.taichi_frac.prim_path.split("/")[-1]
            .lower().startswith("cube")]
    if check(len(root) == 1, f"cube's generation-0 object: {[o.name for o in root]}"):
        scene.frame_set(scene.frame_start)
        got = np.array([tuple(root[0].matrix_world @ v.co) for v in root[0].data.vertices])
        far = max(np.min(np.linalg.norm(got - c, axis=1)) for c in corners)
        check(far < 1e-4, f"the simulated cube's corners lie up to {far:.2e} m from the authored cube's")
    # Pieces show at the end (keyed visibility), the sphere's cache object too.
    scene.frame_set(scene.frame_end)
    visible = [o for o in broken if not o.hide_render]
    check(len(visible) >= 2, f"{len(visible)} pieces visible in renders at the end frame")
    report["pieces"] = sorted(o.taichi_frac.prim_path for o in broken)
    report["scene_path"] = os.path.splitext(cache)[0] + ".toml"
    report["cache"] = cache
    # Simulating again updates in place and keeps the artist's edits: a renamed piece keeps
    # its name and object, a new count of objects is not made.
    renamed = broken[0]
    renamed.name = "my piece"
    count = len(pieces)
    result = bpy.ops.taichi_frac.simulate(wait=True)
    check(result == {"FINISHED"}, f"second simulate returned {result}")
    again = pieces_of(scene, cache)
    check(len(again) == count, f"simulating again gave {len(again)} objects, first {count}")
    check(any(o.name == "my piece" for o in again), "the renamed piece lost its name or its object")
    check(cube.hide_viewport and cube.hide_render, "the cube shows again after the second run")
    report["second_pieces"] = sorted(o.taichi_frac.prim_path for o in again if o.taichi_frac.generation >= 1)


def simulate_error(case: str) -> str:
    """The error Blender reports for ``simulate(wait=True)`` in ``case``, where it must fail."""
    try:
        bpy.ops.taichi_frac.simulate(wait=True)
    except RuntimeError as exc:
        return str(exc).strip()
    check(False, f"simulate with {case} did not fail")
    return ""


def section_offline(workdir: Path):
    scene = empty_scene(workdir)
    cube, _ = cube_and_sphere(scene)
    command = os.environ["TAICHI_FRAC_EXECUTABLE"]
    # A run that fails: the command's own one-line error, in Blender's report.
    scene.taichi_frac_sim.ground_height = 1.0  # (above the cube: the scene loader refuses it)
    message = report["failed_run_message"] = simulate_error("a cube below the ground")
    check("below the ground" in message and "Cube" in message and len(message.splitlines()) == 1,
          f"failed-run message: {message!r}")
    scene.taichi_frac_sim.ground_height = 0.0
    check_export(workdir, scene, cube)
    check_panel(cube)
    # A missing executable: one line, naming where to set it.
    os.environ["TAICHI_FRAC_EXECUTABLE"] = str(workdir / "no-such-taichi-frac")
    message = report["missing_message"] = simulate_error("a missing executable")
    check("no-such-taichi-frac" in message and "\n" not in message.split("Error: ", 1)[-1],
          f"missing-executable message: {message!r}")
    os.environ.pop("TAICHI_FRAC_EXECUTABLE")
    path = os.environ.get("PATH", "")
    os.environ["PATH"] = str(workdir)  # (no taichi-frac there)
    message = report["not_found_message"] = simulate_error("taichi-frac not on the PATH")
    check("TAICHI_FRAC_EXECUTABLE" in message, f"not-found message: {message}")
    os.environ["PATH"] = path
    os.environ["TAICHI_FRAC_EXECUTABLE"] = command
    check(not cube.hide_viewport, "a failed run hid the cube")
    # Velocity from animation: linear keys, the slope is the keys' difference over their time.
    fps = 24.0
    obj = cube
    sim = obj.taichi_frac_sim
    sim.velocity_source = "ANIMATION"
    obj.rotation_euler = (0.0, 0.0, 0.0)
    obj.location = (0.0, 0.0, 1.0)
    obj.keyframe_insert("location", frame=1)
    obj.keyframe_insert("rotation_euler", frame=1)
    obj.location = (1.0, 0.5, 0.6)
    obj.rotation_euler = (0.0, 0.0, math.radians(90.0))
    obj.keyframe_insert("location", frame=11)
    obj.keyframe_insert("rotation_euler", frame=11)
    for curve in _fcurves(obj):
        for key in curve.keyframe_points:
            key.interpolation = "LINEAR"
    scene.frame_set(1)
    addon().export.export_scene(bpy.context)
    entry = next(o for o in exported_scene(scene)["objects"] if o["name"] == "Cube")
    seconds = 10.0 / fps
    expected = np.array([1.0, 0.5, -0.4]) / seconds
    spin = np.array([0.0, 0.0, math.radians(90.0) / seconds])
    report["animated_velocity"] = entry["linear_velocity"]
    report["animated_spin"] = entry["angular_velocity"]
    check(np.allclose(entry["linear_velocity"], expected, rtol=1e-3, atol=1e-3),
          f"velocity from animation {entry['linear_velocity']}, keys' slope {expected.tolist()}")
    check(np.allclose(entry["angular_velocity"], spin, rtol=1e-3, atol=1e-3),
          f"spin from animation {entry['angular_velocity']}, keys' slope {spin.tolist()}")
    check(np.allclose(entry["position"], [0.0, 0.0, 1.0], atol=1e-6), f"position at the start {entry['position']}")


class Layout:
    """Stands in for a panel's UILayout (Blender without a window draws no UI): records the
    labels and checks that every property drawn exists on its data."""

    def __init__(self, lines):
        self.lines, self.enabled = lines, True

    def prop(self, data, name, **_):
        check(name in data.bl_rna.properties, f"the panel draws a missing property {name!r}")

    def label(self, text="", **_):
        self.lines.append(text)

    def operator(self, idname, **_):
        self.lines.append(f"[{idname}]")
        return type("Op", (), {})()

    def box(self):
        return Layout(self.lines)

    row = column = lambda self, **_: Layout(self.lines)


def draw_panel(obj) -> list[str]:
    lines = []
    panel = bpy.types.VIEW3D_PT_taichi_frac_simulation
    bpy.context.view_layer.objects.active = obj
    panel.draw(type("Panel", (), {"layout": Layout(lines)})(), bpy.context)
    return lines


def check_panel(cube):
    sim = cube.taichi_frac_sim
    for role in ("NONE", "BREAKABLE", "RIGID", "STATIC"):
        sim.role = role
        for velocity in ("MANUAL", "ANIMATION"):
            sim.velocity_source = velocity
            for material in ("porcelain", "custom"):
                sim.material = material
                lines = draw_panel(cube)
                check("[taichi_frac.simulate]" in lines, f"no Simulate button for role {role}")
    sim.role, sim.material, sim.velocity_source = "STATIC", "porcelain", "MANUAL"
    check(any("bounding box" in line for line in draw_panel(cube)), "the panel does not say how static objects collide")
    sim.role = "BREAKABLE"
    sim.result_state, sim.result_peak_stress, sim.result_strength = "UNBROKEN", 7.66e6, 35.0e6
    sim.result_frame, sim.result_impact_speed, sim.result_break_speed = 11.0, 4.33, 15.4
    lines = draw_panel(cube)
    check("Peak stress 7.66 MPa of strength 35 MPa" in lines and any("15.4 m/s" in line for line in lines),
          f"the panel's diagnosis: {lines[-6:]}")
    sim.result_state = "NONE"


def exported_scene(scene) -> dict:
    return tomllib.loads(Path(os.path.splitext(scene.taichi_frac_sim.cache_path)[0] + ".toml").read_text())


def check_export(workdir: Path, scene, cube):
    """What the scene file says of a static box, a custom material, an automatic crack count,
    a modifier and the unit scale, each against numbers worked out by hand."""
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(1.0, 2.0, 0.05), rotation=(0.0, 0.0, math.radians(30.0)))
    wall = bpy.context.active_object
    wall.name = "Wall"
    wall.scale = (0.5, 1.0, 0.1)
    wall.taichi_frac_sim.role = "STATIC"
    sim = cube.taichi_frac_sim
    sim.material, sim.density, sim.young_modulus, sim.poisson_ratio, sim.tensile_strength = (
        "custom", 2000.0, 5.0e9, 0.25, 3.0e6)
    sim.crack_count_auto = True
    cube.modifiers.new("bevel", "BEVEL").segments = 2
    cube.scale = (-1.0, 1.0, 1.0)  # (mirrored: the export turns its faces back outwards)
    scene.unit_settings.system, scene.unit_settings.scale_length = "METRIC", 0.01  # (1 unit = 1 cm)
    scene.frame_current = 7
    addon().export.export_scene(bpy.context)
    check(scene.frame_current == 7, f"the export left the scene at frame {scene.frame_current}")
    exported = exported_scene(scene)
    box = next(c for c in exported["colliders"] if c["type"] == "box")
    half = math.radians(30.0) / 2
    check(np.allclose(box["center"], [0.01, 0.02, 0.0005], atol=1e-9), f"static box centre {box['center']}")
    check(np.allclose(box["half_extents"], [0.005, 0.01, 0.001], atol=1e-9), f"static box half {box['half_extents']}")
    check(np.allclose(box["orientation"], [math.cos(half), 0.0, 0.0, math.sin(half)], atol=1e-6),
          f"static box orientation {box['orientation']}")
    entry = next(o for o in exported["objects"] if o["name"] == "Cube")
    check(entry["material"] == {"density": 2000.0, "young_modulus": 5.0e9, "poisson_ratio": 0.25,
                                "tensile_strength": 3.0e6, "fracture_toughness": 1.0e6, "look": "porcelain"},
          f"custom material {entry['material']}")
    check("crack_count" not in entry["fracture"], "auto crack count wrote a count")
    check("crack_fit_rounds" not in entry["fracture"], "a full run's scene sets crack_fit_rounds")
    scene.taichi_frac_sim.draft = True
    addon().export.export_scene(bpy.context)
    entry = next(o for o in exported_scene(scene)["objects"] if o["name"] == "Cube")
    check(entry["fracture"].get("crack_fit_rounds") == 0, f"a draft's fracture table {entry['fracture']}")
    scene.taichi_frac_sim.draft = False
    check(np.allclose(entry["position"], [0.0, 0.0, 0.003], atol=1e-9), f"centimetre position {entry['position']}")
    check(np.allclose(entry["linear_velocity"], [0.0, 0.0, -0.12], atol=1e-9), f"velocity {entry['linear_velocity']}")
    vertices = np.array([[float(v) for v in line.split()[1:]] for line in
                         (Path(scene.taichi_frac_sim.cache_path).parent
                          / entry["mesh"]).read_text().splitlines() if line.startswith("v ")])
    check(len(vertices) > 8, f"the bevel modifier was not applied ({len(vertices)} vertices)")
    # The bevelled cube's extent along its own axes is still the 0.2-unit cube's: 2 mm.
    local = (vertices - entry["position"]) @ np.array(cube.matrix_world.to_3x3())
    check(np.allclose(np.ptp(local, axis=0), 0.002, rtol=1e-4), f"exported extents {np.ptp(local, axis=0)}")
    bpy.data.objects.remove(wall)
    cube.modifiers.clear()
    cube.scale = (1.0, 1.0, 1.0)
    sim.material, sim.crack_count_auto = "porcelain", False
    scene.unit_settings.system, scene.unit_settings.scale_length = "METRIC", 1.0


def _fcurves(obj):
    action = obj.animation_data.action
    if hasattr(action, "fcurves") and len(action.fcurves):  # (legacy actions)
        return list(action.fcurves)
    slot = obj.animation_data.action_slot
    return [c for layer in action.layers for strip in layer.strips for c in strip.channelbag(slot).fcurves]


def section_cancel(workdir: Path):
    scene = empty_scene(workdir, frames=2400)
    cube_and_sphere(scene)
    module = addon()
    job = module.simulate.Job(bpy.context)
    job.start(bpy.context)
    deadline = time.monotonic() + 240.0
    while job.run.progress.frame < 3 and job.run.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    job.run.cancel()  # what Esc does in the modal operator
    code = job.run.wait(timeout=120)
    report["cancel_exit"] = code
    report["cancel_frame"] = job.run.progress.frame
    check(code == 130, f"the cancelled run exited with {code}: {job.run.error_line()}")
    level, message = job.finish(bpy.context)
    report["cancel_message"] = message
    check(level in ("INFO", "WARNING"), f"finish after cancel: {level} {message}")
    from pxr import Usd  # (the add-on made Blender's USD importable)

    stage = Usd.Stage.Open(job.exported.cache_path)
    data = stage.GetRootLayer().customLayerData.get("taichiFrac", {})
    report["cancel_layer"] = {k: (v if isinstance(v, (int, float, str, bool)) else str(v)) for k, v in data.items()}
    pieces = pieces_of(scene, job.exported.cache_path)
    check(len(pieces) >= 2, f"{len(pieces)} objects imported from the cancelled run's cache")
    # Stopped at once, before a first frame: the last run's cache is not taken for its result.
    early = module.simulate.Job(bpy.context)
    early.start(bpy.context)
    early.run.cancel()
    early.run.wait(timeout=120)
    level, message = early.finish(bpy.context)
    report["early_cancel"] = [level, message]
    check(level == "WARNING" and "before its first frame" in message, f"cancelled at once: {level} {message}")


def main():
    zip_path, section, workdir = sys.argv[-3:]
    workdir = Path(workdir)
    install(zip_path)
    {"simulate": section_simulate, "offline": section_offline, "cancel": section_cancel}[section](workdir)
    (workdir / "REPORT.json").write_text(json.dumps(report, indent=2))
    for failure in failures:
        print("FAIL:", failure)
    print(f"{len(failures)} failures")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
