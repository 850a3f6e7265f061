"""The paper's scenes, short versions, end to end (dynamics + fracture + USD cache).

Each asserts physical invariants against independent references:
- mass: the live bodies' exact tet masses plus any dropped mass equal the scene's initial
  mass (independent sum over the input objects' tets);
- no NaN in any body state at any frame;
- nothing deeper than one physics particle radius into the ground at any frame: a body's
  true surface where it collides through it (``simulation.surface_contact``, the default;
  its collision spheres then stand proud of that surface by design), else its spheres;
- the fragment count lies in the range the scene files document.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from taichi_frac.geometry.mass import tet_mass_properties
from taichi_frac.io.cache import check_cache
from taichi_frac.kinematics.quaternion import quaternion_matrix
from taichi_frac.scenes import load_scene
from taichi_frac.scenes import BUILTIN_SCENE_DIR as SCENES
from taichi_frac.simulation import Simulation



@pytest.fixture(scope="module")
def world(scene_world):
    """One World for every scene here (the session's, conftest.py): its kernels compile once."""
    return scene_world


def run_checked(scene, world, frames, output=False):
    """Run ``frames`` frames, checking NaN and ground penetration after every frame (of the
    bodies' surfaces with surface contacts, else of their collision spheres)."""
    worst = {"penetration_ratio": 0.0}
    sim = Simulation(scene, output=output, frames=frames, world=world)
    ground = [c.height for c in scene.colliders if c.type == "ground"]
    surface = scene.simulation.surface_contact

    def check(frame, total, t, fragments, fps):
        state = sim.world.body_state()
        for key in ("position", "orientation", "linear_velocity", "angular_velocity"):
            assert np.all(np.isfinite(state[key])), f"NaN in {key} at frame {frame}"
        if not ground:
            return
        for body in sim.world.body_ids:
            if surface:
                pose = sim.world.body_state([body])
                lowest = np.min(sim.records[body].model.vertices @ quaternion_matrix(pose["orientation"][0])[2])
                depth = ground[0] - (pose["position"][0][2] + lowest)
            else:
                p = sim.world.particle_state(body)
                depth = np.max(ground[0] - (p["position"][:, 2] - p["radius"]))
            allowed = float(sim.records[body].model.particle_radius.mean())
            if depth / allowed > worst["penetration_ratio"]:
                rec = sim.records[body]
                worst.update(penetration_ratio=depth / allowed, frame=frame, body=rec.name,
                             born=rec.birth_frame, generation=rec.generation)

    sim.progress = check
    summary = sim.run()
    return sim, summary, worst


def initial_mass(scene) -> float:
    """Independent reference: the exact tet mass of every input object, meshed afresh."""
    total = 0.0
    for obj in scene.objects:
        model, _ = obj.prepare()
        total += tet_mass_properties(model.vertices, model.tets, obj.material.density).mass
    return total


def assert_invariants(scene, summary, worst):
    ref = initial_mass(scene)
    assert abs(summary.mass_final + summary.mass_dropped - ref) <= 1e-9 * ref
    assert worst["penetration_ratio"] < 1.0, worst


def ring_scene(crack_count: int):
    return load_scene(SCENES / "single_ring.toml", [f"ring.fracture.crack_count={crack_count}"])


def test_single_ring_controls_give_the_documented_fragment_counts(world, tmp_path):
    """scenes/single_ring.toml documents about 2, 5 and 10 fragments for crack_count 1, 3, 5."""
    counts = {}
    for n, (low, high) in ((1, (2, 3)), (3, (4, 7)), (5, (8, 14))):
        out = tmp_path / f"ring{n}.usdc" if n == 1 else False
        sim, summary, worst = run_checked(ring_scene(n), world, frames=40, output=out)
        assert_invariants(sim.scene, summary, worst)
        assert summary.fractures >= 1
        assert low <= summary.fragments <= high, (n, summary.fragments)
        counts[n] = summary.fragments
    assert counts[1] <= counts[3] <= counts[5]
    # The cache of a real run passes USD's validators and holds every body ever made.
    assert check_cache(tmp_path / "ring1.usdc") == []


def test_glass_walls_break_and_pieces_break_again(world):
    """The ball breaks the walls one after another: the substeps in which a wall breaks
    are simulated again with its pieces (resimulate_fractures), so the ball goes on
    through wall 0 (starting at 25 m/s), and every wall breaks, some pieces again."""
    scene = load_scene(SCENES / "glass_walls.toml")
    assert scene.simulation.resimulate_fractures
    sim, summary, worst = run_checked(scene, world, frames=40)  # wall 2 breaks at frame ~33
    assert_invariants(scene, summary, worst)
    assert summary.fractures >= 3 and summary.resimulated_substeps >= 1
    assert summary.fragments >= 30
    live = sim.world.body_ids
    roots = {sim.records[b].name.split("_")[0] for b in live if sim.records[b].generation > 0}
    assert roots == {"wall0", "wall1", "wall2"}
    assert max(sim.records[b].generation for b in live) >= 2
    ball = next(b for b in live if sim.records[b].name == "ball")
    wall0 = next(o for o in scene.objects if o.name == "wall0")
    # Through wall 0 (0.03 m thick), not bounced back off it: 5 cm past its far face.
    assert sim.world.body_state([ball])["position"][0][0] > wall0.position[0] + 0.015 + 0.05


@pytest.mark.slow
def test_thirteen_rings_fall_and_break(world):
    """60 frames: the rings land and break, their pieces pile up. (At frame 53 a 2.6 kg ring
    piece strikes a 17 g chip that, without integrate.hold_above_ground, ended 1.28
    physics-particle radii in the floor.)"""
    scene = load_scene(SCENES / "thirteen_rings.toml")
    sim, summary, worst = run_checked(scene, world, frames=60)
    assert_invariants(scene, summary, worst)
    assert summary.physics_particles > 60_000
    assert summary.fragments >= 13


def test_scene_without_breakable_bodies_never_enters_fracture(world):
    """A scene pays only for what it uses: no breakable body, no fracture analysis at all."""
    scene = ring_scene(1)
    obj = dataclasses.replace(scene.objects[0], breakable=False)
    scene = dataclasses.replace(scene, objects=[obj])
    sim, summary, worst = run_checked(scene, world, frames=30)
    assert summary.fractures == 0 and summary.fragments == 0
    assert summary.stage_seconds["fracture_analysis"] == 0.0
    assert_invariants(scene, summary, worst)


def test_strongest_impact_per_body_pair_matches_a_plain_loop():
    from taichi_frac.fracture.stage import strongest_per_pair

    rng = np.random.default_rng(0)
    k = 300
    impacts = dict(body=rng.integers(0, 6, k), other=rng.integers(-2, 6, k), force=rng.normal(size=(k, 3)))
    breakable = np.array([0, 2, 3, 5])
    result = strongest_per_pair(impacts, breakable)
    force = np.linalg.norm(impacts["force"], axis=1)
    for b in breakable:
        best = {}
        for r in np.nonzero(impacts["body"] == b)[0]:
            o = int(impacts["other"][r])
            if o not in best or force[r] > force[best[o]]:
                best[o] = r
        assert np.array_equal(result[int(b)], np.sort(list(best.values())))
    assert set(result) == {int(b) for b in breakable if np.any(impacts["body"] == b)}


def test_the_whole_stress_field_is_computed_only_for_the_cache(world, tmp_path, monkeypatch):
    """A scene pays only for what it uses: the pieces' peak stress (the cache's per-face
    stress) needs the whole field of a cracking impact's analysis; without a cache that
    analysis is skipped, and the run is otherwise the same (same fragments, same poses)."""
    import taichi_frac.fracture.stage as stage

    calls = []
    real = stage.analyze_impact

    def counting(*args, **kwargs):
        calls.append(kwargs.get("full_field", True))
        return real(*args, **kwargs)

    monkeypatch.setattr(stage, "analyze_impact", counting)  # (the fracture stage's analyses)
    runs = {}
    for label, output in (("cache", tmp_path / "ring.usdc"), ("none", False)):
        calls.clear()
        sim = Simulation(ring_scene(3), output=output, frames=30, world=world)
        summary = sim.run()
        ids = sim.world.body_ids
        runs[label] = (summary.fragments, sim.world.body_state(ids)["position"], calls.count(True))
        assert bool(sim.render_cuts) == (label == "cache")  # (a repeated split's cut may be a memo's: 0 s)
    assert runs["cache"][0] == runs["none"][0] >= 3
    np.testing.assert_array_equal(runs["cache"][1], runs["none"][1])
    assert runs["cache"][2] >= 1 and runs["none"][2] == 0


def test_the_crack_fit_options_reach_the_cut(world, tmp_path, monkeypatch):
    """The scene's crack-fit settings are the ones each split's render cut is made with."""
    import taichi_frac.surfaces.cut as piece_surface

    seen = []
    real = piece_surface.cut_render_solid

    def recording(*args, **kwargs):
        seen.append((kwargs["fit_rounds"], kwargs["fit_min_tets"]))
        return real(*args, **kwargs)

    monkeypatch.setattr(piece_surface, "cut_render_solid", recording)
    scene = load_scene(SCENES / "single_ring.toml", ["ring.fracture.crack_count=3", "ring.fracture.crack_fit_rounds=2",
                                                     "ring.fracture.crack_fit_min_tets=30"])
    summary = Simulation(scene, output=tmp_path / "ring.usdc", frames=30, world=world, surface_workers=0).run()
    assert seen and set(seen) == {(2, 30)}
    # (the cut's time is reported as the part of the split stage it is)
    assert 0.0 < summary.stage_seconds["render_surfaces"] <= summary.stage_seconds["fragment_split"]
