"""The automatic crack count and its energy balance (``fracture/energy.py``) against values
computed by hand: n = (E / E_1)^(1/4) with E_1 = G_c d sqrt(V / (pi d)), G_c = K_Ic^2 / E, and
cracks that spend exactly the impact's energy on new surface."""

from __future__ import annotations

import math

import numpy as np
import pytest

from taichi_frac.fracture import energy as en
from taichi_frac.fracture.cracks import CrackPlane, analyze_impact
from taichi_frac.options import MATERIAL_PRESETS, FractureOptions, Material, OptionError, ParticleOptions, \
    SimulationOptions
from taichi_frac.scenes import Collider, Scene, SceneObject
from taichi_frac.simulation import Simulation

G = 9.81


def test_presets_fracture_energy_is_toughness_squared_over_modulus():
    # Soda-lime glass: K_Ic 0.75 MPa m^0.5, E 72 GPa -> 7.8 J/m^2 (twice Wiederhorn's 3.9 J/m^2
    # surface energy); porcelain 1.2 MPa m^0.5, 70 GPa -> 20.6 J/m^2.
    assert MATERIAL_PRESETS["soda_lime_glass"].fracture_energy == pytest.approx(7.8125, rel=1e-12)
    assert MATERIAL_PRESETS["porcelain"].fracture_energy == pytest.approx(1.44e12 / 70e9, rel=1e-12)
    with pytest.raises(OptionError, match="fracture_toughness"):
        Material(fracture_toughness=0.0)


def test_the_count_is_the_fourth_root_of_the_energy_over_one_crack_through_the_body():
    unit = 0.37
    assert en.auto_crack_count(unit * 3.0**4, unit) == 3
    assert en.auto_crack_count(unit * 3.0**4, unit, scale=2.0) == 6  # the artist's multiplier
    assert en.auto_crack_count(unit * 2.4**4, unit) == 2 and en.auto_crack_count(unit * 2.6**4, unit) == 3
    assert en.auto_crack_count(0.5 * unit, unit) == 1  # below one crack's cost: the Rankine crack alone
    assert en.auto_crack_count(unit * 1e12, unit) == 64
    assert en.auto_crack_count(0.0, unit) == 1
    # Four times the speed, sixteen times the energy: twice the cracks.
    assert en.auto_crack_count(16 * unit * 3.0**4, unit) == 2 * en.auto_crack_count(unit * 3.0**4, unit)


def test_crack_count_accepts_auto_or_a_number_and_names_the_bad_value():
    assert FractureOptions().crack_count == "auto" and FractureOptions().stress_model == "auto"
    with pytest.raises(OptionError, match="crack_count = 'many'"):
        FractureOptions(crack_count="many")
    with pytest.raises(OptionError, match="crack_scale"):
        FractureOptions(crack_scale=0.0)


def _slab(prepared_model, side=0.2, thickness=0.02, particles=3000):
    obj = SceneObject(name="slab", primitive=f"box:x={side},y={side},z={thickness}",
                      particles=ParticleOptions(target_particles=particles))
    return prepared_model(obj)


@pytest.fixture(scope="module")
def prepared_model():
    from taichi_frac.scene_setup import prepare_object

    return lambda obj: prepare_object(obj, surface_contact=False)[0]


def test_a_slab_is_slender_and_a_cube_is_not(prepared_model):
    slab = _slab(prepared_model)
    cube = prepared_model(SceneObject(name="cube", primitive="box:x=0.1,y=0.1,z=0.1",
                                      particles=ParticleOptions(target_particles=1000)))
    # 2 V / A over the diagonal, by hand: slab 2 x 8e-4 / 0.096 / 0.2835; cube 2 x 1e-3 / 0.06 / 0.1732.
    assert en.slenderness(slab) == pytest.approx(2 * 8e-4 / 0.096 / math.sqrt(0.08 + 0.0004), rel=0.02)
    assert en.slenderness(cube) == pytest.approx(2 * 1e-3 / 0.06 / math.sqrt(0.03), rel=0.02)
    options = FractureOptions()
    assert en.stress_model_of(slab, options) == "fem" and en.stress_model_of(cube, options) == "halfspace"
    assert en.stress_model_of(slab, FractureOptions(stress_model="sph")) == "sph"


