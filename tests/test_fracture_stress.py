"""Strain, Hooke stress, principal stresses (fracture/stress.py) and the whole
contact_field chain against the exact stress of the same displacement field."""

import numpy as np
import pytest
from support.fracture_ring import jittered_block

from taichi_frac.fracture import (
    contact_field,
    displacement_gradient,
    green_strain,
    principal_stresses,
    rankine_flags,
    stress_from_gradient,
)
from taichi_frac.fracture import stress as stress_module
from taichi_frac.fracture.field import point_load_gradient_reference
from taichi_frac.options import FractureOptions, Material

E, NU = 70.0e9, 0.2


def test_green_strain_has_no_cancellation_for_tiny_gradients():
    rng = np.random.default_rng(0)
    grad = rng.normal(size=(500, 3, 3)) * 1e-7
    got = green_strain(grad)
    g = grad.astype(np.longdouble)
    ref = 0.5 * (g + np.swapaxes(g, 1, 2) + np.einsum("nka,nkb->nab", g, g))
    rel = np.abs(got - ref).max() / np.abs(ref).max()
    assert rel < 1e-15
    # The textbook form in float64 loses digits (why stress.py does not use it).
    f = np.eye(3) + grad
    naive = 0.5 * (np.einsum("nka,nkb->nab", f, f) - np.eye(3))
    assert np.abs(naive - ref).max() / np.abs(ref).max() > 1e-11


def test_green_strain_vanishes_for_rigid_rotation_and_is_zero_at_rest():
    angle = 0.3
    rot = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0],
                    [0, 0, 1]])
    strain = green_strain((rot - np.eye(3))[None])
    assert np.abs(strain).max() < 1e-15
    assert np.all(green_strain(np.zeros((2, 3, 3))) == 0)  # printed eq. (4) would give -I/2


def test_hooke_uniaxial_strain_and_shear():
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    mu = E / (2 * (1 + NU))
    e = 1e-5
    grad = np.zeros((2, 3, 3))
    grad[0, 0, 0] = e  # uniaxial strain: E_xx = e + e^2/2
    grad[1, 0, 1] = e  # simple shear: E_xy = e/2, E_yy = e^2/2
    s = stress_from_gradient(grad, E, NU)
    exx = e + e * e / 2
    assert s[0, 0, 0] == pytest.approx((lam + 2 * mu) * exx, rel=1e-14)
    assert s[0, 1, 1] == pytest.approx(lam * exx, rel=1e-14)
    assert s[1, 0, 1] == pytest.approx(mu * e, rel=1e-14)
    assert s[1, 1, 1] == pytest.approx((lam + 2 * mu) * e * e / 2, rel=1e-12)
    assert np.array_equal(s, np.swapaxes(s, 1, 2))


@pytest.mark.parametrize("scale", [1e-20, 1.0, 1e20])
def test_principal_stresses_match_numpy(scale):
    rng = np.random.default_rng(1)
    a = rng.normal(size=(300, 3, 3))
    a = (a + np.swapaxes(a, 1, 2)) * scale
    a[0] = np.diag([2.0, 2.0, -1.0]) * scale  # repeated eigenvalue
    a[1] = 0.0
    values, dirs = principal_stresses(a)
    ref = np.linalg.eigh(a)[0][:, ::-1]
    tol = 1e-13 * scale
    np.testing.assert_allclose(values, ref, rtol=0, atol=tol * np.abs(a).max() / scale)
    assert np.all(np.diff(values, axis=1) <= 0)
    residual = np.einsum("nij,njk->nik", a, dirs) - dirs * values[:, None, :]
    assert np.abs(residual).max() < 1e-13 * np.abs(a).max()
    np.testing.assert_allclose(np.einsum("nji,njk->nik", dirs, dirs), np.broadcast_to(np.eye(3), a.shape), atol=1e-13)
    # Sign convention: the largest-magnitude component of each direction is positive.
    big = np.take_along_axis(dirs, np.abs(dirs).argmax(axis=1)[:, None, :], axis=1)
    assert np.all(big > 0)
    assert np.array_equal(values[1], np.zeros(3)) and np.array_equal(dirs[1], np.eye(3))


