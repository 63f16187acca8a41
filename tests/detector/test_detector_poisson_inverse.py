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


def _cornish_fisher_by_hand(lam, u64):
    """The Poisson quantile by the Cornish–Fisher expansion (γ1 = λ^-1/2 the skewness, γ2 = 1/λ the excess
    kurtosis): floor(λ + √λ·w + 0.5), w = z + γ1(z² − 1)/6 + γ2(z³ − 3z)/24 − γ1²(2z³ − 5z)/36, clipped at 0.
    Returns the counts and whether λ + √λ·w + 0.5 lies within rounding of an integer."""
    from scipy.special import ndtri

    z = ndtri(u64)
    g1, g2 = 1 / np.sqrt(lam), 1 / lam
    w = z + g1 * (z**2 - 1) / 6 + g2 * (z**3 - 3 * z) / 24 - g1**2 * (2 * z**3 - 5 * z) / 36
    s = lam + np.sqrt(lam) * w + 0.5
    return np.maximum(np.floor(s), 0.0), np.abs(s - np.round(s)) < 1e-9 * np.maximum(1.0, s)


@pytest.mark.parametrize("lam", [30.5, 100.0, 1.0e4])
def test_above_the_threshold_the_counts_are_the_cornish_fisher_quantile(lam):
    rng = np.random.default_rng(3)
    u = rng.random(20_000)
    k = poisson_inverse_cdf(np.full(u.size, lam), u)
    ref, near = _cornish_fisher_by_hand(lam, u)
    assert near.mean() < 1e-3
    np.testing.assert_array_equal(k[~near], ref[~near])
    # float32 uniforms are 24-bit: each stands for the middle of its 2^-24 step
    u32 = rng.random(20_000, dtype=np.float32)
    k32 = poisson_inverse_cdf(np.full(u32.size, lam, np.float32), u32)
    ref32, near32 = _cornish_fisher_by_hand(lam, u32.astype(np.float64) + 2.0**-25)
    np.testing.assert_array_equal(k32[~near32], ref32[~near32])


def test_cornish_fisher_at_the_ends_of_the_uniforms():
    lam = 1.0e4
    # float32: u = 0 is the step [0, 2^-24), its middle 2^-25 (z = −5.4: 540 counts below λ)
    k = poisson_inverse_cdf(np.array([lam, lam], np.float32), np.array([0.0, 1 - 2.0**-24], np.float32))
    ref, _ = _cornish_fisher_by_hand(lam, np.array([2.0**-25, 1 - 2.0**-24 + 2.0**-25]))
    np.testing.assert_array_equal(k, ref)
    # float64: u is clipped to [2^-54, 1 − 1e-16] (z from −8.5 to 8.2; u = 0 the middle of its 2^-53 step): finite counts
    k = poisson_inverse_cdf(np.array([lam, lam]), np.array([0.0, 1.0]))
    ref, _ = _cornish_fisher_by_hand(lam, np.array([2.0**-54, 1 - 1e-16]))
    np.testing.assert_array_equal(k, ref)
    assert np.all(np.isfinite(k)) and k[0] < lam < k[1] < lam + 9 * 100


@pytest.mark.parametrize("lam_dt,u_dt,out_dt", [(np.float32, np.float32, np.float32), (np.float64, np.float32, np.float64),
                                                (np.float32, np.float64, np.float64), (np.float16, np.float32, np.float64),
                                                (np.float32, np.float16, np.float64)])
def test_counts_are_float32_only_when_both_inputs_are(lam_dt, u_dt, out_dt):
    for lam in (3.0, 300.0):  # the walk and Cornish–Fisher
        k = poisson_inverse_cdf(np.full(8, lam, lam_dt), np.linspace(0.05, 0.95, 8).astype(u_dt))
        assert k.dtype == out_dt


def test_the_default_threshold_30_is_still_exact():
    """λ = 29.9 ≤ 30 (the default ``small``): every count is scipy's ppf(u), away from the CDF's steps."""
    u = np.random.default_rng(8).random(50_000)
    k = poisson_inverse_cdf(np.full(u.size, 29.9), u)
    ref = stats.poisson.ppf(u, 29.9)
    near = np.min(np.abs(u[:, None] - stats.poisson.cdf(ref[:, None] + [-1, 0], 29.9)), axis=1) < 1e-12
    np.testing.assert_array_equal(k[~near], ref[~near])