def test_the_cracks_spend_the_impacts_energy_on_new_surface(prepared_model):
    """A 2 cm slab struck at its centre. With 4^4 crack-energies: four cracks, run to the
    slab's edges (the energy would carry them 64 L, but a crack cannot leave the body). With
    half a crack-energy: one crack, which runs E / (G_c d), so that its new surface costs
    exactly the impact's energy."""
    slab = _slab(prepared_model)
    material = Material(density=2400.0, young_modulus=70e9, poisson_ratio=0.2, tensile_strength=1e5,
                        fracture_toughness=1.0e5)
    spacing = float(np.mean(slab.tet_volume)) ** (1.0 / 3.0)
    thickness = en.thickness_under(slab, [0.0, 0.0, 0.01], [0.0, 0.0, -1.0], 2.0 * spacing)
    assert 0.02 <= thickness <= 0.02 + 1.5 * spacing
    by_hand = material.fracture_energy * thickness * math.sqrt(0.2 * 0.2 * 0.02 / (math.pi * thickness))
    assert en.crack_energy_scale(slab, material, thickness) == pytest.approx(by_hand, rel=0.01)
    hit = dict(contact_point_body=[0.0, 0.0, 0.01], normal_in_body=[0.0, 0.0, -1.0], force_body=[0.0, 0.0, -2e5],
               material=material)
    strong = analyze_impact(slab, **hit, options=FractureOptions(seed=3), energy=[4.0**4 * by_hand])
    planes = [c for c in strong.cracks if isinstance(c, CrackPlane)]
    assert len(planes) == 4
    h = strong.smoothing_length
    for c in planes:  # from the centre to the edge of the 0.2 m square: 0.1 m to its corner's 0.141 m
        assert 0.1 - h <= c.extent <= math.sqrt(2) * 0.1 + h
    weak = analyze_impact(slab, **hit, options=FractureOptions(seed=3), energy=[0.5 * by_hand])
    (crack,) = weak.cracks
    used = en.thickness_under(slab, weak.contact_point[0], weak.normal_in[0], h)
    assert material.fracture_energy * used * crack.extent == pytest.approx(0.5 * by_hand, rel=1e-9)
    assert crack.extent < 0.1  # (stopped by its energy, inside the slab)
    # The same impact with a number of cracks: the artist's count, the stress's reach.
    fixed = analyze_impact(slab, **hit, options=FractureOptions(seed=3, crack_count=2), energy=[4.0**4 * by_hand])
    assert len([c for c in fixed.cracks if isinstance(c, CrackPlane)]) == 2


def test_a_dropped_block_cracks_as_many_times_as_its_fall_pays_for(scene_world):
    """A 0.1 m block falls 0.8 m: m g h = 18.8 J against one crack through it, G_c x 0.1 m x
    sqrt(V / (pi 0.1 m)); K_Ic is chosen so that the ratio is 3^4 (three cracks)."""
    side, fall, density, young = 0.1, 0.8, 2400.0, 70e9
    mass = density * side**3
    energy = mass * G * fall
    reach = math.sqrt(side**3 / (math.pi * side))
    toughness = math.sqrt(energy / 3.0**4 / (side * reach) * young)
    block = SceneObject(
        name="block", primitive=f"box:x={side},y={side},z={side}",
        material=Material(density=density, young_modulus=young, poisson_ratio=0.2, tensile_strength=1.0e6,
                          fracture_toughness=toughness, look="porcelain"),
        position=(0.0, 0.0, fall + side / 2), particles=ParticleOptions(target_particles=500),
        fracture=FractureOptions(seed=1),
    )
    scene = Scene(name="drop", objects=[block], colliders=[Collider.ground(0.0)],
                  simulation=SimulationOptions(fps=50.0, duration=0.5, substeps=10))
    summary = Simulation(scene, output=False, world=scene_world).run()
    first = summary.events[0]
    assert first["energy"] == pytest.approx(energy, rel=0.06)
    # (the block's thickness under the hit is read from its particles, within a spacing of 0.1 m:
    # the count's fourth root moves by under 4 %)
    assert first["cracks"] == 3


def test_a_ring_bent_by_its_hit_also_cracks_across_its_tube_away_from_the_contact():
    """The ring (torus 0.1 / 0.025 m) struck on its outer equator: under its own elasticity
    the bending overloads the tube away from the contact too. Each such crack cuts the tube
    across (its plane holds the ring's axis, within 25 degrees), spans no more than the tube
    and a smoothing length, and lies more than a tube's width from the contact; a plate gets
    none (its far tension is the star's)."""
    from support.fracture_ring import RING_CONTACT, RING_FORCE, RING_NORMAL, struck_ring_model

    ring = struck_ring_model()
    material = Material(density=2400.0, young_modulus=70e9, poisson_ratio=0.2, tensile_strength=4e6)
    analysis = analyze_impact(ring, RING_CONTACT, RING_NORMAL, RING_FORCE * 10, material, FractureOptions(seed=1),
                              energy=[50.0])
    star = int(analysis.group_neighbor_count.shape[1])
    away = [c for c in analysis.cracks if isinstance(c, CrackPlane) and c.group_index >= star]
    assert away, "no crack away from the contact"
    h = analysis.smoothing_length
    for c in away:
        radial = c.point[:2] / np.linalg.norm(c.point[:2])
        hoop = np.array([-radial[1], radial[0], 0.0])
        assert abs(c.normal @ hoop) >= math.cos(math.radians(25.0)), (c.point, c.normal)
        assert c.extent <= 0.05 + 1.5 * h
        assert np.linalg.norm(c.point - RING_CONTACT) > 0.05