def test_rankine_flags():
    values = np.array([[50e6, 0, -1e6], [10e6, 5e6, 0], [45e6, 0, 0]])
    assert rankine_flags(values, 45e6).tolist() == [True, False, False]
    assert rankine_flags(values[:, 0], 9e6).tolist() == [True, True, True]


# --- the whole chain on a block: SPH stress vs the exact stress of the same field -----------

TOP = np.array([0.0, 0.0, 1.0])
DOWN = np.array([0.0, 0.0, -1.0])  # inward normal of the top face


def face_distance(pts):
    return np.min(np.stack([pts[:, 0] + 0.5, 0.5 - pts[:, 0], pts[:, 1] + 0.5,
                            0.5 - pts[:, 1], pts[:, 2], 1 - pts[:, 2]], axis=1), axis=1)


def relative_error(stress, exact, mask):
    return np.linalg.norm(stress[mask] - exact[mask]) / np.linalg.norm(exact[mask])


@pytest.fixture(scope="module")
def block_field():
    pts, vol = jittered_block(17)  # 4,913 particles, the default resolution
    force = np.array([2e4, -1e4, -1e5])
    field = contact_field(pts, vol, TOP, DOWN, force, E, NU)
    shear = E / (2 * (1 + NU))
    exact_grad = point_load_gradient_reference(pts, TOP, DOWN, force, shear, NU,
                                               field.contact_radius)
    return pts, vol, force, field, stress_from_gradient(exact_grad, E, NU)


def test_block_sph_stress_matches_exact_stress_of_same_field(block_field):
    """Error metric (also in benchmarks/bench_stress.py): relative L2 (Frobenius) of sigma
    over particles >= 2h from the load and >= h (a full kernel support) from every face."""
    pts, vol, force, field, exact = block_field
    h = field.smoothing_length
    assert h == pytest.approx(2.0 / 17)
    far = np.linalg.norm(pts - TOP, axis=1) >= 2 * h
    interior = far & (face_distance(pts) >= h)
    assert interior.sum() > 1500
    assert not field.correction_fallback.any()
    corrected_err = relative_error(field.stress, exact, interior)
    assert corrected_err < 0.05, corrected_err  # measured 0.036
    # Near the free surfaces too (the corrected gradient has no surface bias).
    assert relative_error(field.stress, exact, far) < 0.08  # measured 0.064
    plain = stress_from_gradient(
        displacement_gradient(pts, vol, field.displacement, field.neighbor_offsets,
                              field.neighbor_indices, h, corrected=False), E, NU)
    plain_err = relative_error(plain, exact, interior)
    assert plain_err > 2 * corrected_err  # measured 0.137
    assert relative_error(plain, exact, far) > 0.15  # measured 0.205: surface bias
    # Principal outputs are consistent with the stress.
    np.testing.assert_allclose(np.linalg.norm(field.principal_direction, axis=1), 1, atol=1e-12)
    sv = np.einsum("nij,nj->ni", field.stress, field.principal_direction)
    np.testing.assert_allclose(sv, field.principal_stress[:, None] * field.principal_direction,
                               atol=1e-10 * np.abs(field.stress).max())


def test_block_closed_form_boussinesq_stress_for_a_normal_load():
    """BRIEF.md's closed-form sigma_z and tau_rz, evaluated at depth z + a (the regularised
    load), against the SPH stress at interior particles."""
    pts, vol = jittered_block(17, seed=3)
    P = 1e5
    field = contact_field(pts, vol, TOP, DOWN, [0, 0, -P], E, NU)
    h, a = field.smoothing_length, field.contact_radius
    depth = 1.0 - pts[:, 2] + a
    r = np.hypot(pts[:, 0], pts[:, 1])
    rho = np.hypot(r, depth)
    # Stress in the local frame (z down); sigma_zz and the r-z shear are invariant under the
    # flip z -> -z up to the sign of tau_rz.
    s_z = -3 * P * depth**3 / (2 * np.pi * rho**5)
    t_rz = -3 * P * r * depth**2 / (2 * np.pi * rho**5)
    interior = (np.linalg.norm(pts - TOP, axis=1) >= 2 * h) & (face_distance(pts) >= h)
    sph_zz = field.stress[:, 2, 2]
    radial = np.stack([pts[:, 0], pts[:, 1]], axis=1) / np.maximum(r, 1e-300)[:, None]
    sph_rz = -(field.stress[:, 0, 2] * radial[:, 0] + field.stress[:, 1, 2] * radial[:, 1])
    err_z = np.linalg.norm(sph_zz[interior] - s_z[interior]) / np.linalg.norm(s_z[interior])
    err_rz = np.linalg.norm(sph_rz[interior] - t_rz[interior]) / np.linalg.norm(t_rz[interior])
    assert err_z < 0.05, err_z
    assert err_rz < 0.08, err_rz


