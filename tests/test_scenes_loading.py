"""Scene files and the Python API: the shipped scenes, one-to-one mapping onto the option
dataclasses, and errors that name the file, the key and the allowed range."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from taichi_frac.options import FractureOptions, MATERIAL_PRESETS, OptionError, ParticleOptions, SimulationOptions
from taichi_frac.scenes import Collider, Scene, SceneObject, apply_overrides, euler_deg_to_quaternion, load_scene
from taichi_frac.scenes import BUILTIN_SCENE_DIR as SCENES
from taichi_frac.scenes import builtin_scenes, find_scene


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("TAICHI_FRAC_CACHE", str(tmp_path / "cache"))


def _write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


MINIMAL = """
name = "drop"
[[objects]]
name = "ring"
primitive = "torus"
"""


def test_single_ring_scene_matches_the_paper():
    scene = load_scene(SCENES / "single_ring.toml")
    (ring,) = scene.objects
    assert ring.primitive == "torus:major=0.1,minor=0.025" and ring.breakable
    # Porcelain, with the effective strength the scene documents (see its header comment).
    assert ring.material == dataclasses.replace(MATERIAL_PRESETS["porcelain"], tensile_strength=40.0e6)
    assert ring.position[2] == pytest.approx(1.0)
    assert ring.particles.target_particles == 5000
    assert scene.colliders[0].type == "ground" and scene.colliders[0].height == 0.0
    assert scene.output_path == Path.cwd() / "single_ring.usdc"  # a built-in scene writes here, not in the package
    model, report = ring.prepare()
    assert abs(report.physics_particles / 5044 - 1) < 0.1  # Table 1: 5,044


def test_thirteen_rings_about_70000_particles_with_different_controls():
    scene = load_scene(SCENES / "thirteen_rings.toml")
    assert len(scene.objects) == 13
    controls = {(o.fracture.crack_count, o.fracture.seed, o.fracture.crack_length) for o in scene.objects}
    assert len(controls) == 13
    assert len({o.fracture.crack_count for o in scene.objects}) >= 4
    total = sum(o.prepare()[1].physics_particles for o in scene.objects)  # meshed once: same shape
    assert abs(total / 70_000 - 1) < 0.05, total
    # No two rings start interpenetrating, whatever their tilt: bounding spheres (radius
    # R + r = 0.125 m about the centre) are disjoint.
    p = np.array([o.position for o in scene.objects])
    d = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(13)
    assert d.min() > 2 * 0.125
    assert (p[:, 2] > 0.125).all()  # and above the ground


def test_glass_walls_about_20000_particles_and_a_fast_projectile():
    scene = load_scene(SCENES / "glass_walls.toml")
    walls = scene.breakable_objects
    assert len(walls) == 3 and all(w.material.name == "soda_lime_glass" for w in walls)
    (ball,) = [o for o in scene.objects if not o.breakable]
    assert np.linalg.norm(ball.linear_velocity) >= 20.0
    assert ball.material.density == 7850.0
    total = sum(w.prepare()[1].physics_particles for w in walls)
    assert abs(total / 20_000 - 1) < 0.1, total
    # Walls stand on the ground: bottom face at z >= 0 (box height 0.5 m).
    assert all(w.position[2] - 0.25 >= 0 for w in walls)


def test_overrides_set_values_and_none_restores_the_default():
    """--set KEY=VALUE parses VALUE as TOML; ``none`` removes the key (the option's default)."""
    base = load_scene(SCENES / "thirteen_rings.toml")
    assert base.objects[0].fracture.crack_length == 0.25
    scene = load_scene(SCENES / "thirteen_rings.toml", ["ring00.fracture.crack_length=none",
                                                        "ring01.fracture.crack_count=4",
                                                        "ring02.material.tensile_strength=4e6"])
    assert scene.objects[0].fracture.crack_length is None is FractureOptions().crack_length
    assert scene.objects[1].fracture.crack_count == 4
    assert scene.objects[2].material.tensile_strength == 4.0e6
    assert scene.objects[3] == base.objects[3]
    with pytest.raises(OptionError, match="no entry named 'ring99'"):
        load_scene(SCENES / "thirteen_rings.toml", ["objects.ring99.fracture.crack_count=2"])


def test_a_star_in_an_override_sets_every_object_or_collider():
    """``objects.*.KEY`` (or ``*.KEY``) sets KEY in every object, ``colliders.*.KEY`` in every
    collider; a later override of one object wins; a star over no entries is refused."""
    base = load_scene(SCENES / "thirteen_rings.toml")
    scene = load_scene(SCENES / "thirteen_rings.toml", ["objects.*.fracture.crack_fit_rounds=0",
                                                        "ring05.fracture.crack_fit_rounds=2",
                                                        "*.friction=0.25", "colliders.*.friction=0.4"])
    assert [o.fracture.crack_fit_rounds for o in scene.objects] == [0] * 5 + [2] + [0] * 7
    assert {o.friction for o in scene.objects} == {0.25} and [c.friction for c in scene.colliders] == [0.4]
    assert [o.fracture.crack_count for o in scene.objects] == [o.fracture.crack_count for o in base.objects]
    with pytest.raises(OptionError, match="colliders has no entries for"):
        apply_overrides({"objects": [{"name": "ring"}], "colliders": []}, ["colliders.*.friction=1"])
    with pytest.raises(OptionError, match="names a list"):
        load_scene(SCENES / "thirteen_rings.toml", ["objects.*=1"])


def test_toml_and_python_api_give_the_same_scene(tmp_path):
    path = _write(tmp_path, """
name = "same"
[simulation]
fps = 60
duration = 1.5
[output]
path = "same.usdc"
[[colliders]]
type = "ground"
height = -0.1
[[colliders]]
type = "box"
center = [1.0, 0.0, 0.5]
half_extents = [0.1, 1.0, 0.5]
euler_deg = [0.0, 0.0, 30.0]
[[objects]]
name = "ring"
primitive = "torus:major=0.1,minor=0.025"
material = { preset = "porcelain", tensile_strength = 20.0e6 }
position = [0.0, 0.0, 1.0]
orientation = [0.0, 1.0, 0.0, 0.0]
linear_velocity = [1.0, 0.0, 0.0]
friction = 0.4
restitution = 0.3
[objects.particles]
target_particles = 3000
boundary_group_size = 3
keep_leftovers = false
[objects.fracture]
crack_count = 3
crack_length = 0.05
""")
    from taichi_frac.options import Material
    from taichi_frac.scenes import OutputSettings

    porcelain = MATERIAL_PRESETS["porcelain"]
    expected = Scene(
        name="same",
        objects=[SceneObject(
            name="ring", primitive="torus:major=0.1,minor=0.025",
            material=Material(name=porcelain.name, density=porcelain.density, young_modulus=porcelain.young_modulus,
                              poisson_ratio=porcelain.poisson_ratio, tensile_strength=20.0e6,
                              fracture_toughness=porcelain.fracture_toughness, look=porcelain.look),
            position=(0, 0, 1.0), orientation=(0, 1, 0, 0), linear_velocity=(1, 0, 0), friction=0.4, restitution=0.3,
            particles=ParticleOptions(target_particles=3000, boundary_group_size=3, keep_leftovers=False),
            fracture=FractureOptions(crack_count=3, crack_length=0.05))],
        colliders=[Collider.ground(-0.1), Collider.box((1, 0, 0.5), (0.1, 1, 0.5), euler_deg=(0, 0, 30))],
        simulation=SimulationOptions(fps=60, duration=1.5),
        output=OutputSettings(path="same.usdc"),
    )
    loaded = load_scene(path)
    assert loaded.objects == expected.objects
    assert loaded.colliders == expected.colliders
    assert loaded.simulation == expected.simulation and loaded.output == expected.output


def test_euler_degrees_match_an_independent_rotation():
    for angles in [(90, 0, 0), (10, 20, 30), (-45, 60, 170)]:
        w, x, y, z = euler_deg_to_quaternion(angles)
        reference = Rotation.from_euler("xyz", angles, degrees=True).as_quat()  # extrinsic, (x,y,z,w)
        q = np.array([x, y, z, w])
        assert min(np.abs(q - reference).max(), np.abs(q + reference).max()) < 1e-12


def test_quaternion_is_normalised():
    obj = SceneObject(name="a", primitive="sphere", orientation=(2.0, 0.0, 0.0, 0.0))
    assert obj.orientation == (1.0, 0.0, 0.0, 0.0)


def test_mesh_paths_resolve_against_the_scene_folder(tmp_path):
    import trimesh

    (tmp_path / "meshes").mkdir()
    trimesh.creation.box((0.1, 0.1, 0.1)).export(str(tmp_path / "meshes" / "brick.obj"))
    path = _write(tmp_path, '[[objects]]\nname = "b"\nmesh = "meshes/brick.obj"\nunits = "m"\n')
    scene = load_scene(path)
    assert Path(scene.objects[0].mesh) == tmp_path / "meshes" / "brick.obj"


# --- errors name the file, the key and what is allowed -------------------------------------

@pytest.mark.parametrize("text,message", [
    (MINIMAL + "colour = 'red'\n",
     r"scene.toml: objects\[0\]: unknown key 'colour'; allowed keys: name, mesh, primitive"),
    (MINIMAL + "[objects.particles]\ntarget_particle = 5000\n",
     r"scene.toml: objects\[0\].particles: unknown key 'target_particle'; allowed keys: target_particles"),
    (MINIMAL + "[objects.fracture]\ncrack_count = 'three'\n",
     r"scene.toml: objects\[0\].fracture: fracture.crack_count = 'three': use a number of cracks \(1-64\) or 'auto'"),
    (MINIMAL + "[objects.particles]\ntarget_particles = 0\n",
     r"scene.toml: objects\[0\].particles: particles.target_particles = 0 is out of range: allowed \[1, 5e\+06\]"),
    (MINIMAL + "[objects.fracture]\ncrack_count = 100\n",
     r"fracture.crack_count = 100 is out of range: allowed \[1, 64\]"),
    (MINIMAL + "restitution = 1.5\n",
     r"scene.toml: objects\[0\]: objects\['ring'\].restitution = 1.5 is out of range: allowed \[0, 1\]"),
    (MINIMAL + "position = [0, 1]\n",
     r"objects\[0\].position = \[0, 1\] has the wrong type: expected list\[float, float, float\]"),
    (MINIMAL + "material = 'granite'\n",
     r"objects\[0\].material = 'granite': unknown preset; use one of concrete, porcelain, soda_lime_glass"),
    (MINIMAL + "material = { density = -5.0 }\n",
     r"objects\[0\].material: material.density = -5.0 is out of range: allowed \(0, inf\]"),
    (MINIMAL + "breakable = 'yes'\n", r"objects\[0\].breakable = 'yes' has the wrong type: expected bool"),
    (MINIMAL + "mesh = 'teapot.obj'\n", r"objects\[0\].mesh = 'teapot.obj': file not found"),
    (MINIMAL + "euler_deg = [0, 0, 0]\norientation = [1, 0, 0, 0]\n",
     r"give orientation \(quaternion w,x,y,z\) or euler_deg, not both"),
    (MINIMAL + "[simulation]\nfps = 0\n", r"scene.toml: simulation: simulation.fps = 0 is out of range: allowed \[1, 10000\]"),
    (MINIMAL + "[simulation]\nsubstep = 4\n", r"scene.toml: simulation: unknown key 'substep'; allowed keys: fps"),
    (MINIMAL + "[output]\npath = 'out.abc'\n", r"output.path = 'out.abc': must be a .usdc, .usda or .usd file"),
    (MINIMAL + "[[colliders]]\ntype = 'plane'\n", r"collider type = 'plane': use one of ground, box"),
    (MINIMAL + "[[colliders]]\ntype = 'box'\nhalf_extents = [1, 0, 1]\n",
     r"colliders\['box'\].half_extents = 0.0 is out of range: allowed \(0, inf\]"),
    ("[[objects]]\nname = 'a'\n", r"objects\['a'\]: give exactly one of mesh = \"file\" or primitive"),
    ("gravity = 9.81\n" + MINIMAL, r"scene.toml: unknown top-level key 'gravity'; allowed: name, objects"),
    ("name = 'nothing'\n", r"scene 'nothing' has no objects"),
    (MINIMAL + "[[objects]]\nname = 'ring'\nprimitive = 'sphere'\n", r"object names must be unique, repeated: ring"),
    ("[[objects]\n", r"scene.toml: not valid TOML"),
])
def test_bad_scene_errors_name_file_key_and_range(tmp_path, text, message):
    with pytest.raises(OptionError, match=message):
        load_scene(_write(tmp_path, text))


def test_missing_scene_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_scene(tmp_path / "nope.toml")


# --- built-in scenes: by name from any folder --------------------------------------------------

def test_built_in_scenes_load_by_name_from_any_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert builtin_scenes() == ["glass_walls", "single_ring", "thirteen_rings"]
    for name in builtin_scenes():
        assert find_scene(name) == SCENES / f"{name}.toml" == find_scene(f"{name}.toml")
        # the cache goes into the working folder, never into the installed package
        assert load_scene(name).output_path == tmp_path / f"{name}.usdc"
    assert load_scene("single_ring", ["output.path=drops/a.usdc"]).output_path == tmp_path / "drops" / "a.usdc"
    assert load_scene("single_ring", ["output.path=none"]).output_path == tmp_path / "single_ring.usdc"
    assert load_scene("single_ring").objects == load_scene(SCENES / "single_ring.toml").objects


def test_a_scene_file_wins_over_a_built_in_name_and_keeps_its_own_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "single_ring.toml").write_text(MINIMAL)
    scene = load_scene("single_ring.toml")
    assert scene.name == "drop" and scene.output_path == tmp_path / "drop.usdc"
    copy = tmp_path / "mine" / "ring.toml"
    copy.parent.mkdir()
    copy.write_text((SCENES / "single_ring.toml").read_text())
    assert load_scene(copy).output_path == copy.parent / "single_ring.usdc"


def test_an_unknown_scene_name_lists_the_built_in_scenes(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError, match="'single_rings' does not exist.*glass_walls, single_ring, thirteen_rings"):
        load_scene("single_rings")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_scene("elsewhere/single_ring.toml")  # a folder: a path, never a built-in name
