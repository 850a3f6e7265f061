"""Boussinesq-Cerruti contact displacement (fracture/field.py) against closed forms and
the equations of elasticity: the corrected Cerruti field is in equilibrium and
traction-free; the paper's printed eq. (2) is not (BRIEF.md §2)."""

import numpy as np
import pytest

from taichi_frac.fracture import contact_frame, point_load_displacement
from taichi_frac.fracture.field import local_displacement_reference, point_load_gradient_reference

E, NU = 70.0e9, 0.2
G = E / (2.0 * (1.0 + NU))
LAM = E * NU / ((1.0 + NU) * (1.0 - 2.0 * NU))


def printed_eq2(x, y, z, normal_load, load_x, load_y, shear_modulus, poisson_ratio):
    """The paper's eq. (2) as printed (Qx only): '+' in u_x's bracket, 'xy' in u_z."""
    rho = np.sqrt(x * x + y * y + z * z)
    a = 1.0 - 2.0 * poisson_ratio
    c = load_x / (4.0 * np.pi * shear_modulus)
    ux = c * (1 / rho + x * x / rho**3 + a * (1 / (rho + z) + x * x / (rho * (rho + z) ** 2)))
    uy = c * (x * y / rho**3 - a * x * y / (rho * (rho + z) ** 2))
    uz = c * (x * y / rho**3 + a * x / (rho * (rho + z)))
    return ux, uy, uz


def linear_stress(grad):
    """Small-strain Hooke stress (independent of stress.py): lam tr(eps) I + 2 mu eps."""
    eps = 0.5 * (grad + np.swapaxes(grad, 1, 2))
    return LAM * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(3) + 2 * G * eps


def exact_stress(points, force, field=None, radius=0.0):
    grad = point_load_gradient_reference(points, np.zeros(3), [0, 0, 1], force, G, NU, radius,
                                         field=field)
    return linear_stress(grad)


def div_stress(points, force, field=None, step=1e-4):
    """div sigma by central differences of the exact stress (error O(step^2))."""
    div = np.zeros((len(points), 3))
    for b in range(3):
        dx = np.zeros(3)
        dx[b] = step
        diff = (exact_stress(points + dx, force, field) - exact_stress(points - dx, force, field))
        div += diff[:, :, b] / (2 * step)
    return div


def sample_points(count, seed, z_low=0.3):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-1.0, 1.0, (count, 3))
    pts[:, 2] = rng.uniform(z_low, 1.0, count)
    return pts


def test_kernel_matches_numpy_twin_in_any_frame():
    rng = np.random.default_rng(3)
    normal = rng.normal(size=3)
    origin = rng.normal(size=3)
    frame = contact_frame(normal)
    assert np.allclose(frame @ frame.T, np.eye(3), atol=1e-15)
    assert np.allclose(frame[2], normal / np.linalg.norm(normal))
    local = sample_points(200, 4, z_low=0.0)
    pts = origin + local @ frame
    force = rng.normal(size=3) * 1e5
    radius = 0.05
    u = point_load_displacement(pts, origin, normal, force, G, NU, radius)
    p_q = frame @ force
    ref = local_displacement_reference(local[:, 0], local[:, 1], local[:, 2] + radius,
                                       p_q[2], p_q[0], p_q[1], G, NU)
    ref_world = np.stack(ref, axis=1) @ frame
    np.testing.assert_allclose(u, ref_world, rtol=1e-12, atol=1e-12 * np.abs(ref_world).max())


def test_reference_gradient_gives_brief_closed_form_boussinesq_stress():
    """BRIEF.md §2 closed-form stresses (cylindrical) vs the stress of our field's gradient."""
    pts = sample_points(300, 5)
    P = 2.5e4
    sigma = exact_stress(pts, [0.0, 0.0, P])
    x, y, z = pts.T
    r = np.hypot(x, y)
    rho = np.linalg.norm(pts, axis=1)
    a = 1 - 2 * NU
    s_z = -3 * P * z**3 / (2 * np.pi * rho**5)
    s_r = P / (2 * np.pi) * (a / r**2 * (1 - z / rho) - 3 * z * r**2 / rho**5)
    s_t = -P * a / (2 * np.pi) * (1 / r**2 * (1 - z / rho) - z / rho**3)
    t_rz = -3 * P * r * z**2 / (2 * np.pi * rho**5)
    c, s = x / r, y / r
    ref = np.zeros_like(sigma)
    ref[:, 0, 0] = s_r * c * c + s_t * s * s
    ref[:, 1, 1] = s_r * s * s + s_t * c * c
    ref[:, 0, 1] = ref[:, 1, 0] = (s_r - s_t) * c * s
    ref[:, 2, 2] = s_z
    ref[:, 0, 2] = ref[:, 2, 0] = t_rz * c
    ref[:, 1, 2] = ref[:, 2, 1] = t_rz * s
    scale = np.abs(ref).max(axis=(1, 2))[:, None, None]
    assert np.abs(sigma - ref).max() < 1e-9 * scale.max()
    assert (np.abs(sigma - ref) / scale).max() < 1e-9


