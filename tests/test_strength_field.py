"""The strength field of a material (Material.strength_correlation_length): its one-point statistics and its
correlation against the analytic ones, and bonds that take it from where they are, not from the spacing or from where
the body sits (kernels/peridynamics/bonds.py, strength_field_factor)."""

import math

import numpy as np
import pytest
from bond_helpers import bond_ends
from scipy.spatial import cKDTree
from scipy.special import log_ndtr

import pdsim
from pdsim.errors import ParameterError
from pdsim.materials import strength_factors
from pdsim.peridynamics.model import build_model

M = 4.0  # Weibull modulus
ELL = 0.05  # correlation length [m]
SC = 0.005


def _material(seed=3, ell=ELL, m=M):
    return pdsim.Material(
        density=2500.0,
        youngs_modulus=7.0e6,
        poisson_ratio=0.22,
        critical_stretch=SC,
        strength_weibull_modulus=m,
        strength_seed=seed,
        strength_correlation_length=ell,
    )


def _weibull_of_gaussian(g, m):
    """F(g) = (-ln(1 - Phi(g)) / ln 2)^(1 / m), from scipy (independent of the kernel's float32 tails)."""
    return (-log_ndtr(-g) / math.log(2.0)) ** (1.0 / m)


def _analytic_factor_correlation(rho, m, order=80):
    """Correlation of F(X) and F(Y) for standard normals X, Y of correlation rho (Gauss-Hermite quadrature)."""
    a, w = np.polynomial.hermite.hermgauss(order)
    x = math.sqrt(2.0) * a[:, None]
    y = rho * x + math.sqrt(1.0 - rho * rho) * math.sqrt(2.0) * a[None, :]
    ww = w[:, None] * w[None, :] / math.pi
    fx, fy = _weibull_of_gaussian(x, m), _weibull_of_gaussian(y, m)
    mean = np.sum(w * _weibull_of_gaussian(math.sqrt(2.0) * a, m)) / math.sqrt(math.pi)
    second = np.sum(w * _weibull_of_gaussian(math.sqrt(2.0) * a, m) ** 2) / math.sqrt(math.pi)
    return (np.sum(ww * fx * fy) - mean * mean) / (second - mean * mean)


def test_field_statistics_match_the_analytic_ones():
    """Over 16 seeds and 4000 random points each in a 2 m cube: the factors' mean and variance equal the Weibull
    marginal's (lambda Gamma(1 + 1/m), lambda^2 (Gamma(1 + 2/m) - Gamma(1 + 1/m)^2), lambda = ln(2)^(-1/m)) within 1 %
    and 4 %, the median is 1 within 1.5 %, and the correlation of the factors at lags 0.5, 1 and 2 l (random
    directions) equals the analytic one of a Gaussian field of correlation exp(-r^2 / (2 l^2)) mapped to that marginal
    within 0.06 (3 standard errors of the 16 seeds' mean with 64 modes). A field with the correlation length doubled
    fails the correlation check at lag l (so the check can fail)."""
    rng = np.random.default_rng(0)
    lags = (0.5, 1.0, 2.0)
    all_f, pairs = [], {lag: [] for lag in lags}
    pairs_wrong = []
    for seed in range(16):
        base = rng.uniform(-1.0, 1.0, (4000, 3))
        direction = rng.standard_normal((4000, 3))
        direction /= np.linalg.norm(direction, axis=1)[:, None]
        pts = [base] + [base + lag * ELL * direction for lag in lags]
        f = strength_factors(_material(seed), np.concatenate(pts)).reshape(len(pts), -1)
        all_f.append(f[0])
        for i, lag in enumerate(lags):
            pairs[lag].append((f[0], f[i + 1]))
        fw = strength_factors(_material(seed, ell=2.0 * ELL), np.concatenate([base, base + ELL * direction]))
        pairs_wrong.append((fw[:4000], fw[4000:]))
    f = np.concatenate(all_f)
    lam = math.log(2.0) ** (-1.0 / M)
    mean = lam * math.gamma(1.0 + 1.0 / M)
    var = lam * lam * (math.gamma(1.0 + 2.0 / M) - math.gamma(1.0 + 1.0 / M) ** 2)
    assert f.mean() == pytest.approx(mean, rel=0.01)
    assert f.var() == pytest.approx(var, rel=0.04)
    assert np.median(f) == pytest.approx(1.0, abs=0.015)

    def corr(p):
        a = np.concatenate([x for x, _ in p])
        b = np.concatenate([y for _, y in p])
        return ((a - mean) * (b - mean)).mean() / var

    for lag in lags:
        expected = _analytic_factor_correlation(math.exp(-0.5 * lag * lag), M)
        assert corr(pairs[lag]) == pytest.approx(expected, abs=0.06), lag
    at_ell = _analytic_factor_correlation(math.exp(-0.5), M)
    assert abs(corr(pairs_wrong) - at_ell) > 0.1  # the doubled length: the check fails


