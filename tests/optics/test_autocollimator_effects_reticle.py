"""The reticle's drawing and the reticle-centre estimator (no rendering)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rigsim.imaging.reticle import measure_reticle
from rigsim.imaging.spot import measure_spot
from rigsim.optics.reticle import reticle_drawing
from rigsim.rig import load_rig
from rigsim.rig.effects_autocollimator import Reticle

RIG = load_rig("sun_sensor_3axis_autocollimator")
DET = RIG.autocollimator.detector
PITCH = RIG.autocollimator.pixel_pitch_um * 1e-3
ROI = 59  # the face's centroid window on this rig (autocollimator_roi_px)


@pytest.mark.parametrize("pattern", ["cross", "cross_ring"])
def test_drawing_area_is_counted_once(pattern):
    r = Reticle()
    d = reticle_drawing(pattern, r.line_width_um * 1e-3, r.arm_length_mm, r.ring_radius_mm)
    w, L = r.line_width_um * 1e-3, r.arm_length_mm
    area = 2 * w * L - w * w  # two bars, the crossing once
    if pattern == "cross_ring":
        R = r.ring_radius_mm
        area += 2 * math.pi * R * w - 4 * w * w  # the ring, minus where it covers the bars
    assert d.areas.sum() == pytest.approx(area, rel=1e-3)
    # Monte-Carlo area of the union agrees (no overlap counted twice)
    rng = np.random.default_rng(1)
    e = d.half_extent_mm
    x, y = rng.uniform(-e, e, (2, 400_000))
    assert d.inside(x, y).mean() * (2 * e) ** 2 == pytest.approx(d.areas.sum(), rel=0.03)


def test_bad_drawing_rejected():
    with pytest.raises(ValueError, match="line_width_mm"):
        reticle_drawing("cross", 0.6, 0.5)
    with pytest.raises(ValueError, match="ring_radius_mm"):
        reticle_drawing("cross_ring", 0.02, 0.5, 0.3)
    with pytest.raises(ValueError, match="pattern"):
        reticle_drawing("dot", 0.02, 0.5)


def _frame(centre_uv, pattern="cross", level_e=14000.0, seed=0, blur_px=1.0, rotation_rad=0.0):
    """A synthetic DN frame: the drawing imaged about ``centre_uv`` (point-inverted) on a grid 8×
    finer than the pixels, blurred there by a Gaussian (the optics blur before the pixels
    integrate), binned to pixels, with shot and read noise."""
    from scipy.ndimage import gaussian_filter, rotate

    r = Reticle()
    d = reticle_drawing(pattern, r.line_width_um * 1e-3, r.arm_length_mm, r.ring_radius_mm)
    H, W = DET_SHAPE
    k, n = 8, 160
    u0, v0 = int(centre_uv[0]) - n // 2, int(centre_uv[1]) - n // 2
    # sub-pixel coordinate U = k (u + ½) − ½ (sub-pixel centres on integers)
    cU = (k * (centre_uv[0] + 0.5) - 0.5, k * (centre_uv[1] + 0.5) - 0.5)
    fine = d.image_fraction(cU, PITCH / k, (k * u0, k * v0, k * n, k * n), oversample=2)
    if rotation_rad:
        fine = rotate(fine, math.degrees(rotation_rad), reshape=False, order=1)
    fine = gaussian_filter(fine, blur_px * k)
    img = fine.reshape(n, k, n, k).mean(axis=(1, 3))
    e = np.zeros((H, W))
    e[v0:v0 + n, u0:u0 + n] = img * level_e
    rng = np.random.default_rng(seed)
    e = rng.poisson(e) + rng.normal(0.0, DET.read_noise_e, e.shape)
    return np.clip(np.round(e * DET.gain_dn_per_e + DET.offset_dn), 0, DET.max_dn)


DET_SHAPE = (RIG.autocollimator.resolution_px[1], RIG.autocollimator.resolution_px[0])


@pytest.mark.parametrize("pattern", ["cross", "cross_ring"])
@pytest.mark.parametrize("centre", [(640.0, 512.0), (401.37, 688.81), (900.62, 300.25)])
def test_reticle_centre_from_line_fits(pattern, centre):
    dn = _frame(centre, pattern, seed=int(centre[0]))
    sm = measure_spot(dn, DET, roi_px=ROI)
    rm = measure_reticle(dn, sm, ROI)
    assert rm is not None and rm.ok, rm
    err = rm.uv - np.array(centre)
    # shot + read noise over ~90 rows of each bar: σ ≈ 0.005 px (the fit's own estimate)
    assert np.all(rm.sigma_uv < 0.02), rm.sigma_uv
    assert np.max(np.abs(err)) < max(0.01, 5 * rm.sigma_uv.max()), (err, rm.sigma_uv)
    # the plain thresholded centroid on the same frame is biased by its window cutting the arms
    if pattern == "cross":
        assert np.max(np.abs(sm.uv - np.array(centre))) > 3 * np.max(np.abs(err))


def test_rotated_reticle():
    centre = (640.3, 511.7)
    dn = _frame(centre, "cross", seed=5, rotation_rad=math.radians(1.5))
    sm = measure_spot(dn, DET, roi_px=ROI)
    rm = measure_reticle(dn, sm, ROI)
    assert rm is not None and rm.ok
    # the rotation is about the centre of the 160-px patch (the fine grid's centre)
    pivot = np.array([int(centre[0]) - 80 + 79.5, int(centre[1]) - 80 + 79.5])
    c = math.cos(math.radians(1.5))
    s = math.sin(math.radians(1.5))
    d = np.array(centre) - pivot
    # scipy.ndimage.rotate turns the image content by +angle in (row, col) axes
    expected = pivot + np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
    assert np.max(np.abs(rm.uv - expected)) < 0.05, (rm.uv, expected)


def test_compact_spot_is_left_to_the_centroid():
    """An ideal pinhole's spot (a Gaussian) is not a reticle: the estimator returns None and the
    spot's thresholded centroid stays the reading (frames without the effect read as before)."""
    H, W = DET_SHAPE
    v, u = np.indices((H, W))
    e = 14000.0 * np.exp(-((u - 640.3) ** 2 + (v - 511.6) ** 2) / (2 * 2.0 ** 2))
    rng = np.random.default_rng(3)
    e = rng.poisson(e) + rng.normal(0.0, DET.read_noise_e, e.shape)
    dn = np.clip(np.round(e * DET.gain_dn_per_e + DET.offset_dn), 0, DET.max_dn)
    sm = measure_spot(dn, DET, roi_px=ROI)
    assert sm.ok
    assert measure_reticle(dn, sm, ROI) is None
