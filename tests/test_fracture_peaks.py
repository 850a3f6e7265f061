"""Why a body did not break (``fracture/peaks.py``, ``taichi-frac run``'s "did not break"
lines and the stats file's ``unbroken``): a porcelain cube landing on a corner at 12 m/s,
on its collision spheres (``surface_contact`` off: struck on its true corner, the cube
breaks at 12 m/s, and at 7 m/s already).

The strength estimate is checked against the simulation itself: the same run with the
strength just under the reported peak breaks the cube, just over it does not and reports
the same peak. The speed estimate rests on the Hertz force growing as v^(6/5): two impact
speeds' forces are checked against that law."""

from __future__ import annotations

import json

import numpy as np
import pytest

from taichi_frac.cli import main
from taichi_frac.fracture.peaks import SPEED_EXPONENT, diagnose
from taichi_frac.options import FractureOptions, Material, ParticleOptions, SimulationOptions
from taichi_frac.scenes import Collider, Scene, SceneObject
from taichi_frac.simulation import Simulation

CUBE_SPEED = 12.0  # m/s, downwards


def cube_scene(strength: float = 35.0e6, speed: float = CUBE_SPEED) -> Scene:
    cube = SceneObject(
        name="cube", primitive="box:x=0.2,y=0.2,z=0.2",
        material=Material(name="porcelain", density=2400.0, young_modulus=70.0e9, poisson_ratio=0.2,
                          tensile_strength=strength, look="porcelain"),
        position=(0.0, 0.0, 0.3), euler_deg=(45.0, 35.0, 0.0), linear_velocity=(0.0, 0.0, -speed),
        particles=ParticleOptions(target_particles=400),
        fracture=FractureOptions(crack_count=3, crack_length=0.4),
    )
    return Scene(name="cube", objects=[cube], colliders=[Collider.ground(0.0)],
                 simulation=SimulationOptions(fps=24.0, duration=0.25, substeps=10, surface_contact=False))


def unbroken(scene, world):
    sim = Simulation(scene, output=False, world=world)
    summary = sim.run()
    names = [sim.records[b].name for b in sim.world.body_ids
             if sim.records[b].generation == 0 and sim.records[b].breakable]
    return summary, {e["name"]: e for e in diagnose(sim.fracture_stage.peaks, names, scene.simulation.frame_dt)}


def test_strength_estimate_is_the_strength_that_breaks_it(scene_world):
    summary, found = unbroken(cube_scene(), scene_world)
    assert summary.fragments == 0
    entry = found["cube"]
    peak = entry["peak_stress"]
    assert 0.0 < peak < 35.0e6
    assert entry["break_strength"] == peak
    assert entry["frame"] == 1 and 0.0 < entry["time"] <= 1.0 / 24.0
    # The landing corner: the most stressed point lies within two smoothing lengths of the
    # contact, and the contact on the ground plane.
    assert abs(entry["impact_point_world"][2]) < 0.01
    assert np.linalg.norm(np.subtract(entry["point_world"], entry["impact_point_world"])) < 0.12
    assert entry["break_speed"] == pytest.approx(entry["impact_speed"] * (35.0e6 / peak) ** SPEED_EXPONENT)
    assert entry["break_speed"] > entry["impact_speed"] > CUBE_SPEED
    # Just under the peak: the same impact cracks it; just over: it holds, with the same peak.
    weaker, found_weaker = unbroken(cube_scene(strength=0.97 * peak), scene_world)
    assert weaker.fragments >= 2 and "cube" not in found_weaker
    stronger, found_stronger = unbroken(cube_scene(strength=1.03 * peak), scene_world)
    assert stronger.fragments == 0
    assert found_stronger["cube"]["peak_stress"] == pytest.approx(peak, rel=1e-6)


def test_hertz_force_grows_as_speed_to_the_six_fifths(scene_world):
    """The speed estimate's premise (stress ∝ force, force ∝ v^(6/5)): the impact forces at
    two speeds follow the Hertz law within 1 %."""
    _, slow = unbroken(cube_scene(speed=6.0), scene_world)
    _, fast = unbroken(cube_scene(speed=9.0), scene_world)
    slow, fast = slow["cube"], fast["cube"]
    expected = (fast["impact_speed"] / slow["impact_speed"]) ** (1.0 / SPEED_EXPONENT)
    assert fast["impact_force"] / slow["impact_force"] == pytest.approx(expected, rel=0.01)


def test_run_prints_and_writes_why_it_did_not_break(tmp_path, scene_world, monkeypatch, capsys):
    import functools

    import taichi_frac.simulation as simulation

    monkeypatch.setattr(simulation, "Simulation", functools.partial(Simulation, world=scene_world))
    scene = tmp_path / "cube.toml"
    scene.write_text(
        'name = "cube"\n[simulation]\nfps = 24\nduration = 0.25\nsurface_contact = false\n[output]\npath = "cube.usdc"\n'
        '[[colliders]]\ntype = "ground"\n[[objects]]\nname = "cube"\nprimitive = "box:x=0.2,y=0.2,z=0.2"\n'
        'material = "porcelain"\nposition = [0.0, 0.0, 0.3]\neuler_deg = [45.0, 35.0, 0.0]\n'
        'linear_velocity = [0.0, 0.0, -12.0]\n[objects.particles]\ntarget_particles = 400\n')
    stats = tmp_path / "stats.json"
    assert main(["run", str(scene), "--no-output", "-q", "--stats-json", str(stats)]) == 0
    out = capsys.readouterr().out
    entry = json.loads(stats.read_text())["unbroken"][0]
    assert entry["name"] == "cube" and entry["strength"] == 35.0e6
    line = next(line for line in out.splitlines() if line.startswith("did not break: cube:"))
    assert f"{entry['peak_stress'] / 1e6:.3g} MPa < strength 35 MPa" in line
    assert f"breaks at about {entry['break_speed']:.3g} m/s" in line