def test_hard_cases_stay_finite_and_linear():
    # The paper's SPH gradient (the exact model's peak follows the contact particle's radius).
    pts, vol = jittered_block(12, seed=4)
    # Contact exactly on a top-layer particle near the centre.
    top_layer = np.where(pts[:, 2] > 1 - 1.0 / 12)[0]
    on = top_layer[np.argmin(np.hypot(pts[top_layer, 0], pts[top_layer, 1]))]
    unit = np.array([0.3, -0.2, -1.0])
    ref = contact_field(pts, vol, pts[on], DOWN, unit, E, NU, method="sph")
    assert np.all(np.isfinite(ref.stress)) and np.isfinite(ref.principal_stress).all()
    # Off the particle by half a spacing: the peak stress changes by less than 2x.
    off = contact_field(pts, vol, pts[on] + [0.5 / 12, 0, 0], DOWN, unit, E, NU, method="sph")
    ratio = np.abs(off.stress).max() / np.abs(ref.stress).max()
    assert 0.5 < ratio < 2.0, ratio
    for force_scale in (1e-6, 1e9):
        f = contact_field(pts, vol, pts[on], DOWN, unit * force_scale, E, NU, method="sph")
        assert np.all(np.isfinite(f.stress)) and np.all(np.isfinite(f.principal_direction))
        if force_scale == 1e-6:  # linear regime: stress scales with the force
            np.testing.assert_allclose(f.stress, ref.stress * force_scale, rtol=1e-6,
                                       atol=1e-9 * np.abs(ref.stress).max() * force_scale)
    for nu in (0.0, 0.49):
        f = contact_field(pts, vol, pts[on], DOWN, unit * 1e5, E, nu)
        assert np.all(np.isfinite(f.stress)) and np.all(np.isfinite(f.displacement))
        assert np.abs(f.principal_stress).max() > 0


def test_contact_field_defaults_follow_options_and_material():
    pts, vol = jittered_block(6, seed=5)
    glass = Material(name="glass", young_modulus=72e9, poisson_ratio=0.23)
    f = contact_field(pts, vol, TOP, DOWN, [0, 0, -1e4], glass.young_modulus,
                      glass.poisson_ratio, options=FractureOptions(smoothing_length_factor=3.0,
                                                                   contact_radius=0.05))
    assert f.smoothing_length == pytest.approx(3.0 / 6)
    assert f.contact_radius == 0.05
    g = contact_field(pts, vol, TOP, DOWN, [0, 0, -1e4], glass.young_modulus,
                      glass.poisson_ratio, smoothing_length=0.4, corrected=False)
    assert g.smoothing_length == 0.4 and not g.correction_fallback.any()
    nearest = np.argmin(np.linalg.norm(pts - TOP, axis=1))
    assert g.contact_radius == pytest.approx((3 * vol[nearest] / (4 * np.pi)) ** (1 / 3))
    assert f.displacement.shape == (len(pts), 3) and f.stress.shape == (len(pts), 3, 3)
    assert f.principal_stress.shape == (len(pts),) and f.principal_direction.shape == (len(pts), 3)


