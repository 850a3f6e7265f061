"""Seeded fuzzing of scene loading: mutated scene structures, mutated scene-file bytes and
hostile ``--set`` overrides. Every case must either load into a scene whose numbers the
simulation can hold (finite, within float32, unit quaternions, positive sizes) or raise
the package's OptionError: any other exception (OverflowError, TypeError,
UnicodeDecodeError, ...) is a crash the user would see as a traceback. No simulation runs:
loading and validation only (a few hundred cases in about a second)."""

from __future__ import annotations

import copy
import math
import random
import tomllib

import pytest

from taichi_frac.options import FLOAT32_MAX, OptionError
from taichi_frac.scenes import Scene, apply_overrides, load_scene, scene_from_dict
from taichi_frac.scenes import BUILTIN_SCENE_DIR as SCENES

SEED = 20261201

NASTY_VALUES = [
    10**400, -(10**400), 2**63, -1, 0, 1, 3, 0.0, -0.0, 1e-300, 1e-12, 1e308, -1e308, 1e39, 3.5e38,
    float("nan"), float("inf"), float("-inf"), True, False, "", "²", "\x00", "torus:major=1e308",
    "box:x=1e-12,y=1,z=1", "sphere:radius=nan", "torus:major=0.1,minor=0.2", "porcelain", "ground", "box",
    "é" * 3, [], [1], [1, 2], [1e200, 1e200, 0, 0], [0, 0, 0, 0], [0, 1e39, 0], [0, -9.2e18, 0], [[1]],
    ["a", "b", "c"], [float("nan")] * 3, {}, {"a": 1}, {"preset": 5}, {"preset": "porcelain", "density": -1},
]

# --set values as typed on a command line (parsed as TOML, else taken as text).
NASTY_TEXTS = [
    "nan", "inf", "-inf", "1e400", str(10**400), "-1", "0", "1e-300", "[1e200,1e200,0,0]", "[0,1e39,0]",
    "{a=1}", "none", "None", "true", "'x'", '"\\u00ff"', "[", "]]", "torus:major=1e308", "box:x=1e-12,y=1,z=1",
    "[1,2]", "[[1]]", "1e308", "-1e308", "\"\"", "=", "0x10", "1_000", "2024-01-01",
    # and values that are fine, so that some cases load
    "0.5", "2", "[0, 0, 2]", "\"concrete\"", "0.3", "100", "[1, 0, 0, 0]",
]
NASTY_KEYS = [
    "objects.².friction", ".", "..", "objects.99.friction", "ring..friction", "ring", "simulation", "output",
    "colliders.0", "objects", "name", "name.x", "ring.material.preset", "ring.material", "ring.fracture",
    "ring.particles.target_particles", "ring.orientation", "ring.euler_deg", "ring.position",
    "ring.primitive", "ring.mesh", "ring.units", "ring.scale", "simulation.fps", "simulation.duration",
    "simulation.gravity", "simulation.arch", "output.path", "output.checkpoint_every", "colliders.0.height",
    "colliders.0.type", "colliders.0.half_extents", "nothing.here", "objects.ring.fracture.seed",
]


def _scene_dicts() -> list[tuple[str, dict]]:
    """The project's scenes, parsed; the 13 rings cut to their first three objects (the
    rest repeat them, and would make every case thirteen times the work)."""
    scenes = []
    for p in sorted(SCENES.glob("*.toml")):
        data = tomllib.loads(p.read_text())
        data["objects"] = data.get("objects", [])[:3]
        scenes.append((p.name, data))
    return scenes


def _paths(node, prefix=()):
    """Every (path, value) in a parsed scene; a path is a tuple of keys and list indices."""
    yield prefix, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


def _set(data, path, value):
    node = data
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value


def _delete(data, path):
    node = data
    for part in path[:-1]:
        node = node[part]
    del node[path[-1]]


def _mutate(rng: random.Random, data: dict) -> dict:
    data = copy.deepcopy(data)
    for _ in range(rng.randint(1, 3)):
        paths = [p for p, _ in _paths(data) if p]
        path = rng.choice(paths)
        action = rng.random()
        if action < 0.7:
            _set(data, path, copy.deepcopy(rng.choice(NASTY_VALUES)))
        elif action < 0.85:
            _delete(data, path)
        else:
            parent = path[:-1]
            node = data
            for part in parent:
                node = node[part]
            if isinstance(node, dict):
                node[rng.choice(["bogus", "objectz", "Density", "seed"])] = rng.choice(NASTY_VALUES)
    return data


def _check_representable(scene: Scene) -> None:
    """What a loaded scene promises the simulation: finite float32 numbers, unit
    quaternions, at least one frame."""
    sim = scene.simulation
    assert sim.frame_count >= 1
    for obj in scene.objects:
        q = obj.orientation
        assert abs(math.sqrt(sum(c * c for c in q)) - 1.0) < 1e-9, q
        for vec in (obj.position, obj.linear_velocity, obj.angular_velocity):
            assert all(math.isfinite(v) and abs(v) <= FLOAT32_MAX for v in vec), vec
        for value in (obj.scale, obj.friction, obj.restitution, obj.material.density, obj.material.young_modulus,
                      obj.material.tensile_strength):
            assert math.isfinite(value) and abs(value) <= FLOAT32_MAX, value
    for collider in scene.colliders:
        assert all(math.isfinite(v) for v in (*collider.center, *collider.half_extents, collider.height))
        assert abs(math.sqrt(sum(c * c for c in collider.orientation)) - 1.0) < 1e-9


