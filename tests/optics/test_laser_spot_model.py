"""The boresight laser spot's model (rigsim.optics.laser_spot_model) against a second method (each
pixel's share of the disk from its chord lengths, integrated over u by the midpoint rule; the
Gaussian's from a 2-D midpoint rule), then the forward-model fit on frames drawn from that second
image with the rig's detector noise: its scatter against the image's Cramér–Rao bound, and the
thresholded centroid's on the same frames."""

import math

import numpy as np
import pytest

from rigsim.imaging import NoiseModel
from rigsim.imaging.forward_model import fit_spot_model, model_crlb
from rigsim.imaging.rois import tcom_fast
from rigsim.optics.laser_spot_model import LaserSpotModel
from rigsim.procedures.boresight.model_spot import laser_spot_shape, model_centroid_rois
from rigsim.rig.load import load_boresight_rig

RIG = load_boresight_rig("dual_line_array_prism")
DET = RIG.detector
NOISE = NoiseModel.from_detector(DET)
W = RIG.orbit.window_px


def chord_image(c, R, origin, W, ss=4096):
    """Unit-flux pixel image of a uniform disk (radius R px, centre c) by chords: independent of
    the model's quadrant areas."""
    x = origin[0] - 0.5 + (np.arange(W * ss) + 0.5) / ss - c[0]
    h = np.sqrt(np.maximum(R * R - x * x, 0.0))
    y0 = origin[1] - 0.5 + np.arange(W) - c[1]
    chord = np.clip(np.minimum(y0[:, None] + 1, h[None, :]) - np.maximum(y0[:, None], -h[None, :]), 0, None)
    return chord.reshape(W, W, ss).sum(axis=2) / ss / (math.pi * R * R)


def test_the_rigs_spot_is_the_cores_disk():
    R, profile = laser_spot_shape(RIG, 0)
    assert profile == "disk" and R == pytest.approx(2.5)  # 25 µm core, 10 µm pixels
    gb = RIG.model_copy(update={"effects": RIG.effects.model_copy(update={
        "gaussian_beam": RIG.effects.gaussian_beam.model_copy(update={"enabled": True})})})
    Rg, pg = laser_spot_shape(gb, 0)
    assert pg == "gaussian" and Rg > 2.5  # w(z) 2 mm from a 25 µm waist


@pytest.mark.parametrize("c", [(10.0, 10.0), (10.37, 9.81), (10.5, 10.5), (9.02, 10.66)])
def test_the_disk_image_is_the_chord_integrals(c):
    """Pixel by pixel to 1e-5 of the peak (the midpoint rule's own error at the disk's tangents), the
    light in the window to 1e-9; a disk 2 % larger is 30× farther off. The analytic gradient is the
    image's central differences."""
    o = (0, 0)
    ref = chord_image(c, 2.5, o, 20)
    img = LaserSpotModel(2.5, o, (20, 20))(*c)
    assert np.abs(img - ref).max() < 1e-5 * ref.max()
    assert img.sum() == pytest.approx(1.0, abs=1e-9)
    wrong = LaserSpotModel(2.55, o, (20, 20))(*c)
    assert np.abs(wrong - ref).max() > 30 * 1e-5 * ref.max()
    if c == (10.0, 10.0):  # the disk's tangents on the pixels' edges: not differentiable there
        return
    m, h = LaserSpotModel(2.5, o, (20, 20)), 1e-5
    _, gu, gv = m.gradient(*c)
    assert np.abs(gu - (m(c[0] + h, c[1]) - m(c[0] - h, c[1])) / (2 * h)).max() < 1e-6
    assert np.abs(gv - (m(c[0], c[1] + h) - m(c[0], c[1] - h)) / (2 * h)).max() < 1e-6


def test_the_gaussian_image_is_a_midpoint_rule():
    c, w, ss = (8.3, 7.6), 3.1, 64
    off = (np.arange(ss) + 0.5) / ss - 0.5
    v, u = np.indices((16, 16))
    U = u[..., None, None] + off[None, None, None, :] - c[0]
    V = v[..., None, None] + off[None, None, :, None] - c[1]
    ref = (np.exp(-2 * (U * U + V * V) / w**2) * 2 / (math.pi * w * w)).mean(axis=(2, 3))
    img = LaserSpotModel(w, (0, 0), (16, 16), profile="gaussian")(*c)
    assert np.abs(img - ref).max() < 1e-4 * ref.max()


@pytest.mark.slow  # 200 draws × 4 phases; the model's images against closed forms stay in the default stage
def test_the_fit_attains_the_crlb_and_the_thresholded_centroid_does_not():
    """200 ROIs drawn from the chord image at the rig's brightness (400 000 photons, QE 0.6; Poisson
    electrons, read noise, 12-bit DN): the fit's rms error per axis within 1.1× the bound (sampling
    error of an rms over 200 draws: 5 %), its bias below a third of it; the rig's thresholded
    centroid (tcom) 1.5–4× the bound on the same frames."""
    R, _ = laser_spot_shape(RIG, 0)
    o = (100, 200)
    c = np.array([124.31, 222.83])
    ref = chord_image(c, R, o, W)
    K = DET.gain_dn_per_e
    flux_e = RIG.laser.photons_per_frame * DET.quantum_efficiency
    bg_e = DET.dark_current_e_per_s * DET.exposure_s
    rng = np.random.default_rng(3)
    mu = flux_e * ref + bg_e
    n = 200
    e = rng.poisson(mu, size=(n, W, W)) + rng.normal(0.0, DET.read_noise_e, (n, W, W))
    dn = np.clip(np.round(K * e + DET.offset_dn), 0, 4095).astype(np.uint16)
    res, fits = model_centroid_rois(dn, [o] * n, R, "disk", NOISE, saturation_dn=4095)
    assert res.valid.all()
    assert all(f.chi2_dof < 1.3 for f in fits)
    err = res.uv - c
    model = LaserSpotModel(R, o, (W, W))
    bound = np.sqrt(np.diag(model_crlb(model, *c, K * flux_e, K * bg_e + DET.offset_dn, NOISE))[:2])
    ratio = np.sqrt(np.mean(err**2, axis=0)) / bound
    assert np.all(ratio < 1.1), ratio
    assert np.all(np.abs(err.mean(axis=0)) < bound / 3), (err.mean(axis=0), bound)
    # the σ the fit reports is the bound
    assert np.median([f.sigma_u for f in fits]) == pytest.approx(bound[0], rel=0.05)
    uv, ok = tcom_fast(dn, [o] * n, noise=NOISE)
    assert ok.all()
    tr = np.sqrt(np.mean((uv - c) ** 2, axis=0)) / bound
    assert np.all(tr > 1.3), tr


def test_a_wrong_radius_is_refused_by_its_chi2():
    """The same frames fitted with a core 20 % larger: the χ² says the spot is not the model's."""
    o = (0, 0)
    c = np.array([24.4, 23.7])
    K = DET.gain_dn_per_e
    mu = RIG.laser.photons_per_frame * DET.quantum_efficiency * chord_image(c, 2.5, o, W)
    dn = np.round(K * np.random.default_rng(1).poisson(mu) + DET.offset_dn)
    good = fit_spot_model(dn, LaserSpotModel(2.5, o, (W, W)), NOISE, 24.0, 24.0)
    bad = fit_spot_model(dn, LaserSpotModel(3.0, o, (W, W)), NOISE, 24.0, 24.0)
    assert good.chi2_dof < 1.3 and bad.chi2_dof > 3.0