def test_stress_kernels_compile_once():
    for n in (3, 7):
        grad = np.random.default_rng(n).normal(size=(n, 3, 3)) * 1e-6
        principal_stresses(stress_from_gradient(grad, E, NU))
        green_strain(grad)
    for kernel in (stress_module._stress_kernel, stress_module._principal_kernel,
                   stress_module._strain_kernel):
        assert len(kernel._primal.compiled_kernels) == 1


def test_largest_principal_stress_closed_form_matches_lapack():
    """The closed-form largest eigenvalue against LAPACK's (numpy eigvalsh) on random
    symmetric stresses of 1 Pa to 1 GPa, and on the degenerate cases where the cubic's
    angle is least accurate: two or three equal principal stresses, zero, pure shear."""
    rng = np.random.default_rng(7)
    a = rng.normal(size=(2000, 3, 3)) * 10.0 ** rng.uniform(0, 9, (2000, 1, 1))
    a = 0.5 * (a + a.transpose(0, 2, 1))
    rot = np.linalg.qr(rng.normal(size=(4, 3, 3)))[0]
    special = [np.zeros((3, 3)), np.eye(3) * 5e6, np.diag([3e6, 3e6, -1e6]), np.diag([-2e6, 7e6, 7e6]),
               np.array([[0, 4e6, 0], [4e6, 0, 0], [0, 0, 0]])]
    special += [r @ np.diag([6e6, 6e6 * (1 + 1e-12), 1e5]) @ r.T for r in rot]
    stress = np.concatenate([a, np.array(special)])
    got = stress_module.largest_principal_stress(stress)
    exact = np.linalg.eigvalsh(stress)[:, -1]
    size = np.abs(stress).max(axis=(1, 2))
    assert np.all(np.abs(got - exact) <= 1e-8 * np.maximum(size, 1e-300))


def test_closed_form_extreme_eigenvalues_match_lapack():
    """sym_eig3_extremes_f64 (the corrected gradient's conditioning test) against LAPACK on
    random symmetric matrices, on PSD moment-like ones near the test's 1e-3 ratio, and on
    the degenerate cases (repeated eigenvalues, zero, rank one)."""
    import taichi as ti

    rng = np.random.default_rng(11)
    a = rng.normal(size=(1000, 3, 3))
    a = 0.5 * (a + a.transpose(0, 2, 1))
    rot = np.linalg.qr(rng.normal(size=(300, 3, 3)))[0]
    psd = np.einsum("nij,nj,nkj->nik", rot, np.stack([np.ones(300), 10.0 ** rng.uniform(-4, 0, 300),
                                                      10.0 ** rng.uniform(-4, 0, 300)], axis=1), rot)
    special = np.array([np.zeros((3, 3)), np.eye(3), np.diag([1.0, 1.0, 1e-3]), np.diag([2.0, 0.0, 0.0]),
                        np.outer([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])])
    m = np.ascontiguousarray(np.concatenate([a, psd, special]))
    out = np.zeros((len(m), 2))

    @ti.kernel
    def extremes(m: ti.types.ndarray(dtype=ti.f64, ndim=3), out: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        for n in range(m.shape[0]):
            mat = ti.Matrix.zero(ti.f64, 3, 3)
            for r, c in ti.static(ti.ndrange(3, 3)):
                mat[r, c] = m[n, r, c]
            low, high = stress_module.sym_eig3_extremes_f64(mat)
            out[n, 0] = low
            out[n, 1] = high

    extremes(m, out)
    exact = np.linalg.eigvalsh(m)
    size = np.abs(m).max(axis=(1, 2))
    # Where two eigenvalues nearly coincide the cubic's angle keeps half the digits
    # (~1e-8 of the size); the conditioning test compares against 1e-3 of it.
    err = np.abs(out - exact[:, [0, 2]]) / np.maximum(size, 1e-300)[:, None]
    assert err.max() <= 1e-6, err.max(axis=0)
    assert np.median(err) <= 1e-14
    decided = out[:, 0] > 1e-3 * out[:, 1]
    exact_decided = exact[:, 0] > 1e-3 * exact[:, 2]
    near = np.abs(exact[:, 0] - 1e-3 * exact[:, 2]) <= 1e-6 * size
    assert np.array_equal(decided[~near], exact_decided[~near])
