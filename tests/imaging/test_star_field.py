"""Star extraction on a vignetted, glowing sky (rigsim.imaging.star_field).

The synthetic frames are drawn here by supersampling each star's Gaussian on an 8 × 8 grid per
pixel (not the erf pixel integrals the fit uses), on a sky that falls by 35 % to the corners and
rises along one side, with Poisson electrons of a known gain and Gaussian read noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rigsim.imaging import Flag
from rigsim.imaging.detect import find_spots
from rigsim.imaging.star_field import extract_star_field, photon_transfer, sky_map

H, W = 240, 320
GAIN = 0.5     # DN per electron
READ_E = 6.0
OFFSET = 100.0
PSF = 0.9      # px


def _sky_e(h=H, w=W):
    v, u = np.mgrid[0:h, 0:w]
    r2 = ((u - w / 2) ** 2 + (v - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    return 600.0 * (1.0 - 0.35 * r2) * (1.0 + 2.0 * u / w)  # vignetting, and a glow rising 3× towards +u


def _stars_e(u, v, flux_e, sigma=PSF, h=H, w=W, sub=8):
    """Each star's electrons per pixel: its Gaussian sampled at sub × sub points inside every pixel of
    a ±5σ box (a second derivation: the fit integrates the Gaussian with erf)."""
    img = np.zeros((h, w))
    o = (np.arange(sub) + 0.5) / sub - 0.5
    for uu, vv, ff in zip(u, v, flux_e):
        r = int(math.ceil(5 * sigma)) + 1
        u0, v0 = int(round(uu)), int(round(vv))
        ys, xs = np.arange(max(0, v0 - r), min(h, v0 + r + 1)), np.arange(max(0, u0 - r), min(w, u0 + r + 1))
        yy = ys[:, None, None, None] + o[None, None, :, None]
        xx = xs[None, :, None, None] + o[None, None, None, :]
        g = np.exp(-((xx - uu) ** 2 + (yy - vv) ** 2) / (2 * sigma**2)) / (2 * math.pi * sigma**2)
        img[np.ix_(ys, xs)] += ff * g.mean(axis=(2, 3))
    return img


def _frame(rng, u, v, flux_e, *, sat_dn=4095):
    e = rng.poisson(_sky_e() + _stars_e(u, v, flux_e)).astype(float)
    dn = OFFSET + GAIN * (e + rng.normal(0.0, READ_E, e.shape))
    return np.clip(np.round(dn), 0, sat_dn).astype(np.uint16)


def _field(rng, n=60, margin=12):
    u = rng.uniform(margin, W - margin, n)
    v = rng.uniform(margin, H - margin, n)
    keep = np.ones(n, bool)  # no two stars within 10 px, a fitting window (blends are tested on their own)
    for i in range(n):
        if keep[i] and np.any(np.hypot(u[i + 1:] - u[i], v[i + 1:] - v[i]) < 10):
            keep[i + 1:][np.hypot(u[i + 1:] - u[i], v[i + 1:] - v[i]) < 10] = False
    u, v = u[keep], v[keep]
    flux = 10 ** rng.uniform(np.log10(300), np.log10(30000), u.size)  # electrons: SNR ~3 to ~250
    return u, v, flux


def _snr_matched(flux_e, sky_e):
    """A star's matched-filter SNR in white noise: F / sqrt(4π σ² σ_px²) with σ_px² = sky + read²."""
    return flux_e / np.sqrt(4 * math.pi * PSF**2 * (sky_e + READ_E**2))


def _match(found_uv, u, v, tol=1.0):
    d = np.hypot(found_uv[:, None, 0] - u[None], found_uv[:, None, 1] - v[None])
    j = np.argmin(d, axis=1)
    ok = d[np.arange(len(found_uv)), j] < tol
    return j, ok


def test_stars_on_a_vignetted_glowing_sky_are_found_to_the_noise_floor_and_centred_to_their_sigma():
    rng = np.random.default_rng(11)
    pulls, found_snr, missed_snr, false = [], [], [], 0
    for _ in range(4):
        u, v, flux = _field(rng)
        img = _frame(rng, u, v, flux)
        sf = extract_star_field(img, psf_sigma_px=1.0, gain_dn_per_e=GAIN, mesh_px=32)
        ok = (sf.flags & int(Flag.INVALID | Flag.EDGE | Flag.BLENDED | Flag.SATURATED)) == 0
        j, m = _match(sf.uv[ok], u, v)
        false += int((~m).sum())
        snr = _snr_matched(flux, _sky_e()[v.astype(int), u.astype(int)])
        hit = np.zeros(u.size, bool)
        hit[j[m]] = True
        found_snr += list(snr[hit])
        missed_snr += list(snr[~hit])
        du = (sf.uv[ok][m] - np.stack([u[j[m]], v[j[m]]], 1)) / sf.sigma_uv[ok][m]
        pulls.append(du)
    pulls = np.concatenate(pulls)
    missed = np.array(missed_snr)
    assert not np.any(missed > 8.0), f"stars of matched-filter SNR {missed[missed > 8]} missed"
    assert false <= 2, f"{false} detections that are no star (5σ: expected ~0)"
    rms = np.sqrt(np.mean(pulls**2, axis=0))
    assert np.all((rms > 0.8) & (rms < 1.25)), f"error/σ rms {rms} (u, v) over {len(pulls)} stars"
    # a single background level and noise (the old extraction) misses faint stars where the sky is dark
    res, _ = find_spots(_frame(np.random.default_rng(12), *_field(np.random.default_rng(12))), method="gauss",
                        sigma_px=PSF, threshold_sigma=5.0)
    assert len(res) < len(found_snr) / 4


