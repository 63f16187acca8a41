"""Centroiders against truth: accuracy relative to the CRLB, bias, predicted uncertainty vs
Monte-Carlo scatter, agreement between the batch and scipy paths, and the pixel convention
checked against OpenCV."""

import math

import cv2
import numpy as np
import pytest

from rigsim.imaging import (
    NoiseModel,
    centroid,
    centroid_gauss,
    centroid_gauss_lsq,
    centroid_tcom,
    centroid_wcom,
    crlb_gaussian,
    fit_circle,
)
from rigsim.imaging.synth import add_noise, disk_image, flux_for_snr, gaussian_spots, pixel_fractions

B_E, READ_E, SIGMA = 20.0, 5.0, 1.0
NOISE = NoiseModel(1.0, READ_E)


def _spots(snr, n, seed, roi=9, sigma=SIGMA):
    rng = np.random.default_rng(seed)
    F = flux_for_snr(snr, B_E, READ_E, sigma)
    c = roi // 2
    du = rng.uniform(-0.5, 0.5, n)
    dv = rng.uniform(-0.5, 0.5, n)
    img = add_noise(gaussian_spots((roi, roi), c + du, c + dv, F, sigma, B_E), NOISE, rng)
    bound = crlb_gaussian(F, B_E, READ_E, sigma, du=du, dv=dv, roi_px=roi)
    bound_rms = math.sqrt(np.mean(np.concatenate([bound.sigma_u, bound.sigma_v]) ** 2))
    return img, c + du, c + dv, F, bound_rms


# Measured efficiency (RMS / CRLB) at SNR 100 with sigma = 1 px (see docs/imaging.md), with
# margin for the ~1.3 % sampling error of 3000 spots.
METHOD_CASES = [
    ("tcom", dict(), 1.10),
    ("wcom", dict(window_sigma_px=SIGMA), 1.30),
    ("gauss", dict(sigma_px=SIGMA), 1.05),
    ("gauss_fit_sigma", dict(sigma_px=SIGMA, fit_sigma=True), 1.05),
]


@pytest.mark.parametrize("name,kw,max_ratio", METHOD_CASES, ids=[c[0] for c in METHOD_CASES])
def test_accuracy_against_truth_and_crlb(name, kw, max_ratio):
    img, u, v, F, bound = _spots(100.0, 3000, seed=11)
    method = "gauss" if name.startswith("gauss") else name
    r = centroid(img, method, noise=NOISE, **kw)
    assert np.all(r.valid)
    eu, ev = r.u - u, r.v - v
    rms = math.sqrt(np.mean(np.concatenate([eu, ev]) ** 2))
    # an unbiased estimator cannot beat the CRLB (allow 4 standard errors of the RMS)
    assert rms / bound > 1.0 - 4.0 / math.sqrt(2 * eu.size)
    assert rms / bound < max_ratio
    # no mean bias beyond 4 standard errors
    for e in (eu, ev):
        assert abs(e.mean()) < 4 * e.std() / math.sqrt(e.size)
    # flux is recovered (within 5 % for the aperture sums, 4 sigma_F for the fit)
    assert np.median(r.flux) == pytest.approx(F, rel=0.05)


@pytest.mark.parametrize("name,kw", [(c[0], c[1]) for c in METHOD_CASES], ids=[c[0] for c in METHOD_CASES])
@pytest.mark.parametrize("snr", [30.0, 300.0])
def test_predicted_sigma_matches_monte_carlo(name, kw, snr):
    img, u, v, _, _ = _spots(snr, 2000, seed=int(snr) + 5)
    method = "gauss" if name.startswith("gauss") else name
    r = centroid(img, method, noise=NOISE, **kw)
    for err, pred in ((r.u - u, r.sigma_u), (r.v - v, r.sigma_v)):
        measured = math.sqrt(np.mean(err**2))
        predicted = math.sqrt(np.mean(pred**2))
        assert predicted / measured == pytest.approx(1.0, abs=0.2), (predicted, measured)


def test_noise_free_phase_bias():
    ph = np.linspace(-0.5, 0.5, 21)
    F = flux_for_snr(100.0, B_E, READ_E, SIGMA)
    img = gaussian_spots((9, 9), 4 + ph, 4.0 - 0.5 * ph, F, SIGMA, B_E)
    g = centroid_gauss(img, sigma_px=SIGMA, noise=NOISE)
    assert np.max(np.abs(g.u - 4 - ph)) < 1e-6
    assert np.max(np.abs(g.v - 4 + 0.5 * ph)) < 1e-6
    gs = centroid_gauss(img, fit_sigma=True, noise=NOISE)
    assert np.max(np.abs(gs.u - 4 - ph)) < 1e-6
    assert np.allclose(gs.extra["sigma_px"], SIGMA, atol=1e-6)
    # the moment methods have a small S-curve (measured 1.6e-3 and 4.6e-4 px at this SNR)
    t = centroid_tcom(img, noise=NOISE)
    w = centroid_wcom(img, window_sigma_px=SIGMA, noise=NOISE)
    assert np.max(np.abs(t.u - 4 - ph)) < 3e-3
    assert np.max(np.abs(w.u - 4 - ph)) < 1e-3


