"""Hot pixels and cosmic-ray hits against their closed forms.

Statistical tolerances are 5 standard errors of the quantity tested (binomial for a count of hot
pixels, σ/√n for a mean); the seeds are fixed, so each test is deterministic.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from rigsim.detector.defects import (
    CosmicRayHits,
    _moyal,
    deposit_cosmic_rays,
    draw_cosmic_rays,
    hot_pixel_electrons,
    hot_pixel_rates,
)

HOT = {"fraction": 0.01, "threshold_e_per_s": 1000.0, "mean_excess_e_per_s": 3000.0}


def test_hot_pixels_have_the_stated_share_and_dark_current():
    H, W = 512, 640
    rate = hot_pixel_rates(7, W, (0, H), (0, W), **HOT)
    n, hot = H * W, rate > 0
    k = int(hot.sum())
    assert abs(k - 0.01 * n) < 5 * math.sqrt(n * 0.01 * 0.99)
    excess = rate[hot] - 1000.0
    assert excess.min() >= 0.0
    assert abs(excess.mean() - 3000.0) < 5 * 3000.0 / math.sqrt(k)       # exponential: σ = mean
    assert stats.kstest(excess / 3000.0, "expon").pvalue > 1e-3
    # no spatial structure: the hot pixels of the left and right halves are as many within binomial noise
    left, right = int(hot[:, : W // 2].sum()), int(hot[:, W // 2:].sum())
    assert abs(left - right) < 5 * math.sqrt(k)


def test_hot_pixels_are_a_property_of_the_sensor_not_of_the_window():
    H, W = 300, 400
    full = hot_pixel_rates(3, W, (0, H), (0, W), **HOT)
    win = hot_pixel_rates(3, W, (120, 170), (33, 301), **HOT)
    np.testing.assert_array_equal(win, full[120:170, 33:301])
    other = hot_pixel_rates(4, W, (0, H), (0, W), **HOT)
    assert np.count_nonzero((full > 0) & (other > 0)) < 0.05 * np.count_nonzero(full)   # another sensor
    assert not hot_pixel_rates(3, W, (0, H), (0, W), **{**HOT, "fraction": 0.0}).any()


def test_hot_pixel_electrons_are_poisson_with_the_rate_times_exposure():
    rates = np.full((200, 200), 0.0)
    rates[::2] = 4000.0
    rng = np.random.default_rng(1)
    e = hot_pixel_electrons(rates, 0.05, rng)
    hot = e[::2]
    assert not e[1::2].any()
    assert abs(hot.mean() - 200.0) < 5 * math.sqrt(200.0 / hot.size)
    assert abs(hot.var() - 200.0) < 5 * 200.0 * math.sqrt(2.0 / hot.size)
    np.testing.assert_array_equal(hot_pixel_electrons(rates, 0.05, None, noiseless=True), rates * 0.05)


def _hits(n_frames=400, **kw):
    rng = np.random.default_rng(11)
    p = {"pixel_pitch_um": 15.0, "exposure_s": 1.0, "flux_per_cm2_s": 50.0, "depth_um": 10.0, "charge_e_per_um": 60.0,
             "landau_width": 0.0}
    p.update(kw)
    return [draw_cosmic_rays(rng, (1024, 1024), **p) for _ in range(n_frames)]


def test_cosmic_ray_count_length_and_charge_follow_the_isotropic_flux():
    frames = _hits()
    area = (1024 * 15e-4) ** 2                                             # 2.36 cm²
    counts = np.array([len(h) for h in frames])
    lam = 50.0 * area
    assert abs(counts.mean() - lam) < 5 * math.sqrt(lam / counts.size)
    assert abs(counts.var() - lam) < 5 * lam * math.sqrt(2.0 / counts.size)
    start = np.concatenate([h.start_uv for h in frames])
    end = np.concatenate([h.end_uv for h in frames])
    q = np.concatenate([h.charge_e for h in frames])
    n = q.size
    length_um = np.hypot(*(end - start).T) * 15.0
    # cos θ = √U: E[tan θ] = π/2, E[1/cos θ] = 2; both variances grow like ln(1/cos θ_min) = ln 10⁴
    assert abs(length_um.mean() / 10.0 - math.pi / 2) < 5 * 4.0 / math.sqrt(n)
    assert abs(q.mean() / 600.0 - 2.0) < 5 * 4.0 / math.sqrt(n)
    # the shortest possible track is a vertical one: the charge of the depth alone
    assert q.min() >= 600.0 - 1e-9
    # path length and charge are one geometry: Q = q·√(d² + ℓ²)
    np.testing.assert_allclose(q, 60.0 * np.hypot(10.0, length_um), rtol=1e-9)
    assert (start >= -0.5).all() and (start[:, 0] < 1023.5).all() and (start[:, 1] < 1023.5).all()


def test_landau_fluctuation_is_moyal_with_its_mode_at_the_most_probable_charge():
    x = _moyal(np.random.default_rng(2), 20000)
    assert stats.kstest(x, "moyal").pvalue > 1e-3                        # scipy's Moyal: a second method
    frames = _hits(100, landau_width=0.25)
    q = np.concatenate([h.charge_e for h in frames])
    length_um = np.concatenate([np.hypot(*(h.end_uv - h.start_uv).T) for h in frames]) * 15.0
    fluct = q / (60.0 * np.hypot(10.0, length_um))                       # the deposit over the most probable one
    assert stats.kstest((fluct - 1.0) / 0.25, "moyal").pvalue > 1e-3
    assert abs(np.median(fluct) - (1 + 0.25 * stats.moyal.median())) < 0.01


def test_deposited_charge_is_the_tracks_charge_and_windows_agree():
    hits = CosmicRayHits(np.array([[10.2, 20.7], [100.0, 5.0], [50.0, 80.0]]),
                         np.array([[40.9, 31.1], [100.0, 25.0], [50.3, 80.1]]), np.array([1000.0, 800.0, 600.0]))
    full = deposit_cosmic_rays(hits, (0, 128), (0, 128))
    assert math.isclose(full.sum(), 2400.0, rel_tol=1e-12)
    col = full[:, 100]
    assert math.isclose(col.sum(), 800.0, rel_tol=1e-12)                  # a track along a column stays in it
    assert np.count_nonzero(col) == 21                                    # v = 5 … 25
    assert math.isclose(full[80, 50], 600.0, rel_tol=1e-12)               # a short track: one pixel
    np.testing.assert_array_equal(deposit_cosmic_rays(hits, (15, 60), (30, 110)), full[15:60, 30:110])
