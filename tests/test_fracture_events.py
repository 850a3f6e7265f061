"""The run's record of fracture events (``fracture.stage.impact_event``, ``RunSummary.events``,
``--stats-json``'s ``events``), against a free fall computed by hand: a block released at
rest strikes the ground at sqrt(2 g d) after falling d, with m g d of kinetic energy."""

from __future__ import annotations

import json

import numpy as np
import pytest

from taichi_frac.cli import main
from taichi_frac.options import FractureOptions, Material, ParticleOptions, SimulationOptions
from taichi_frac.scenes import Collider, Scene, SceneObject
from taichi_frac.simulation import Simulation

HALF = 0.05  # [m] half the block's height
FALL = 0.8  # [m] from its lowest face to the ground
G = 9.81


def block_scene() -> Scene:
    block = SceneObject(
        name="block", primitive=f"box:x=0.1,y=0.1,z={2 * HALF}",
        material=Material(name="weak", density=2400.0, young_modulus=70.0e9, poisson_ratio=0.2,
                          tensile_strength=1.0e6, look="porcelain"),
        position=(0.0, 0.0, FALL + HALF), particles=ParticleOptions(target_particles=500),
        fracture=FractureOptions(crack_count=2, crack_length=0.3),
    )
    return Scene(name="drop", objects=[block], colliders=[Collider.ground(0.0)],
                 simulation=SimulationOptions(fps=50.0, duration=0.5, substeps=10))


def test_a_free_fall_strikes_with_its_hand_computed_speed_and_energy(scene_world):
    sim = Simulation(block_scene(), output=False, world=scene_world)
    summary = sim.run()
    assert summary.fractures >= 1 and len(summary.events) == summary.fractures
    first = summary.events[0]
    mass = sim.records[min(sim.records)].root.mass
    v = np.sqrt(2.0 * G * FALL)
    # (the contact is made within the frame the fall ends in, or the substep before it)
    assert first["body"] == "block" and abs(first["frame"] - np.sqrt(2 * FALL / G) * 50.0) < 1.0
    assert first["speed"] == pytest.approx(v, rel=0.03)
    # The ground is static: the energy is the block's own 1/2 m v^2 (one touch: one pair).
    assert first["energy"] == pytest.approx(0.5 * mass * first["speed"] ** 2, rel=1e-6)
    assert first["energy"] == pytest.approx(mass * G * FALL, rel=0.06)
    assert first["force"] > mass * G and first["cracks"] + first["ring_cracks"] >= 1
    assert first["pieces"] >= 2


def test_the_stats_file_lists_the_events(tmp_path, scene_world, monkeypatch):
    scene_file = tmp_path / "drop.toml"
    scene_file.write_text(f"""
name = "drop"
[simulation]
duration = 0.5
[[colliders]]
type = "ground"
[[objects]]
name = "block"
primitive = "box:x=0.1,y=0.1,z={2 * HALF}"
material = {{ preset = "porcelain", tensile_strength = 1.0e6 }}
position = [0.0, 0.0, {FALL + HALF}]
particles = {{ target_particles = 500 }}
[objects.fracture]
crack_count = 2
crack_length = 0.3
""")
    stats = tmp_path / "stats.json"
    assert main(["run", str(scene_file), "--no-output", "-q", "--stats-json", str(stats)]) == 0
    data = json.loads(stats.read_text())
    assert data["fractures"] == len(data["events"]) >= 1
    assert set(data["events"][0]) == {"frame", "body", "speed", "energy", "force", "cracks", "ring_cracks", "pieces"}
