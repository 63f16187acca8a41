"""Single-pixel events: found by their shape against the PSF's, never on a star, and repaired."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

from rigsim.detector import DetectorConfig, apply_detector
from rigsim.imaging import NoiseModel
from rigsim.imaging.cosmetics import psf_peak_ratio, repair_pixels, single_pixel_events
from rigsim.render.star import render_stars


def _gauss(x, s):
    return math.exp(-x * x / (2 * s * s)) / (math.sqrt(2 * math.pi) * s)


def test_peak_ratio_is_the_pixel_integrated_gaussian_s():
    for s in (0.5, 0.77, 1.2):
        p0 = integrate.quad(_gauss, -0.5, 0.5, args=(s,))[0]
        p1 = integrate.quad(_gauss, 0.5, 1.5, args=(s,))[0]
        assert psf_peak_ratio(s) == pytest.approx(p0 / p1, rel=1e-9)


def _frame(sigma_psf, seed=0):
    """Stars at random sub-pixel positions (the brightest 20 000 e⁻) and hot pixels on a grid."""
    rng = np.random.default_rng(seed)
    H, W = 256, 256
    n = 150
    uv = np.column_stack([rng.uniform(8, W - 8, n), rng.uniform(8, H - 8, n)])
    photons = 10 ** rng.uniform(2.5, 4.5, n)
    ph = render_stars(uv, photons, (H, W), sigma_psf, background=10.0)
    cfg = DetectorConfig(quantum_efficiency=0.6, exposure_s=0.1, full_well_e=40000.0, read_noise_e=10.0,
                         dark_current_e_per_s=50.0, dsnu_e=2.0, prnu_frac=0.005, gain_dn_per_e=0.1, adc_bits=12,
                         offset_dn=100.0, sensor_seed=4)
    hot = np.zeros((H, W), bool)
    hot[5::23, 7::29] = True
    added = np.where(hot, 400.0, 0.0)                                  # 40 DN: 30× the background noise
    det = apply_detector(ph, cfg, seed=seed + 1, added_e=added)
    star_px = render_stars(uv, photons, (H, W), sigma_psf) > 1.0        # pixels holding ≥ 1 photon of a star
    return det.dn, hot, star_px, NoiseModel.from_detector(cfg)


@pytest.mark.parametrize("sigma_psf", [0.6, 0.77, 1.2])
def test_hot_pixels_are_found_and_no_star_pixel_is(sigma_psf):
    dn, hot, star_px, noise = _frame(sigma_psf)
    m = single_pixel_events(dn, noise, 0.77)                           # the nominal PSF, as the pipeline knows it
    clear = hot & ~star_px
    assert m[clear].all()                                              # every hot pixel off the stars is found
    brightest = np.zeros_like(star_px)
    brightest[star_px] = dn[star_px] > np.percentile(dn[star_px], 50)
    assert not (m & brightest & ~hot).any()                            # no star pixel is taken for one
    assert (m & ~hot).sum() <= 2                                       # and almost nothing else


def test_repair_takes_the_mean_of_the_edge_neighbours():
    img = np.full((5, 5), 100, np.uint16)
    img[2, 1], img[1, 2], img[2, 3], img[3, 2] = 90, 110, 120, 100
    img[2, 2] = 4000
    m = np.zeros((5, 5), bool)
    m[2, 2] = True
    out = repair_pixels(img, m)
    assert out[2, 2] == 105 and out.dtype == np.uint16
    assert (out[~m] == img[~m]).all()


def test_the_sequence_pattern_holds_the_defects_not_the_stars_nor_a_smooth_background():
    from rigsim.imaging.cosmetics import sequence_fixed_pattern

    rng = np.random.default_rng(5)
    H, W, n = 128, 160, 12
    hot = np.zeros((H, W), bool)
    hot[7::17, 5::13] = True
    gradient = np.linspace(0.0, 40.0, W)[None, :] * np.ones((H, 1))     # stray light fixed on the detector
    frames = []
    for k in range(n):                                                   # stars move 20 px per frame
        uv = np.column_stack([rng.uniform(5, W - 5, 40), rng.uniform(5, H - 5, 40)])
        stars = render_stars(uv, np.full(40, 3000.0), (H, W), 0.8)
        frames.append(np.rint(100.0 + gradient + stars + 25.0 * hot + rng.normal(0.0, 1.5, (H, W))))
    p = sequence_fixed_pattern(frames)
    inner = np.zeros_like(hot)
    inner[2:-2, 2:-2] = True
    assert (p[hot & inner] > 20.0).all() and (np.abs(p[hot & inner] - 25.0) < 3.0).all()
    assert np.count_nonzero(p[~hot]) <= 3                                # neither the gradient nor the stars
    with pytest.raises(ValueError, match="at least 3 frames"):
        sequence_fixed_pattern(frames[:2])