@pytest.mark.parametrize("force", [[0, 0, 1e4], [1e4, 0, 0], [0, 1e4, 0], [3e3, -2e3, 1e4]])
def test_corrected_field_is_in_equilibrium_and_traction_free(force):
    pts = sample_points(200, 6)
    rho = np.linalg.norm(pts, axis=1)
    sigma_scale = np.linalg.norm(force) / rho**2  # |sigma| ~ F / rho^2
    residual = np.linalg.norm(div_stress(pts, force), axis=1) * rho / sigma_scale
    assert residual.max() < 1e-5, residual.max()
    # Free surface z = 0 away from the load: traction sigma . e_z = 0.
    surface = sample_points(200, 7)
    surface[:, 2] = 1e-9  # on the surface (the reference needs z > 0 strictly)
    rho_s = np.linalg.norm(surface, axis=1)
    traction = exact_stress(surface, force)[:, :, 2]
    scale = np.linalg.norm(force) / rho_s**2
    assert (np.linalg.norm(traction, axis=1) / scale).max() < 1e-7


def test_printed_cerruti_eq2_fails_equilibrium():
    """The test above would catch the misprint: the printed field is far from equilibrium."""
    force = [1e4, 0.0, 0.0]
    pts = sample_points(200, 6)
    rho = np.linalg.norm(pts, axis=1)
    sigma_scale = np.linalg.norm(force) / rho**2
    residual = np.linalg.norm(div_stress(pts, force, field=printed_eq2), axis=1) * rho / sigma_scale
    assert np.median(residual) > 0.05, np.median(residual)
    # ... and it is not traction-free on z = 0 either.
    surface = sample_points(200, 7)
    surface[:, 2] = 1e-9
    rho_s = np.linalg.norm(surface, axis=1)
    traction = exact_stress(surface, force, field=printed_eq2)[:, :, 2]
    assert np.median(np.linalg.norm(traction, axis=1) * rho_s**2 / 1e4) > 0.01


def test_regularised_field_is_exact_solution_with_unit_resultant():
    """Load at depth -a: still in equilibrium inside, and the normal traction it puts on
    z = 0 integrates to P (a pressure patch of radius ~a, not a point)."""
    a = 0.05
    force = [2e3, -1e3, 1e4]
    pts = sample_points(100, 8, z_low=0.0)
    pts_shifted = pts + [0, 0, a]
    # Equilibrium of the regularised field = equilibrium of the exact one at z + a.
    rho = np.linalg.norm(pts_shifted, axis=1)
    residual = np.linalg.norm(div_stress(pts_shifted, force), axis=1) * rho / np.linalg.norm(force) * rho**2
    assert residual.max() < 1e-5
    # Resultant of the surface traction over a disc of radius R (polar midpoint rule):
    # -integral sigma_zz dA -> P (1 - a^3 / (R^2 + a^2)^(3/2)).
    radius = 40 * a
    r = (np.arange(400) + 0.5) * radius / 400
    th = (np.arange(64) + 0.5) * 2 * np.pi / 64
    R, TH = np.meshgrid(r, th, indexing="ij")
    surface = np.stack([R.ravel() * np.cos(TH.ravel()), R.ravel() * np.sin(TH.ravel()),
                        np.zeros(R.size)], axis=1)
    sigma = exact_stress(surface, force, radius=a)
    dA = (R * (radius / 400) * (2 * np.pi / 64)).ravel()
    resultant = -(sigma[:, :, 2] * dA[:, None]).sum(axis=0)
    expected_p = force[2] * (1 - a**3 / (radius**2 + a**2) ** 1.5)
    assert resultant[2] == pytest.approx(expected_p, rel=2e-3)


def test_load_exactly_on_a_particle_is_finite_and_bounded():
    pts = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.0, 0.01]])
    P, a = 1e9, 0.005
    u = point_load_displacement(pts, pts[0], [0, 0, 1], [0, 0, P], G, 0.49, a)
    assert np.all(np.isfinite(u))
    # Bounded by the field at distance a from the load: |u| <= (3 - 2 nu) P / (4 pi G a).
    assert np.abs(u).max() <= (3 - 2 * 0.49) * P / (4 * np.pi * G * a) * (1 + 1e-12)
    # Unregularised (a = 0) is floored, not NaN.
    u0 = point_load_displacement(pts, pts[0], [0, 0, 1], [1, 2, 3], G, 0.0)
    assert np.all(np.isfinite(u0))


def test_points_outside_the_tangent_plane_are_finite():
    pts = sample_points(50, 9)
    pts[:, 2] *= -1.0  # all on the wrong side of a concave contact
    u = point_load_displacement(pts, np.zeros(3), [0, 0, 1], [1e3, 1e3, 1e3], G, NU, 0.01)
    assert np.all(np.isfinite(u))


def test_bad_inputs_raise():
    with pytest.raises(ValueError):
        point_load_displacement(np.zeros((2, 3)), np.zeros(3), [0, 0, 0], [0, 0, 1], G, NU)
    with pytest.raises(ValueError):
        point_load_displacement(np.zeros((2, 3)), np.zeros(3), [0, 0, 1], [0, 0, 1], G, 0.5)
    with pytest.raises(ValueError):
        point_load_displacement(np.zeros((2, 2)), np.zeros(3), [0, 0, 1], [0, 0, 1], G, NU)