def _bond_midpoints_and_factors(material, spacing, *, centre=(0.0, 0.0, 0.0)):
    """(bond midpoints relative to the shape's centre [m], bond factors s / s_c) of a 12 cm box at ``spacing``."""
    shape = pdsim.box((0.12, 0.12, 0.12), center=centre)
    body = pdsim.PeridynamicBody(shape, material, spacing)
    model = build_model([body], "cpu", origin=body.rest_positions.mean(axis=0))
    k, j = bond_ends(model)
    local = body.rest_positions - np.asarray(centre)
    mid = 0.5 * (local[k] + local[j])
    return mid, model.bond_critical_stretch.numpy()[: len(k)].astype(np.float64) / SC


def test_bonds_take_the_field_at_their_midpoint_at_every_spacing_and_place():
    """A 12 cm box at h = 2 cm and 1 cm: every bond's factor is the field at its midpoint (1e-4 relative: float32
    bond midpoints), bonds whose midpoints coincide at the two spacings (several hundred) hold the same factor within
    1e-4, and the box placed at (1000, -500, 250) m gives the bonds of the box at the origin to 1e-5. One draw per bond
    (no correlation length) gives unrelated factors at the two spacings (so the check can fail)."""
    mat = _material()
    mid_h, f_h = _bond_midpoints_and_factors(mat, 0.02)
    mid_f, f_f = _bond_midpoints_and_factors(mat, 0.01)
    np.testing.assert_allclose(f_h, strength_factors(mat, mid_h), rtol=1.0e-4)
    np.testing.assert_allclose(f_f, strength_factors(mat, mid_f), rtol=1.0e-4)
    dist, idx = cKDTree(mid_f).query(mid_h)
    same = dist < 1.0e-7
    assert same.sum() > 300
    np.testing.assert_allclose(f_f[idx[same]], f_h[same], rtol=1.0e-4)
    assert np.std(f_h) > 0.1  # the factors do scatter

    _, f_far = _bond_midpoints_and_factors(mat, 0.02, centre=(1000.0, -500.0, 250.0))
    np.testing.assert_allclose(f_far, f_h, rtol=1.0e-5)

    per_bond = pdsim.Material(
        density=2500.0, youngs_modulus=7.0e6, poisson_ratio=0.22, critical_stretch=SC, strength_weibull_modulus=M
    )
    mid_h, g_h = _bond_midpoints_and_factors(per_bond, 0.02)
    mid_f, g_f = _bond_midpoints_and_factors(per_bond, 0.01)
    dist, idx = cKDTree(mid_f).query(mid_h)
    same = dist < 1.0e-7
    assert np.median(np.abs(g_f[idx[same]] / g_h[same] - 1.0)) > 0.05


def test_field_options_are_validated():
    with pytest.raises(ParameterError, match="strength_correlation_length"):
        pdsim.Material(
            density=1.0, youngs_modulus=1.0, poisson_ratio=0.2, critical_stretch=0.01, strength_correlation_length=0.1
        )
    with pytest.raises(ParameterError, match="strength_correlation_length"):
        _material(ell=0.0)
    with pytest.raises(ParameterError, match="sampling_jitter"):
        pdsim.Material(density=1.0, youngs_modulus=1.0, poisson_ratio=0.2, sampling_jitter=0.5)
    with pytest.raises(ParameterError, match="sampling_jitter"):
        pdsim.Material(density=1.0, youngs_modulus=1.0, poisson_ratio=0.2, critical_stretch=0.01, sampling_jitter=1.5)
    with pytest.raises(ParameterError, match="material"):
        strength_factors(pdsim.presets.clay(), np.zeros((1, 3)))