def test_threshold_definition_is_the_documented_one():
    # hand-computed thresholded centre of mass: w = I - T above T, mean of coordinates
    img = np.array(
        [[0, 0, 0, 0, 0], [0, 1, 3, 1, 0], [0, 2, 10, 6, 0], [0, 0, 4, 1, 0], [0, 0, 0, 0, 0]], dtype=float
    )
    T = 1.5
    w = np.where(img > T, img - T, 0.0)
    vv, uu = np.mgrid[0:5, 0:5]
    r = centroid_tcom(img, threshold=T)
    assert r.u == pytest.approx((w * uu).sum() / w.sum(), abs=1e-12)
    assert r.v == pytest.approx((w * vv).sum() / w.sum(), abs=1e-12)
    m = centroid_tcom(img, threshold=T, mode="mask", background=0.0)
    wm = np.where(img > T, img, 0.0)
    assert m.u == pytest.approx((wm * uu).sum() / wm.sum(), abs=1e-12)
    with pytest.raises(ValueError):
        centroid_tcom(img, mode="square")


def test_batch_and_scipy_paths_agree():
    img, u, v, _, _ = _spots(50.0, 25, seed=3, roi=11, sigma=1.2)
    a = centroid_gauss(img, sigma_px=1.2, noise=NOISE)
    b = centroid_gauss_lsq(img, sigma_px=1.2, fit_sigma=False, noise=NOISE)
    assert np.max(np.abs(a.u - b.u)) < 1e-4
    assert np.max(np.abs(a.v - b.v)) < 1e-4
    assert np.allclose(a.sigma_u, b.sigma_u, rtol=1e-3)
    # one ROI gives a Centroid equal to the batch entry
    one = centroid_gauss(img[3], sigma_px=1.2, noise=NOISE)
    assert one.u == pytest.approx(a.u[3], abs=1e-9) and one.v == pytest.approx(a.v[3], abs=1e-9)


def test_elliptical_lsq_recovers_widths():
    rng = np.random.default_rng(8)
    su, sv, F = 1.0, 1.6, 2.0e4
    ex = pixel_fractions(15, 7.3, su)
    ey = pixel_fractions(15, 6.8, sv)
    img = add_noise(F * np.outer(ey, ex) + B_E, NOISE, rng)
    r = centroid_gauss_lsq(img, elliptical=True, noise=NOISE)
    assert r.u == pytest.approx(7.3, abs=4 * r.sigma_u)
    assert r.v == pytest.approx(6.8, abs=4 * r.sigma_v)
    assert r.sigma_v > r.sigma_u  # the wider axis is less certain


def test_origin_shift():
    img, u, v, _, _ = _spots(100.0, 5, seed=4)
    o = np.array([[100.0, 200.0]] * 5)
    a = centroid_gauss(img, sigma_px=SIGMA, noise=NOISE)
    b = centroid_gauss(img, sigma_px=SIGMA, noise=NOISE, origin_uv=o)
    assert np.allclose(b.u - a.u, 100.0) and np.allclose(b.v - a.v, 200.0)


def test_default_noise_model_without_noisemodel():
    """Without a NoiseModel (gain K = 1 DN/e- assumed, background noise measured) the fit is still
    unbiased and its sigma is within 20 % of the scatter for gain-1 data."""
    img, u, v, _, _ = _spots(100.0, 1500, seed=21)
    r = centroid_gauss(img, sigma_px=SIGMA)
    err = np.concatenate([r.u - u, r.v - v])
    pred = np.concatenate([r.sigma_u, r.sigma_v])
    assert math.sqrt(np.mean(pred**2)) / math.sqrt(np.mean(err**2)) == pytest.approx(1.0, abs=0.2)


# ----------------------------------------------------------------------------- pixel convention
def test_pixel_convention_integer_position_is_pixel_centre():
    img = gaussian_spots((9, 11), 3.0, 5.0, 1000.0, 1.0)
    assert np.unravel_index(np.argmax(img), img.shape) == (5, 3)  # img[v, u]
    r = centroid_gauss(img, sigma_px=1.0, noise=NoiseModel(1.0, 1.0))
    assert (r.u, r.v) == (pytest.approx(3.0, abs=1e-6), pytest.approx(5.0, abs=1e-6))


