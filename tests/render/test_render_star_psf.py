"""The traced PSF (``[effects.traced_psf]``) in rendered star frames: each star's light lands where its
traced PSF puts it (the truth position plus the traced shift), all of it, and with the effect off
the frame is bit-identical to the Gaussian frame of before."""

from __future__ import annotations

import numpy as np
import pytest

from rigsim.render.frame import digitise
from rigsim.render.star import render_frame, render_stars, render_stars_psf
from rigsim.render.star_effects import star_frame_effects, traced_psf_table, traced_star_psfs
from rigsim.truth.star import StarSky


@pytest.fixture(scope="module")
def traced(star_rig, star_sky):
    rig = star_rig.model_copy(update={"effects": star_rig.effects.only(["traced_psf"])})
    return StarSky(rig, sky=star_sky.sky)


def _isolated(uv, shape_hw, r):
    """Stars with no other star within 2r + 2 px and their whole window on the detector."""
    H, W = shape_hw
    d = np.hypot(*(uv[:, None, :] - uv[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    inside = (uv[:, 0] > r + 2) & (uv[:, 0] < W - r - 3) & (uv[:, 1] > r + 2) & (uv[:, 1] < H - r - 3)
    return np.flatnonzero((d.min(axis=1) > 2 * r + 2) & inside)


def _centroids(img, uv, idx, r):
    out = []
    for i in idx:
        u0, v0 = np.floor(uv[i] + 0.5).astype(int)
        win = img[v0 - r:v0 + r + 1, u0 - r:u0 + r + 1]
        vv, uu = np.mgrid[v0 - r:v0 + r + 1, u0 - r:u0 + r + 1]
        out.append([(win * uu).sum() / win.sum(), (win * vv).sum() / win.sum()])
    return np.array(out)


def test_with_the_effect_off_the_frame_is_the_gaussian_frame_bit_for_bit(star_rig, star_sky):
    assert not star_rig.effects.traced_psf.enabled
    R = np.eye(3)
    fr = render_frame(star_sky, R, seed=11, fits_header=False, keep_photons=True)
    s = star_rig.sensor
    truth = star_sky.field(R, margin_px=-np.ceil(5 * s.psf_sigma_px))
    photons = render_stars(truth.uv_substeps, truth.photons, truth.shape_hw, s.psf_sigma_px,
                           background=truth.background_photons_per_px)
    assert star_frame_effects(star_sky, seed=11).photons is None
    want = digitise(photons, s.detector, seed=11, truth={}, render={})
    np.testing.assert_array_equal(fr.photons, photons)
    np.testing.assert_array_equal(fr.dn, want.dn)
    assert "effects" not in fr.sidecar["truth"]


def test_each_star_lands_at_its_truth_position_plus_the_traced_shift(star_rig, star_sky, traced):
    R = np.eye(3)
    off = render_frame(star_sky, R, seed=3, noiseless=True, keep_photons=True, fits_header=False)
    on = render_frame(traced, R, seed=3, noiseless=True, keep_photons=True, fits_header=False)
    truth = on.truth_object
    shift = np.array(on.sidecar["truth"]["effects"]["traced_psf"]["centroid_shift_px"])
    r = traced_psf_table(traced.rig).radius_px + 1
    idx = _isolated(truth.uv, truth.shape_hw, r)
    assert idx.size >= 10
    bg = truth.background_photons_per_px
    c_on = _centroids(on.photons - bg, truth.uv, idx, r)
    c_off = _centroids(off.photons - bg, truth.uv, idx, r)     # the same stars (the traced frame lists more off-detector ones)
    # the Gaussian frame puts each star at its truth position (its pixel-phase error is
    # ~exp(−2π²σ²)/π = 3e-6 px for σ = 0.77 px); the traced frame moves it by the traced shift. The
    # traced PSF's own pixel-phase error (its sharp defocus rim) scatters each star by ~0.01 px about
    # it, with zero mean over pixel phases: the regression of the measured shift on the traced one
    # has slope 1 to its standard error (≈ 0.005 here; 4 of them allowed)
    np.testing.assert_allclose(c_off, truth.uv[idx], atol=1e-5)
    d, s = c_on - c_off, shift[idx]
    slope = (d * s).sum() / (s * s).sum()
    se = np.sqrt(np.mean((d - s) ** 2) / (s * s).sum())
    assert abs(slope - 1.0) < 4 * se and se < 0.05
    assert np.sqrt(np.mean((d - s) ** 2)) < 0.05
    assert np.abs(s).max() > 0.1                        # the traced shift is there to measure
    # each star's window is its traced PSF at the truth position, pixel for pixel (a brute-force
    # rasterisation: each PSF bin cut into 20 × 20 points)
    psfs, _, table = traced_star_psfs(traced.rig, truth)
    M, os_, Rp = 20, table.oversample, table.radius_px
    n = psfs.shape[-1]
    sub = (np.arange(n * M) + 0.5) / (os_ * M) - Rp
    for i in idx[:5]:
        ref = np.zeros(truth.shape_hw)
        cols = np.floor(truth.uv[i, 0] + sub + 0.5).astype(int)
        rows = np.floor(truth.uv[i, 1] + sub + 0.5).astype(int)
        Pm = np.repeat(np.repeat(psfs[i], M, axis=0), M, axis=1) / M**2 * truth.photons[i]
        np.add.at(ref, (rows[:, None], cols[None, :]), Pm)
        v0, u0 = rows.min(), cols.min()
        win = (on.photons - bg)[v0:rows.max() + 1, u0:cols.max() + 1]
        assert np.abs(win - ref[v0:rows.max() + 1, u0:cols.max() + 1]).max() < 0.02 * win.max()
    # and the light is all there: each isolated star's window holds its photons
    for i in idx:
        u0, v0 = np.floor(truth.uv[i] + 0.5).astype(int)
        assert (on.photons - bg)[v0 - r:v0 + r + 1, u0 - r:u0 + r + 1].sum() == pytest.approx(truth.photons[i], rel=1e-9)


def test_the_shift_grows_with_field_and_depends_on_the_star_colour(traced):
    """Towards the corner the shift is larger; two stars in one direction but of other colours (B−V −0.2
    and 1.6) are shifted apart by the lens's lateral colour."""
    from dataclasses import replace

    from rigsim.optics.star_psf import bv_temperature_k, photon_spectrum_weights

    R = np.eye(3)
    truth = traced.field(R)
    corner = np.array([[np.tan(0.17), np.tan(0.17), 1.0], [0.0, 0.0, 1.0]])
    corner /= np.linalg.norm(corner, axis=1, keepdims=True)
    t2 = replace(truth, dirs_cam=np.repeat(corner, 2, axis=0), bv=np.array([-0.2, 1.6, -0.2, 1.6]))
    _, shift, table = traced_star_psfs(traced.rig, t2)
    blue_red = shift[0] - shift[1]
    assert np.hypot(*blue_red) > 0.01                   # lateral colour in the corner (px)
    np.testing.assert_allclose(shift[2:], 0.0, atol=1e-9)    # the axis: no shift for any colour
    # the shift is the spectrum-weighted mean of the per-wavelength centroids (corner node)
    w = photon_spectrum_weights(bv_temperature_k([-0.2, 1.6]), table.wavelengths_nm)
    node = table.centroid[-1, -1]
    t3 = replace(truth, dirs_cam=np.repeat(np.array([[table.tan_x[-1], table.tan_y[-1], 1.0]]), 2, axis=0),
                 bv=np.array([-0.2, 1.6]))
    np.testing.assert_allclose(traced_star_psfs(traced.rig, t3)[1], w @ node, atol=1e-12)


def test_tabulated_psfs_are_integrated_exactly_over_the_pixels_with_smear():
    """render_stars_psf against a brute-force rasterisation (each bin cut into 40 × 40 points, each
    point counted in the pixel it falls in: error ≤ one point's share along a pixel edge), for
    sub-pixel positions and smear; every photon lands on the detector."""
    rng = np.random.default_rng(1)
    os_, R = 4, 3
    n = 2 * R * os_
    P = rng.random((3, n, n))
    P /= P.sum(axis=(1, 2), keepdims=True)
    c = (np.arange(n) + 0.5) / os_ - R
    own = np.stack([P.sum(axis=1) @ c, P.sum(axis=2) @ c], axis=1)
    uv = np.array([[20.3, 17.8], [40.49, 41.51], [60.0, 25.25]])[:, None, :] + np.linspace(-0.4, 0.4, 5)[None, :, None]
    ph = np.array([1000.0, 2000.0, 500.0])
    img = render_stars_psf(uv, ph, (64, 80), P, R, os_)
    assert img.sum() == pytest.approx(ph.sum(), rel=1e-12)
    M = 40
    sub = (np.arange(n * M) + 0.5) / (os_ * M) - R          # point offsets from the star
    ref = np.zeros((64, 80))
    Pm = np.repeat(np.repeat(P, M, axis=1), M, axis=2) / M**2
    K = uv.shape[1]
    for i in range(3):
        for k in range(K):
            cols = np.floor(uv[i, k, 0] + sub + 0.5).astype(int)
            rows = np.floor(uv[i, k, 1] + sub + 0.5).astype(int)
            np.add.at(ref, (rows[:, None], cols[None, :]), Pm[i] * ph[i] / K)
    np.testing.assert_allclose(img, ref, atol=ph.max() * 2.0 / (os_ * M) * P.max(axis=(1, 2)).max() * n)
    assert np.abs(img - ref).max() < 0.02 * img.max()
    cen = _centroids(img, uv.mean(axis=1), range(3), R + 2)
    assert np.abs(cen - (uv.mean(axis=1) + own)).max() < 0.05   # a pixel centroid: close, not exact


def test_the_mitsuba_renderer_refuses_the_traced_psf(traced):
    with pytest.raises(ValueError, match="traced_psf"):
        render_frame(traced, np.eye(3), seed=1, renderer="mitsuba", mitsuba=object(), fits_header=False)


def test_bad_traced_psf_values_name_the_field_and_the_range():
    from rigsim.errors import RigError
    from rigsim.rig.load import parse_model
    from rigsim.rig.star import StarRig

    with pytest.raises(RigError, match=r"effects\.traced_psf\.wavelengths` = 0.*≥ 1 and ≤ 41"):
        parse_model(StarRig, {"name": "x", "effects": {"traced_psf": {"wavelengths": 0}}}, "f.toml")
    with pytest.raises(RigError, match=r"band_max_nm = 500.0 must be ≥ band_min_nm = 800.0"):
        parse_model(StarRig, {"name": "x", "effects": {"traced_psf": {"band_min_nm": 800.0, "band_max_nm": 500.0}}},
                    "f.toml")
