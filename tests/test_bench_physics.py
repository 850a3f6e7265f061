"""The physics page's fits (benchmarks/physics.py) on samples of known laws: the power-law
exponent by maximum likelihood, Clauset's choice of its lower bound and the log-log slope.
No simulation."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import physics


def power_law_sample(tau: float, m_min: float, n: int, seed: int = 0) -> np.ndarray:
    """``n`` masses of density ∝ m^-tau above ``m_min`` (inverse transform)."""
    u = np.random.default_rng(seed).random(n)
    return m_min * (1.0 - u) ** (-1.0 / (tau - 1.0))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_tau_mle_recovers_a_known_power_law(seed):
    masses = power_law_sample(1.7, 0.01, 2000, seed)
    tau, se, n = physics.power_law_tau(masses, 0.01)
    assert n == 2000
    assert se == pytest.approx((tau - 1.0) / np.sqrt(2000))
    assert abs(tau - 1.7) < 3.0 * se
    # Above a higher bound: the tail alone, the same exponent.
    tau_tail, se_tail, n_tail = physics.power_law_tau(masses, 0.05)
    assert n_tail == np.count_nonzero(masses >= 0.05) and abs(tau_tail - 1.7) < 3.0 * se_tail


def test_ks_distance_small_for_the_law_large_for_another():
    masses = power_law_sample(1.7, 0.01, 2000)
    assert physics.ks_distance(masses, 0.01, 1.7) < physics.ks_critical(2000)
    assert physics.ks_distance(masses, 0.01, 2.5) > 3.0 * physics.ks_critical(2000)


def test_ks_tail_finds_where_the_power_law_starts():
    """Uniform masses below 0.1 under a power law above it: Clauset's rule puts m_min near
    0.1 and recovers tau from the tail."""
    rng = np.random.default_rng(3)
    tail = power_law_sample(2.0, 0.1, 1000, seed=4)
    body = rng.uniform(0.02, 0.1, 600)
    fit = physics.ks_tail(np.concatenate([body, tail]))
    assert 0.08 <= fit.m_min <= 0.13
    assert abs(fit.tau - 2.0) < 3.0 * fit.se
    assert physics.ks_tail(tail[:10]) is None  # fewer than MIN_PIECES_TAU pieces


def test_loglog_slope_recovers_exponent_and_prefactor():
    v = np.array([25.0, 35.0, 50.0, 70.0, 100.0, 140.0, 200.0])
    slope, prefactor, se = physics.loglog_slope(v, 0.8 * v ** 0.5)
    assert slope == pytest.approx(0.5) and prefactor == pytest.approx(0.8) and se == pytest.approx(0.0, abs=1e-9)
    noisy = 0.8 * v ** 0.5 * np.exp(np.random.default_rng(0).normal(0.0, 0.05, len(v)))
    slope, _, se = physics.loglog_slope(v, noisy)
    assert se > 0.0 and abs(slope - 0.5) < 4.0 * se
