"""The add-on's bpy-free parts of simulating from Blender, in plain Python: the scene-file
writer read back by tomllib and by the scene loader, the command's progress lines, and where
the taichi-frac command is looked for (preferences, TAICHI_FRAC_EXECUTABLE, PATH)."""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "blender"))
from addon_loader import addon_module  # noqa: E402

scene_toml = addon_module("scene_toml")
runner = addon_module("runner")


def test_scene_file_reads_back_bit_for_bit(tmp_path):
    document = {
        "name": "shot \"1\"",
        "simulation": {"fps": 24.0, "duration": 0.5, "substeps": 10},
        "colliders": [{"type": "ground", "height": -0.1},
                      {"type": "box", "center": [0.1, 0.2, 0.3], "half_extents": [1e-6, 2.5, 3.0]}],
        "objects": [
            {"name": "Cube", "mesh": "meshes/Cube.obj", "material": scene_toml.Inline(preset="porcelain",
                                                                                       tensile_strength=1e7),
             "breakable": True, "position": [0.1 + 0.2, -6.776263337627997e-18, 1 / 3],
             "particles": {"target_particles": 400}, "fracture": {"crack_count": 3, "crack_length": 0.4}},
            {"name": "Ball", "mesh": "meshes/Ball.obj", "material": "concrete", "breakable": False,
             "particles": {"target_particles": 400}},
        ],
    }
    text = scene_toml.dumps(document, header="two\nlines")
    assert text.startswith("# two\n# lines\n")
    assert tomllib.loads(text) == document  # (floats written with repr: exact)
    with pytest.raises(ValueError, match="not finite"):
        scene_toml.dumps({"simulation": {"fps": float("nan")}})
    # The scene loader takes it as a scene (a primitive stands in for the meshes).
    from taichi_frac.scenes import load_scene

    for obj in document["objects"]:
        obj.pop("mesh")
        obj["primitive"] = "box:x=0.2,y=0.2,z=0.2"
    document["objects"][0]["position"][2] = 0.5
    path = tmp_path / "shot.toml"
    path.write_text(scene_toml.dumps(document))
    scene = load_scene(str(path))
    assert [o.name for o in scene.objects] == ["Cube", "Ball"]
    assert scene.objects[0].material.tensile_strength == 1e7 and scene.objects[0].fracture.crack_count == 3
    assert scene.colliders[1].half_extents == (1e-6, 2.5, 3.0)


def test_progress_lines():
    p = runner.parse_progress('{"frame": 3, "frames": 12, "time": 0.125, "fragments": 6, "fps": 1.5}\n')
    assert (p.frame, p.frames, p.time, p.fragments, p.fps) == (3, 12, 0.125, 6, 1.5)
    assert p.fraction == 0.25
    assert runner.parse_progress("[Taichi] Starting on arch=x64") is None
    assert runner.parse_progress('{"frame": "x"}') is None
    assert runner.parse_surfaces_wait('{"stage": "surfaces", "left": 2, "splits": 5}\n') == (2, 5)
    assert runner.parse_surfaces_wait('{"stage": "prepare", "objects": 3}') is None
    assert runner.parse_progress('{"stage": "surfaces", "left": 2, "splits": 5}') is None


def _command(folder: Path, name: str = "taichi-frac") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text("#!/bin/sh\nexit 0\n")
    path.chmod(0o755)
    return path


def test_executable_order_and_errors(tmp_path):
    preferred = _command(tmp_path / "pref")
    from_env = _command(tmp_path / "env")
    on_path = _command(tmp_path / "bin")
    env = {"PATH": str(on_path.parent), runner.EXECUTABLE_ENV: str(from_env)}
    assert runner.find_executable(str(preferred), env) == (str(preferred), "the add-on's preferences")
    assert runner.find_executable("", env) == (str(from_env), runner.EXECUTABLE_ENV)
    assert runner.find_executable("", {"PATH": env["PATH"]}) == (str(on_path), "PATH")
    with pytest.raises(runner.RunError) as missing:
        runner.find_executable(str(tmp_path / "nowhere" / "taichi-frac"), env)
    message = str(missing.value)
    assert "\n" not in message and "nowhere" in message and "preferences" in message
    with pytest.raises(runner.RunError) as none:
        runner.find_executable("", {"PATH": str(tmp_path / "empty")})
    assert runner.EXECUTABLE_ENV in str(none.value) and "\n" not in str(none.value)


def test_failed_run_gives_the_commands_one_line_error(tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text('name = "bad"\n[[objects]]\nname = "a"\nprimitive = "torus"\nfriction = -1.0\n')
    command = Path(__file__).resolve().parents[1] / ".venv" / "bin" / "taichi-frac"
    run = runner.SimulationRun(str(command), str(scene), str(tmp_path / "stats.json"))
    run.start()
    assert run.wait(timeout=300) == 2
    line = run.error_line()
    assert line.startswith("bad.toml:") and "friction" in line and "\n" not in line, line
    assert not (tmp_path / "stats.json").exists()


def test_the_run_reads_the_wait_for_the_last_surfaces(tmp_path):
    """A command that reports frames, then the wait for the last surfaces: the run's progress
    holds the splits left, and those lines are not taken for the command's messages."""
    command = tmp_path / "fake-taichi-frac"
    command.write_text("#!/bin/sh\n"
                       "echo '{\"stage\": \"prepare\", \"objects\": 1}' >&2\n"
                       "echo '{\"frame\": 4, \"frames\": 4, \"time\": 0.08, \"fragments\": 3, \"fps\": 9.0}' >&2\n"
                       "echo '{\"stage\": \"surfaces\", \"left\": 2, \"splits\": 2}' >&2\n"
                       "echo '{\"stage\": \"surfaces\", \"left\": 0, \"splits\": 2}' >&2\n")
    command.chmod(0o755)
    run = runner.SimulationRun(str(command), str(tmp_path / "scene.toml"))
    run.start()
    assert run.wait(timeout=60) == 0
    p = run.progress
    assert (p.frame, p.frames, p.fragments, p.surfaces_left, p.surfaces_splits) == (4, 4, 3, 0, 2)
    assert not any("surfaces" in line for line in run.stderr_lines)
