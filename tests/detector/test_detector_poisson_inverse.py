"""The detector's Poisson sampler: exact distribution, one uniform per pixel, stable under tiny λ changes."""

import numpy as np
import pytest
from scipy import stats

from rigsim.detector import DetectorConfig, apply_detector
from rigsim.detector.model import poisson_inverse_cdf


@pytest.mark.parametrize("lam", [0.0, 0.3, 4.0, 29.9, 30.1, 500.0, 2.0e4])
def test_moments_and_pmf(lam):
    rng = np.random.default_rng(1)
    n = 200_000
    k = poisson_inverse_cdf(np.full(n, lam), rng.random(n))
    assert np.all(k == np.round(k)) and k.min() >= 0
    se = np.sqrt(max(lam, 1e-12) / n)
    assert abs(k.mean() - lam) < 5 * se + 1e-12
    if lam > 0:
        assert k.var() == pytest.approx(lam, rel=5 * np.sqrt(2 / n) + 0.01)
    if 0 < lam < 10:
        counts = np.bincount(k.astype(int), minlength=25)[:25]
        pmf = stats.poisson.pmf(np.arange(25), lam) * n
        ok = pmf > 50
        chi2 = np.sum((counts[ok] - pmf[ok]) ** 2 / pmf[ok])
        assert chi2 < stats.chi2.ppf(0.999, ok.sum() - 1)


def test_frame_is_stable_under_float_noise_in_the_photon_image():
    """ptracer reproduces photon images only to ~1e-7: the DN frame must not change."""
    rng = np.random.default_rng(0)
    ph = rng.uniform(0, 3e4, (256, 256))
    ph[::7, ::5] = 0.2
    jitter = ph * (1 + rng.uniform(-2e-7, 2e-7, ph.shape))
    cfg = DetectorConfig()
    a = apply_detector(ph, cfg, seed=9).dn
    b = apply_detector(jitter, cfg, seed=9).dn
    assert np.mean(a != b) < 1e-3  # only pixels within ~1e-7 of a CDF step (or a DN rounding edge) may move
    assert np.abs(a.astype(int) - b.astype(int)).max() <= 1


@pytest.mark.parametrize("lam", [0.1, 1.0, 9.0, 30.0, 100.0, 1.0e4])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_distribution_against_scipy(lam, dtype):
    """The sampler apply_detector uses (float32) and the float64 one: mean, variance, chi² of the
    histogram and Kolmogorov–Smirnov distance against scipy.stats.poisson, at the 0.1 % level."""
    n = 400_000
    rng = np.random.default_rng(int(lam * 10) + 7)
    k = poisson_inverse_cdf(np.full(n, lam, dtype), rng.random(n, dtype=dtype)).astype(np.float64)
    assert k.dtype == np.float64 and np.all(k == np.round(k)) and k.min() >= 0
    assert abs(k.mean() - lam) < 4 * np.sqrt(lam / n)
    assert k.var() == pytest.approx(lam, rel=4 * np.sqrt((2 + 1 / lam) / n))  # var of s²: λ²(2/n) + λ/n
    lo, hi = stats.poisson.ppf([1e-4, 1 - 1e-4], lam)
    inner = np.arange(lo, hi + 1)                                   # values; the ends collect the tails
    cdf = stats.poisson.cdf(inner, lam)
    expect = np.diff(np.concatenate([[0.0], cdf[:-1], [1.0]])) * n
    counts = np.histogram(k, np.concatenate([[-np.inf], inner[:-1] + 0.5, [np.inf]]))[0]
    ok = expect > 20
    chi2 = np.sum((counts[ok] - expect[ok]) ** 2 / expect[ok])
    assert chi2 < stats.chi2.ppf(0.999, ok.sum() - 1)
    ecdf = np.searchsorted(np.sort(k), inner, side="right") / n
    assert np.max(np.abs(ecdf - cdf)) < 1.95 / np.sqrt(n)              # KS 0.1 % critical value


@pytest.mark.parametrize("lam", [0.05, 0.7, 3.0, 12.0, 29.0])
def test_walk_is_the_exact_inverse(lam):
    """Below the Cornish–Fisher threshold every count is scipy's ppf(u), except where u lies within
    the CDF's rounding (float32: 1e-6) of a step."""
    rng = np.random.default_rng(5)
    for dtype, eps in ((np.float32, 1e-6), (np.float64, 1e-12)):
        u = rng.random(100_000, dtype=dtype)
        k = poisson_inverse_cdf(np.full(u.size, lam, dtype), u)
        ref = stats.poisson.ppf(u.astype(np.float64), lam)
        near = np.min(np.abs(u.astype(np.float64)[:, None] - stats.poisson.cdf(ref[:, None] + [-1, 0], lam)), axis=1) < eps
        assert np.mean(near) < 1e-3
        np.testing.assert_array_equal(k[~near], ref[~near])
    # the largest float32 uniform: a finite deep-tail count near the exact quantile
    top = np.float32(1 - 2.0 ** -24)
    k = poisson_inverse_cdf(np.array([lam], np.float32), np.array([top]))[0]
    assert abs(k - stats.poisson.ppf(float(top), lam)) <= 2