def _expected_significance(flux_e, u, v):
    """A faint star's matched-filter SNR, computed here: the PSF (σ 0.9 px) sampled per pixel, the filter a
    unit Gaussian of σ 1 px, white sky + read noise: F Σ k g / (σ_px sqrt(Σ k²))."""
    x = np.arange(-8, 9)
    g = np.exp(-x**2 / (2 * PSF**2)); g /= g.sum()
    k = np.exp(-x**2 / 2.0); k /= k.sum()
    gain = float(np.sum(np.outer(k, k) * np.outer(g, g))) / math.sqrt(float(np.sum(np.outer(k, k) ** 2)))
    sky = _sky_e()[v.astype(int), u.astype(int)]
    return flux_e * gain / np.sqrt(sky + READ_E**2)


def test_the_significance_follows_the_local_noise_across_the_field():
    """Where the glow triples the sky, the noise is 1.7× the dark side's: a star's significance must
    still be its own SNR there (a single noise value for the frame would not give that)."""
    rng = np.random.default_rng(21)
    ratio, side = [], []
    for _ in range(3):
        u, v, flux = _field(rng)
        sf = extract_star_field(_frame(rng, u, v, flux), psf_sigma_px=1.0, gain_dn_per_e=GAIN, mesh_px=32)
        ok = (sf.flags & int(Flag.INVALID | Flag.EDGE | Flag.BLENDED | Flag.SATURATED)) == 0
        j, m = _match(sf.uv[ok], u, v)
        want = _expected_significance(flux[j[m]], u[j[m]], v[j[m]])
        faint = (want > 8) & (want < 25)  # the stars' own shot noise stays small
        ratio += list(sf.significance[ok][m][faint] / want[faint])
        side += list(u[j[m]][faint] / W)
    ratio, side = np.array(ratio), np.array(side)
    dark, bright = np.median(ratio[side < 0.35]), np.median(ratio[side > 0.65])
    assert 0.8 < dark < 1.05 and 0.8 < bright < 1.05, (dark, bright)
    assert abs(bright / dark - 1) < 0.1, (dark, bright)


def test_saturated_and_blended_stars_are_flagged_and_a_saturated_core_is_one_star():
    rng = np.random.default_rng(3)
    # a star far above the ADC's top; a pair 5.3 px apart (both found), a pair 3.4 px apart (one peak
    # after the filter: found once, flagged), an isolated star
    u = np.array([60.3, 200.0, 205.2, 150.0, 100.0, 103.2])
    v = np.array([80.7, 120.0, 121.1, 60.0, 170.0, 171.1])
    flux = np.array([4e6, 8000.0, 6000.0, 5000.0, 8000.0, 6000.0])
    sf = extract_star_field(_frame(rng, u, v, flux), psf_sigma_px=1.0, gain_dn_per_e=GAIN, saturation=4095, mesh_px=32)
    j, m = _match(sf.uv, u, v, tol=1.5)
    assert m.all() and sorted(set(j.tolist()) & {0, 1, 2, 3}) == [0, 1, 2, 3], (sf.uv, sf.flags)
    fl = {int(jj): int(f) for jj, f in zip(j, sf.flags)}
    assert fl[0] & int(Flag.SATURATED)
    assert fl[1] & int(Flag.BLENDED) and fl[2] & int(Flag.BLENDED)
    assert not fl[3] & int(Flag.BLENDED | Flag.SATURATED)
    close = [f for jj, f in fl.items() if jj in (4, 5)]
    assert close and all(f & int(Flag.BLENDED) for f in close)
    assert len(sf) == len(set(j.tolist()))  # the saturated core is one star, not a ring of maxima


def test_the_sky_map_follows_vignetting_and_glow():
    rng = np.random.default_rng(5)
    img = _frame(rng, *_field(rng))
    m = sky_map(img, mesh_px=32)
    truth = OFFSET + GAIN * _sky_e()
    inner = (slice(32, H - 32), slice(32, W - 32))  # a mesh in from the edges
    rel = (m.level[inner] - truth[inner]) / (truth[inner] - OFFSET)
    assert np.max(np.abs(rel)) < 0.03
    sd_true = np.sqrt(GAIN**2 * (_sky_e() + READ_E**2) + 1 / 12)
    assert np.max(np.abs(m.rms[inner] / sd_true[inner] - 1)) < 0.12


def test_photon_transfer_recovers_the_gain_from_one_frame_s_own_sky():
    rng = np.random.default_rng(8)
    pt = photon_transfer(_frame(rng, *_field(rng, n=20)), mesh_px=16)
    assert pt is not None
    assert abs(pt.gain_dn_per_e - GAIN) < max(3 * pt.gain_sigma, 0.05), pt
    # the variance it predicts at the sky's mean level: K (L − offset) + (K σ_read)² + 1/12
    L = float(np.mean(OFFSET + GAIN * _sky_e()))
    want = GAIN * (L - OFFSET) + (GAIN * READ_E) ** 2 + 1 / 12
    assert abs(pt.gain_dn_per_e * L + pt.intercept_dn2 - want) < 0.05 * want, pt
    flat = np.full((H, W), 300, np.uint16)
    assert photon_transfer(flat) is None  # no spread of levels: no gain


@pytest.mark.parametrize("bad", [np.zeros((0, 5)), np.zeros((3, 4, 5))])
def test_bad_shapes_are_refused(bad):
    with pytest.raises(ValueError):
        extract_star_field(bad)


def test_an_empty_sky_gives_no_star():
    rng = np.random.default_rng(1)
    img = np.round(OFFSET + GAIN * rng.poisson(_sky_e())).astype(np.uint16)
    sf = extract_star_field(img, psf_sigma_px=1.0, gain_dn_per_e=GAIN, mesh_px=32)
    assert len(sf) <= 1