def _accepts_only_option_errors(load, case) -> str:
    try:
        scene = load()
    except OptionError:
        return "refused"
    except Exception as exc:  # the failure this test exists to find
        pytest.fail(f"{type(exc).__name__}: {exc} for case {case!r}")
    _check_representable(scene)
    return "loaded"


def test_mutated_scene_structures_load_or_raise_option_errors(tmp_path):
    rng = random.Random(SEED)
    outcomes = {"refused": 0, "loaded": 0}
    scenes = _scene_dicts()
    for k in range(240):
        name, base = rng.choice(scenes)
        data = _mutate(rng, base)
        outcome = _accepts_only_option_errors(
            lambda: scene_from_dict(data, where=name, base_dir=tmp_path, source_path=tmp_path / name), (k, data))
        outcomes[outcome] += 1
    # The mutator must exercise both sides: values refused and values that still load.
    assert outcomes["refused"] > 100 and outcomes["loaded"] > 10, outcomes


def test_mutated_scene_file_bytes_load_or_raise_option_errors(tmp_path):
    rng = random.Random(SEED + 1)
    sources = [p.read_bytes() for p in sorted(SCENES.glob("*.toml"))]
    outcomes = {"refused": 0, "loaded": 0}
    for k in range(120):
        raw = bytearray(rng.choice(sources))
        for _ in range(rng.randint(1, 4)):
            at = rng.randrange(len(raw))
            kind = rng.random()
            if kind < 0.4:
                raw[at] = rng.randrange(256)  # any byte, including ones that are not UTF-8
            elif kind < 0.7:
                del raw[at: at + rng.randint(1, 40)]
            else:
                raw[at:at] = rng.choice([b"9" * 400, b"nan", b"inf", b"\xff\xfe", b"]]", b"=", b"\n[objects]\n",
                                         b"\n[[objects]]\nname = 1\n", b"e39", b"-"])
        path = tmp_path / f"case{k}.toml"
        path.write_bytes(bytes(raw))
        outcomes[_accepts_only_option_errors(lambda: load_scene(path), (k, bytes(raw[:200])))] += 1
    assert outcomes["refused"] > 30 and outcomes["loaded"] > 5, outcomes


def test_hostile_overrides_load_or_raise_option_errors():
    rng = random.Random(SEED + 2)
    outcomes = {"refused": 0, "loaded": 0}
    scene = SCENES / "single_ring.toml"
    for k in range(200):
        overrides = [f"{rng.choice(NASTY_KEYS)}={rng.choice(NASTY_TEXTS)}" for _ in range(rng.randint(1, 3))]
        if rng.random() < 0.1:
            overrides.append(rng.choice(["novalue", "=", "==", "ring.fracture.crack_count"]))
        outcomes[_accepts_only_option_errors(lambda: load_scene(scene, overrides), overrides)] += 1
    assert outcomes["refused"] > 100 and outcomes["loaded"] > 0, outcomes


def test_overrides_on_mutated_scenes_raise_only_option_errors(tmp_path):
    """Overrides applied to mutated structures (an object named by a list, a table that is
    a number, ...)."""
    rng = random.Random(SEED + 3)
    scenes = _scene_dicts()
    for k in range(80):
        name, base = rng.choice(scenes)
        data = _mutate(rng, base)
        overrides = [f"{rng.choice(NASTY_KEYS)}={rng.choice(NASTY_TEXTS)}" for _ in range(rng.randint(1, 2))]
        _accepts_only_option_errors(
            lambda: scene_from_dict(apply_overrides(data, overrides, where=name), where=name, base_dir=tmp_path),
            (k, overrides, data))


def test_overrides_on_scenes_without_the_table_or_with_wrong_shapes(tmp_path):
    """Repros: --set on a scene with no [simulation] table sets it; ``objects = 5`` with an
    override and an index written with a superscript digit are OptionErrors."""
    bare = {"objects": [{"name": "ring", "primitive": "torus", "position": [0, 0, 1]}]}
    data = apply_overrides(bare, ["simulation.duration=0.5", "output.path=\"x.usda\""], where="bare.toml")
    scene = scene_from_dict(data, where="bare.toml")
    assert scene.simulation.duration == 0.5 and scene.output.path == "x.usda"
    with pytest.raises(OptionError, match="objects must be an array"):
        scene_from_dict(apply_overrides({"objects": 5}, ["simulation.fps=3"]), where="five.toml")
    with pytest.raises(OptionError, match="no entry named '²'"):
        apply_overrides(bare, ["objects.².friction=1"])
    with pytest.raises(OptionError, match="the scene has no colliders"):
        apply_overrides(bare, ["colliders.0.friction=1"])
    listed = {"objects": [{"name": [1], "primitive": "torus"}]}
    with pytest.raises(OptionError, match="name"):
        scene_from_dict(apply_overrides(listed, ["simulation.fps=30"]), where="listed.toml")