def _exact_or_near(k, u, lam, eps=1e-12):
    """k equals scipy's ppf(u) wherever u is not within eps of a CDF step."""
    ref = stats.poisson.ppf(u, lam)
    near = np.min(np.abs(u[:, None] - stats.poisson.cdf(ref[:, None] + [-1, 0], lam)), axis=1) < eps
    assert near.mean() < 1e-3
    np.testing.assert_array_equal(k[~near], ref[~near])


@pytest.mark.parametrize("with_work", [False, True])
@pytest.mark.parametrize("with_out", [False, True])
def test_a_mixed_image_walks_below_the_threshold_and_uses_cornish_fisher_above(with_work, with_out):
    from rigsim.detector.scratch import Scratch

    rng = np.random.default_rng(11)
    lam = rng.choice([3.0, 30.0, 300.0], size=(60, 50))  # 30 = the threshold: still walked (exact)
    u = rng.random(lam.shape)
    out = np.full(lam.shape, -7.0) if with_out else None
    k = poisson_inverse_cdf(lam, u, out=out, work=Scratch() if with_work else None)
    assert k.shape == lam.shape and (out is None or k is out)
    for v in (3.0, 30.0):
        _exact_or_near(k[lam == v], u[lam == v], v)
    lo = lam <= 30.0
    ref, near = _cornish_fisher_by_hand(300.0, u[~lo])
    np.testing.assert_array_equal(k[~lo][~near], ref[~near])


@pytest.mark.parametrize("lam", [3.0, 300.0])
def test_counts_written_into_out(lam):
    from rigsim.detector.scratch import Scratch

    u = np.random.default_rng(12).random((40, 30))
    for work in (None, Scratch()):
        out = np.full(u.shape, -7.0)
        k = poisson_inverse_cdf(np.full(u.shape, lam), u, out=out, work=work)
        assert k is out
        if lam < 30:
            _exact_or_near(out.ravel(), u.ravel(), lam)
        else:
            ref, near = _cornish_fisher_by_hand(lam, u.ravel())
            np.testing.assert_array_equal(out.ravel()[~near], ref[~near])


def test_the_lowest_uniforms_give_the_lowest_counts():
    """Just above the threshold (λ = 31) the lowest uniforms lie 8 σ below the mean: the count is 0, never
    negative (λ + √λ·w + 0.5 < −1 there) and never above the mean: at u = 1e-300 (z = −37) the expansion's
    skewness term wins and it would give 180."""
    u = np.array([0.0, 2.0**-53, 1e-12])
    k = poisson_inverse_cdf(np.full(3, 31.0), u)
    np.testing.assert_array_equal(k, stats.poisson.ppf([2.0**-54, 2.0**-53, 1e-12], 31.0))  # 0, 0, 1
    assert np.all(np.diff(poisson_inverse_cdf(np.full(7, 31.0), np.array([0.0, 2.0**-53, 1e-12, 1e-6, 0.01, 0.5, 0.99]))) >= 0)


def test_an_empty_image_gives_an_empty_image():
    k = poisson_inverse_cdf(np.zeros((0, 5), np.float32), np.zeros((0, 5), np.float32))
    assert k.shape == (0, 5) and k.dtype == np.float32
    out = np.zeros((0, 5))
    assert poisson_inverse_cdf(np.zeros((0, 5)), np.zeros((0, 5)), out=out) is out


@pytest.mark.parametrize("lam", [0.7, 3.0, 12.0, 29.0])
def test_a_deep_tail_uniform_among_many_decided_ones_stops(lam):
    """The largest float32 uniform lies above the float32-rounded CDF's top for these λ: its walk stops where the
    pmf falls below ε/4, near the exact quantile. Among 300 values decided early it is the only one left, so it
    is walked in the sparse phase (a mutant that never stops there hangs: the run's time limit kills it)."""
    u = np.full(300, 0.5, np.float32)
    u[123] = np.float32(1 - 2.0**-24)
    k = poisson_inverse_cdf(np.full(300, lam, np.float32), u)
    assert abs(k[123] - stats.poisson.ppf(float(u[123]), lam)) <= 2
    np.testing.assert_array_equal(np.delete(k, 123), stats.poisson.ppf(0.5, lam))