def test_pixel_convention_matches_opencv_moments_and_fitellipse():
    """A disk rendered at (u, v) = (23.37, 17.81): OpenCV's image moments, its ellipse fit on the
    disk's contour, and rigsim's estimators all return the same centre (OpenCV treats integer
    coordinates as pixel centres, as rigsim does)."""
    u0, v0 = 23.37, 17.81
    img = disk_image((40, 50), u0, v0, 9.0, inside=1.0, outside=0.0, supersample=16)
    m = cv2.moments(img.astype(np.float32))
    assert m["m10"] / m["m00"] == pytest.approx(u0, abs=2e-3)
    assert m["m01"] / m["m00"] == pytest.approx(v0, abs=2e-3)
    mask = (img > 0.5).astype(np.uint8)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    (cx, cy), _, _ = cv2.fitEllipse(max(contours, key=len))
    assert cx == pytest.approx(u0, abs=0.1) and cy == pytest.approx(v0, abs=0.1)
    # the pixel-integrated blurred-disk model is unbiased even for this sharp edge
    c = fit_circle(img, method="model", noise=NoiseModel(1.0e-4, 1.0))
    assert c.u == pytest.approx(m["m10"] / m["m00"], abs=3e-3)
    assert c.v == pytest.approx(m["m01"] / m["m00"], abs=3e-3)
    # the faster edge-point fit has a small systematic error from linear interpolation across
    # the edge (measured up to ~0.006 px for a blurred R = 9 px disk, ~0.015 px if unblurred)
    blurred = disk_image((40, 50), u0, v0, 9.0, inside=1.0, outside=0.0, blur_sigma_px=0.7, supersample=16)
    mb = cv2.moments(blurred.astype(np.float32))
    e = fit_circle(blurred)
    assert e.u == pytest.approx(mb["m10"] / mb["m00"], abs=8e-3)
    assert e.v == pytest.approx(mb["m01"] / mb["m00"], abs=8e-3)
    t = centroid_tcom(img, threshold=0.0)
    assert t.u == pytest.approx(m["m10"] / m["m00"], abs=1e-6)
    assert t.v == pytest.approx(m["m01"] / m["m00"], abs=1e-6)


def test_tcom_peak_leaves_out_a_ghost_the_threshold_separates():
    """A spot (σ 1.5 px) and a 4 % ghost 17.5 px away (the boresight prism's Fresnel ghost at 2ε·F/d):
    the ROI's thresholded centroid is pulled towards the ghost by the ghost's weight above the threshold
    (closed form from the two blobs' own moments); the peak's blob alone is the spot's centroid, to the
    noise-free digit and, with noise, to within the noise's scatter."""
    roi, s = 48, 1.5
    c = np.array([20.3, 23.6])
    g = c + np.array([0.0, 17.5])
    F = 2.0e5
    spot = gaussian_spots((roi, roi), c[0], c[1], F, s, 0.0)
    ghost = gaussian_spots((roi, roi), g[0], g[1], 0.04 * F, s, 0.0)
    thr = 0.01 * spot.max()            # the ghost's peak is 4 % of the spot's: above it
    both = centroid_tcom(spot + ghost, threshold=thr)
    peak = centroid(spot + ghost, method="tcom_peak", threshold=thr)
    alone = centroid_tcom(spot, threshold=thr)
    ghost_alone = centroid_tcom(ghost, threshold=thr)
    # the two blobs do not touch above the threshold: the ROI's centroid is their weighted mean
    w_s, w_g = (np.clip(im - thr, 0.0, None).sum() for im in (spot, ghost))
    want_v = (w_s * alone.v + w_g * ghost_alone.v) / (w_s + w_g)
    assert both.v == pytest.approx(want_v, abs=1e-9)
    assert both.v - alone.v > 0.3                       # the ghost's pull
    assert (peak.u, peak.v) == pytest.approx((alone.u, alone.v), abs=1e-12)
    # with noise (background 20 e⁻, read 5 e⁻), over 200 frames: the peak blob's error is the noise's
    rng = np.random.default_rng(7)
    imgs = np.stack([add_noise(spot + ghost + B_E, NOISE, rng) for _ in range(200)])
    pk = centroid(imgs, method="tcom_peak", noise=NOISE)
    roi_c = centroid_tcom(imgs, noise=NOISE)
    assert abs(np.mean(pk.v) - c[1]) < 4 * np.std(pk.v) / np.sqrt(200) + 0.01
    assert np.mean(roi_c.v) - c[1] > 0.3


def test_tcom_peak_equals_tcom_on_a_lone_spot_and_refuses_a_bad_region():
    img, *_ = _spots(200, 50, seed=3, roi=15)
    a, b = centroid_tcom(img, noise=NOISE), centroid(img, method="tcom_peak", noise=NOISE)
    # isolated noise pixels above 3σ away from the spot are the only difference
    assert np.median(np.abs(a.u - b.u)) < 1e-3 and np.median(np.abs(a.v - b.v)) < 1e-3
    with pytest.raises(ValueError, match="region must be"):
        centroid_tcom(img, noise=NOISE, region="blob")
