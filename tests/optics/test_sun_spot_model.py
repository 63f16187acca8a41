"""The sun sensor's spot model (rigsim.optics.sun_spot_model) against a second method: the disk's
equal-solid-angle directions (sun_disk.disk_directions, not the model's quadrature) projected through
the camera, histogrammed on 1/8 px, convolved with the pinhole's PSF sampled on 1/8 px (the model
uses 1/4 px and a spline), summed into pixels. Then the forward-model fit on frames drawn from that
second image with the detector's noise: its scatter against the image's Cramér–Rao bound."""

import math

import numpy as np
import pytest
from scipy.signal import fftconvolve

from rigsim.imaging import NoiseModel
from rigsim.imaging.forward_model import fit_spot_model, model_crlb
from rigsim.optics.pinhole_diffraction import PinholePSF
from rigsim.optics.sun_disk import SIMULATOR_32ARCMIN_RAD as A
from rigsim.optics.sun_disk import disk_directions, spot_truth
from rigsim.optics.sun_spot_model import SunSpotModel
from rigsim.rig import load_rig

RIG = load_rig("sun_sensor_3axis_autocollimator")
CAM = RIG.sun_sensor.camera()
PD = RIG.effects.pinhole_diffraction
PSF = PinholePSF(PD.pinhole_diameter_mm, PD.mask_thickness_mm, RIG.sun_sensor.focal_length_mm)
NOISE = NoiseModel(gain_dn_per_e=0.5, read_noise_e=10.0)


def direction(theta_deg, phi_deg=30.0):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def second_method(s, origin, W, psf=None, m=8, half=None):
    """Unit-flux pixel image of the window (W × W from ``origin``): see the module docstring. The PSF
    reaches ``half`` px (default W/2, as the renderer's window keeps it)."""
    d = disk_directions(s, A, 400_000)
    uv, _ = CAM.project_valid(d)
    w = d[:, 2]
    x, y = (uv[:, 0] - origin[0] + 0.5) * m, (uv[:, 1] - origin[1] + 0.5) * m
    img, _, _ = np.histogram2d(y, x, bins=[W * m, W * m], range=[[0, W * m], [0, W * m]], weights=w / w.sum())
    if psf is not None:
        img = fftconvolve(img, psf.kernel(s, CAM.fx, CAM.fy, W / 2 if half is None else half, 1.0 / m), mode="same")
    return img.reshape(W, m, W, m).sum(axis=(1, 3))


def window_at(s, W):
    c = CAM.project_valid(s[None, :])[0][0]
    return c, np.floor(c + 0.5).astype(int) - W // 2


@pytest.mark.parametrize("theta_deg,psf", [
    (0.5, None), (40.0, None), (60.0, None), (40.0, PSF),
    pytest.param(0.5, PSF, marks=pytest.mark.slow), pytest.param(60.0, PSF, marks=pytest.mark.slow)],
    ids=["point pinhole-0.5", "point pinhole-40", "point pinhole-60", "diffraction-40", "diffraction-0.5",
         "diffraction-60"])
def test_the_model_image_is_the_second_methods(theta_deg, psf):
    """Pixel by pixel to 1 % of the peak (a 2.5 px sharp-edged disk, or its 9 px diffracted image;
    at 60° the camera's distortion shapes it); the same light in the window to 0.5 %; the same
    first moment to 3e-3 px. With the wrong optics (no PSF for a diffracted spot) the peak is 3×
    off and the test fails."""
    W = 32
    s = direction(theta_deg)
    c, origin = window_at(s, W)
    ref = second_method(s, origin, W, psf, half=W / 2 + 1)  # the model's PSF reaches 1 px past the window's half width
    img = SunSpotModel(CAM, A, s, origin, (W, W), psf=psf)(c[0], c[1])
    assert np.abs(img - ref).max() < 0.01 * ref.max()
    assert img.sum() == pytest.approx(ref.sum(), rel=5e-3)
    v, u = np.indices(img.shape)
    for a in (img, ref):
        a /= a.sum()
    assert (img * u).sum() == pytest.approx((ref * u).sum(), abs=3e-3)
    assert (img * v).sum() == pytest.approx((ref * v).sum(), abs=3e-3)


