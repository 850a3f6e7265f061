"""The three stress models (fracture/halfspace.py, fem.py, api.body_stress, cracks.analyze_impact)
against independent references: the complex-step derivative of the half-space displacement,
a patch test, beam theory, the half-space solution in a large block, equilibrium."""

from __future__ import annotations

import numpy as np
import pytest

from taichi_frac.fracture import body_stress, contact_field
from taichi_frac.fracture import fem
from taichi_frac.fracture.field import point_load_gradient_reference
from taichi_frac.fracture.halfspace import point_loads_gradient
from taichi_frac.fracture.stress import largest_principal_stress, stress_from_gradient
from taichi_frac.options import FractureOptions, OptionError

E, NU = 70.0e9, 0.2
SHEAR = E / (2.0 * (1.0 + NU))


def box_mesh(size, cells, split_axis_last=False):
    """A structured tet mesh of the box [0, sx] x [-sy/2, sy/2] x [-sz/2, sz/2]: cells
    (nx, ny, nz) hexahedra, each split into the six tets around its main diagonal (Kuhn).
    Returns (vertices (V,3) [m], tets (T,4))."""
    sx, sy, sz = size
    nx, ny, nz = cells
    axes = [np.linspace(0, sx, nx + 1), np.linspace(-sy / 2, sy / 2, ny + 1), np.linspace(-sz / 2, sz / 2, nz + 1)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    index = np.arange(len(grid)).reshape(nx + 1, ny + 1, nz + 1)
    corner = [index[i:i + nx, j:j + ny, k:k + nz].reshape(-1)
              for i, j, k in ((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1))]
    tets = [np.stack([corner[0], corner[a], corner[b], corner[6]], axis=1)
            for a, b in ((1, 2), (2, 3), (3, 7), (7, 4), (4, 5), (5, 1))]
    return grid, np.concatenate(tets)


# --- halfspace: the closed-form gradient ---------------------------------------------------

def test_closed_form_gradient_matches_the_complex_step_derivative():
    rng = np.random.default_rng(4)
    points = rng.uniform(-0.2, 0.2, (400, 3))
    contacts = np.array([[0.01, -0.02, 0.0], [-0.05, 0.04, 0.01]])
    normals = np.array([[0.1, 0.2, 1.0], [-0.3, 0.1, 1.0]])
    forces = np.array([[2e4, -1e4, -1e5], [-3e3, 5e3, -2e4]])
    radii = np.array([0.004, 0.0])  # a regularised patch and the singular point load
    points[:, 2] = np.abs(points[:, 2])  # most points inside both half spaces
    depth = np.stack([(points - contacts[k]) @ (normals[k] / np.linalg.norm(normals[k])) for k in range(2)])
    inside = np.all(depth > 1e-3, axis=0)
    points = points[inside]
    grad = point_loads_gradient(points, contacts, normals, forces, SHEAR, NU, radii)
    ref = sum(point_load_gradient_reference(points, contacts[k], normals[k], forces[k], SHEAR, NU, radii[k])
              for k in range(2))
    assert len(points) > 100
    assert np.max(np.abs(grad - ref)) <= 1e-10 * np.max(np.abs(ref))
    # A wrong term anywhere in the field would show: the Boussinesq part alone differs.
    normal_only = point_loads_gradient(points, contacts[:1], normals[:1], forces[:1], SHEAR, NU, radii[:1])
    assert np.max(np.abs(normal_only - ref)) > 1e-3 * np.max(np.abs(ref))


def test_above_the_tangent_plane_the_gradient_is_the_clamped_fields():
    """z is clamped to 0 outside the half space (field.py): the field there varies only along
    the plane, and its in-plane derivatives are those of the surface field."""
    a = 0.003
    above = np.array([[0.02, 0.01, -0.004]])
    on = np.array([[0.02, 0.01, 0.0]])
    grad_above = point_loads_gradient(above, np.zeros((1, 3)), [[0, 0, 1.0]], [[1e3, 0, -1e4]], SHEAR, NU, [a])
    grad_on = point_load_gradient_reference(on + [0, 0, 1e-300], np.zeros(3), [0, 0, 1.0], [1e3, 0, -1e4], SHEAR,
                                            NU, a)
    assert np.all(grad_above[0][:, 2] == 0.0)
    assert np.allclose(grad_above[0][:, :2], grad_on[0][:, :2], rtol=1e-9, atol=1e-9 * np.abs(grad_on).max())


def test_default_body_stress_is_exact_on_the_cubes_tet_centroids():
    """The benchmark's cube: 0.2 m, a shear + normal load at the top centre; the default model's
    interior stress on the tet centroids against the exact stress of the same load."""
    vertices, tets = box_mesh((0.2, 0.2, 0.2), (8, 8, 8))
    vertices = vertices - [0.1, 0.0, 0.0]
    top = np.array([0.0, 0.0, 0.1])
    force = np.array([2e4, -1e4, -1e5])
    result = body_stress(vertices, tets, 2500.0, top, [0, 0, -1.0], force, E, NU)
    assert result.method == "halfspace"
    exact = stress_from_gradient(point_load_gradient_reference(result.centroids, top, [0, 0, -1.0], force, SHEAR,
                                                               NU, result.contact_radius[0]), E, NU)
    r = np.linalg.norm(result.centroids - top, axis=1)
    interior = r < 0.2 / 3
    assert np.sum(np.abs(result.stress[interior] - exact[interior])) <= 1e-9 * np.sum(np.abs(exact[interior]))
    assert np.allclose(result.principal_stress, largest_principal_stress(exact), rtol=0,
                       atol=1e-8 * np.abs(exact).max())
    # contact_field's halfspace method is the same field; its "sph" method is not exact.
    field = contact_field(result.centroids, result.volumes, top, [0, 0, -1.0], force, E, NU, method="halfspace")
    assert np.allclose(field.stress, result.stress, rtol=0, atol=1e-9 * np.abs(exact).max())
    sph = contact_field(result.centroids, result.volumes, top, [0, 0, -1.0], force, E, NU, method="sph")
    assert np.sum(np.abs(sph.stress[interior] - exact[interior])) > 0.01 * np.sum(np.abs(exact[interior]))


# --- fem ------------------------------------------------------------------------------------

def test_patch_test_reproduces_a_uniform_stress_exactly():
    """Consistent nodal forces of a uniform stress's traction on every boundary face: a
    balanced load whose exact solution is that uniform stress, which linear tets hold exactly."""
    vertices, tets = box_mesh((0.3, 0.2, 0.1), (4, 3, 2))
    rng = np.random.default_rng(1)
    vertices = vertices + rng.uniform(-0.01, 0.01, vertices.shape) * (np.abs(vertices) < [0.29, 0.09, 0.04])
    body = fem.elastic_body(vertices, tets, 2000.0, E, NU)
    sigma = np.array([[3e6, 1e6, -2e6], [1e6, -4e6, 5e5], [-2e6, 5e5, 1e6]])
    from taichi_frac.geometry.topology import boundary_faces

    faces = boundary_faces(body.tets)[0]
    tri = vertices[faces]
    area_normal = 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # outward, |.| = area
    loads = np.zeros_like(vertices)
    np.add.at(loads, faces.reshape(-1), np.repeat(area_normal @ sigma / 3.0, 3, axis=0))
    relief = fem.inertia_relief(body, loads)
    assert np.abs(relief).max() <= 1e-9 * np.abs(loads).max()  # a uniform stress is balanced by itself
    stress = fem.tet_stress(body, fem.solve_displacement(body, loads + relief))
    assert np.abs(stress - sigma).max() <= 1e-7 * np.abs(sigma).max()


def test_cantilever_tip_deflection_matches_beam_theory():
    """A clamped 0.3 x 0.1 x 0.1 m beam, tip load P: Timoshenko's P L^3 / (3 E I) +
    P L / (kappa G A) within 5 % (linear tets, 10 elements through the depth; nu = 0 so
    the clamp adds no lateral restraint that beam theory ignores)."""
    length, depth, load, young = 0.3, 0.1, 1e3, 1e9
    vertices, tets = box_mesh((length, depth, depth), (30, 10, 10))
    clamped = np.nonzero(vertices[:, 0] < 1e-9)[0]
    body = fem.elastic_body(vertices, tets, 1000.0, young, 0.0, fixed_nodes=clamped)
    tip = np.nonzero(vertices[:, 0] > length - 1e-9)[0]
    on_edge = [np.isclose(np.abs(vertices[tip, c]), depth / 2) for c in (1, 2)]
    weight = np.where(on_edge[0], 0.5, 1.0) * np.where(on_edge[1], 0.5, 1.0)  # the face's trapezoid rule
    weight /= weight.sum()
    loads = np.zeros_like(vertices)
    loads[tip, 2] = -load * weight
    u = fem.solve_displacement(body, loads)
    deflection = -np.average(u[tip, 2], weights=weight)
    inertia, area, shear = depth**4 / 12.0, depth**2, young / 2.0
    beam = load * length**3 / (3.0 * young * inertia) + load * length / (5.0 / 6.0 * shear * area)
    assert abs(deflection / beam - 1.0) <= 0.05, deflection / beam


def test_inertia_relieved_load_has_no_net_force_or_torque():
    vertices, tets = box_mesh((0.2, 0.1, 0.05), (6, 3, 2))
    body = fem.elastic_body(vertices, tets, 2400.0, E, NU)
    contacts = np.array([[0.2, 0.0, 0.0], [0.1, 0.05, 0.01]])
    normals = np.array([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    forces = np.array([[-5e3, 2e3, 1e3], [0.0, -3e3, 4e3]])
    loads = fem.contact_loads(body, contacts, normals, forces, [0.01, 0.005])
    assert np.allclose(loads.sum(axis=0), forces.sum(axis=0), rtol=1e-12)
    relief = fem.inertia_relief(body, loads)
    total = loads + relief
    arm = vertices - body.centre_of_mass
    scale = np.abs(forces).max()
    assert np.abs(total.sum(axis=0)).max() <= 1e-10 * scale
    assert np.abs(np.cross(arm, total).sum(axis=0)).max() <= 1e-10 * scale * 0.2
    # The relief is not trivially zero: it carries the whole resultant and moment.
    assert np.allclose(relief.sum(axis=0), -forces.sum(axis=0), rtol=1e-9)
    assert np.abs(np.cross(arm, relief).sum(axis=0)).max() > 10.0


def test_large_block_matches_the_half_space_away_from_its_faces():
    """A 1 m block loaded at its top centre: FEM against the exact half-space stress of the
    same load, 8 to 30 cm from the load (far from the other faces). Linear tets' stress is
    constant per tet and noisy from tet to tet, so the check is on the volume-weighted mean
    stress of each quadrant of that shell (measured 8-16 % on this 10,368-tet mesh; a flipped
    or missing load component gives > 50 %)."""
    vertices, tets = box_mesh((1.0, 1.0, 1.0), (12, 12, 12))
    # Grade the mesh toward the loaded top centre (x = 0.5, z = 0.5): finer where it matters.
    centre = np.array([0.5, 0.0, 0.5])
    rel = (vertices - centre) / np.array([0.5, 0.5, 1.0])
    vertices = centre + np.sign(rel) * np.abs(rel) ** 2 * np.array([0.5, 0.5, 1.0])
    force = np.array([1e4, 0.0, -5e4])
    result = body_stress(vertices, tets, 2500.0, centre, [0, 0, -1.0], force, E, NU, method="fem",
                         contact_radius=0.01)
    exact = stress_from_gradient(point_load_gradient_reference(result.centroids, centre, [0, 0, -1.0], force, SHEAR,
                                                               NU, 0.01), E, NU)
    offset = result.centroids - centre
    r = np.linalg.norm(offset, axis=1)
    for sx in (-1, 1):
        for sy in (-1, 1):
            region = (r > 0.08) & (r < 0.3) & (np.sign(offset[:, 0]) == sx) & (np.sign(offset[:, 1]) == sy)
            assert region.sum() > 300
            weight = result.volumes[region]
            fem_mean = np.einsum("t,tij->ij", weight, result.stress[region])
            exact_mean = np.einsum("t,tij->ij", weight, exact[region])
            error = np.linalg.norm(fem_mean - exact_mean) / np.linalg.norm(exact_mean)
            assert error < 0.2, (sx, sy, error)


# --- the models in the crack analysis -------------------------------------------------------

@pytest.mark.parametrize("model", ["sph", "halfspace", "fem"])
def test_every_model_cracks_the_ring_with_the_asked_crack_count(model):
    from taichi_frac.fracture.cracks import CrackPlane, analyze_impact
    from taichi_frac.options import Material

    from support import fracture_ring as ring

    body = ring.struck_ring_model()
    material = Material(density=2400.0, young_modulus=E, poisson_ratio=NU, tensile_strength=1e6)
    planes = {}
    for count in (1, 3):
        options = FractureOptions(stress_model=model, crack_count=count, crack_length=0.05, seed=2)
        analysis = analyze_impact(body, ring.RING_CONTACT, ring.RING_NORMAL, 5 * ring.RING_FORCE, material, options,
                                  full_field=model == "fem")
        planes[count] = [c for c in analysis.cracks if isinstance(c, CrackPlane)]
        assert analysis.peak_principal_stress > material.tensile_strength
        if model == "fem":  # one contact: its analysis point is the body's tension peak, wherever it lies
            assert analysis.analysis_particle[0] == np.nanargmax(analysis.particle_principal_stress)
    assert len(planes[1]) == 1 and len(planes[3]) == 3
    normals = np.array([c.normal for c in planes[3]])
    assert np.min(1.0 - np.abs(normals @ normals.T)[~np.eye(3, dtype=bool)]) > 1e-3  # they fan out


def test_the_fem_model_factorises_a_body_once():
    from taichi_frac.fracture.fem import elastic_body_of
    from taichi_frac.options import Material

    from support import fracture_ring as ring

    material = Material(density=2400.0, young_modulus=E, poisson_ratio=NU, tensile_strength=1e6)
    body = ring.struck_ring_model()
    assert elastic_body_of(body, material) is elastic_body_of(body, material)


def test_an_unknown_stress_model_is_named_in_the_error():
    with pytest.raises(OptionError, match="stress_model = 'exact'.*sph, halfspace, fem"):
        FractureOptions(stress_model="exact")
    with pytest.raises(ValueError, match="'fem' needs the tets"):
        contact_field(np.zeros((4, 3)), np.ones(4), np.zeros(3), [0, 0, 1.0], [0, 0, 1.0], E, NU, method="fem")