def test_the_models_reference_point_is_the_disks_centre():
    """Its first moment at (u, v) is the exact pixel-binned centroid of a disk whose centre projects
    to (u, v) (spot_truth's 2 M point quadrature), to 2e-3 px: the fit returns the centre, not the
    centroid (they differ by the disk's own bias, 0.01–0.1 px off axis)."""
    W = 24
    for th in (20.0, 55.0):
        s = direction(th)
        c, origin = window_at(s, W)
        t = spot_truth(CAM, s, A, n=2_000_000)
        img = SunSpotModel(CAM, A, s, origin, (W, W))(c[0], c[1])
        v, u = np.indices(img.shape)
        mom = np.array([(img * u).sum(), (img * v).sum()]) / img.sum() + origin
        assert mom == pytest.approx(t["pixel_centroid_uv"], abs=2e-3)


@pytest.mark.parametrize("theta_deg,psf", [(20.0, None), (35.0, PSF)], ids=["point pinhole", "diffraction"])
def test_the_fit_attains_the_images_crlb(theta_deg, psf):
    """200 frames drawn from the second method's image (Poisson electrons + read noise), fitted with
    the model built at the first estimate: rms error within 1.1× the image's Cramér–Rao bound per
    axis (sampling error of the rms 5 %) and a bias below a third of it."""
    W = 24
    s = direction(theta_deg)
    c, origin = window_at(s, W)
    flux_e, bg_e = 2.0e5, 50.0
    ref = second_method(s, origin, W, psf)
    rng = np.random.default_rng(11)
    mu_e = flux_e * ref + bg_e
    n = 200
    dn = NOISE.gain_dn_per_e * (rng.poisson(mu_e, size=(n, W, W)) + rng.normal(0.0, NOISE.read_noise_e, (n, W, W)))
    start = c + 0.03  # a moment centroid's error; the sweep refits where a fit moved farther than 0.05 px
    model = SunSpotModel(CAM, A, CAM.unproject(start[None, :])[0], origin, (W, W), psf=psf)
    fits = [fit_spot_model(d, model, NOISE, *start) for d in dn]
    assert all(f.ok for f in fits)
    e = np.array([[f.u, f.v] for f in fits]) - c
    bound = np.sqrt(np.diag(model_crlb(model, *c, flux_e * NOISE.gain_dn_per_e, bg_e * NOISE.gain_dn_per_e,
                                       NOISE))[:2])
    ratio = np.sqrt(np.mean(e**2, axis=0)) / bound
    assert np.all(ratio < 1.1), ratio
    # the model's own grid (1/32 px, 60 000 disk points) leaves up to 3e-4 px: a quarter of this bright
    # spot's bound, well inside the 1.1× (a spot at half the full well, as the rigs', has 2–5× the bound)
    assert np.all(np.abs(e.mean(axis=0)) < 0.35 * bound), (e.mean(axis=0), bound)


def test_a_streak_cut_by_the_readout_window_is_fitted_where_it_is():
    """66° off axis the diffracted spot is a streak longer than the 32 px readout window. Its noise-free
    image (the second method, the PSF to the window's half width as the renderer draws it), fitted on the
    30 px window the sweep uses: within 0.01 px of the true centre. With the model's PSF cut at the fit
    window's own half width (``psf_margin_px = 0``) the fit is 0.06 px off."""
    s = direction(66.0, 40.0)
    c, origin = window_at(s, 32)
    img = second_method(s, origin, 32, PSF)[1:31, 1:31]
    noise = NoiseModel(gain_dn_per_e=0.12, read_noise_e=8.0, offset_dn=64.0)
    for margin, worst in ((1.0, 0.01), (0.0, None)):
        f = fit_spot_model(2.4e4 * img + 64.0, SunSpotModel(CAM, A, s, origin + 1, (30, 30), psf=PSF, psf_margin_px=margin),
                           noise, *c)
        err = max(abs(f.u - c[0]), abs(f.v - c[1]))
        assert (err < worst) if worst else (err > 0.04), (margin, err)
