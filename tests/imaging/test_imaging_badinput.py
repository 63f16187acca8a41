"""Bad input: empty, NaN, all-saturated frames and spots at the edge produce flags, never an
exception from inside numpy and never an unflagged wrong position."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from rigsim.imaging import (
    METHODS,
    Flag,
    NoiseModel,
    centroid,
    centroid_gauss,
    centroid_tcom,
    detect,
    edge_points,
    estimate_background,
    extract_rois,
    find_spots,
    fit_circle,
    fit_ellipse,
)
from rigsim.imaging.synth import add_noise, gaussian_spots

NOISE = NoiseModel(1.0, 5.0)
KW = {"tcom": {}, "tcom_peak": {}, "wcom": {}, "gauss": {"sigma_px": 1.0}, "gauss_lsq": {"sigma_px": 1.0}}
ALL = sorted(METHODS)


def _spot(u, v, shape=(9, 9), F=2.0e4, seed=0):
    rng = np.random.default_rng(seed)
    return add_noise(gaussian_spots(shape, u, v, F, 1.0, 20.0), NOISE, rng)


def _invalid(r):
    return bool(r.flags & Flag.INVALID) and math.isnan(r.u) and math.isnan(r.v)


@pytest.mark.parametrize("method", ALL)
def test_empty_array(method):
    r = centroid(np.zeros((0, 0)), method, **KW[method])
    assert _invalid(r) and r.flags & Flag.EMPTY
    b = centroid(np.zeros((0, 9, 9)), method, **KW[method])
    assert len(b) == 0


@pytest.mark.parametrize("method", ALL)
def test_tiny_array(method):
    r = centroid(np.ones((2, 2)), method, **KW[method])
    assert _invalid(r)


@pytest.mark.parametrize("method", ALL)
def test_all_nan(method):
    r = centroid(np.full((9, 9), np.nan), method, **KW[method])
    assert _invalid(r) and r.flags & Flag.NAN and r.flags & Flag.EMPTY


@pytest.mark.parametrize("method", ALL)
def test_constant_and_zero_frames(method):
    for val in (0.0, 17.0):
        r = centroid(np.full((9, 9), val), method, noise=NOISE, **KW[method])
        assert _invalid(r) and r.flags & Flag.EMPTY, (val, r)


@pytest.mark.parametrize("method", ALL)
def test_all_saturated(method):
    r = centroid(np.full((9, 9), 4095.0), method, saturation=4095.0, **KW[method])
    assert _invalid(r) and r.flags & Flag.SATURATED
    # integer frames: the dtype maximum counts as saturation by default
    r = centroid(np.full((9, 9), 65535, dtype=np.uint16), method, **KW[method])
    assert _invalid(r) and r.flags & Flag.SATURATED


@pytest.mark.parametrize("method", ALL)
def test_pure_noise_is_never_a_confident_position(method):
    rng = np.random.default_rng(5)
    img = add_noise(np.full((9, 9), 20.0), NOISE, rng)
    r = centroid(img, method, noise=NOISE, **KW[method])
    assert r.flags & (Flag.INVALID | Flag.FAINT | Flag.EMPTY), r


@pytest.mark.parametrize("method", ALL)
def test_few_nan_pixels_are_ignored_and_flagged(method):
    img = _spot(4.2, 3.9)
    img[0, 0] = np.nan
    img[8, 3] = np.inf
    r = centroid(img, method, noise=NOISE, **KW[method])
    assert r.flags & Flag.NAN and r.valid
    assert abs(r.u - 4.2) < 5 * r.sigma_u + 0.01 and abs(r.v - 3.9) < 5 * r.sigma_v + 0.01


def test_nan_in_the_core_gauss_still_right():
    img = _spot(4.2, 3.9, F=5.0e4)
    img[4, 4] = np.nan
    r = centroid_gauss(img, sigma_px=1.0, noise=NOISE)
    assert r.flags & Flag.NAN and r.valid
    assert abs(r.u - 4.2) < 4 * r.sigma_u and abs(r.v - 3.9) < 4 * r.sigma_v


def test_saturated_core_gauss_fits_the_wings():
    rng = np.random.default_rng(9)
    F, sat = 2.0e5, 15000.0
    truth = (4.3, 3.8)
    img = add_noise(gaussian_spots((11, 11), *truth, F, 1.2, 20.0), NOISE, rng, saturation_dn=sat)
    assert (img >= sat).sum() >= 3
    g = centroid_gauss(img, sigma_px=1.2, noise=NOISE, saturation=sat)
    assert g.flags & Flag.SATURATED and g.valid
    assert abs(g.u - truth[0]) < 4 * g.sigma_u and abs(g.v - truth[1]) < 4 * g.sigma_v
    assert g.flux == pytest.approx(F, rel=0.05)
    t = centroid_tcom(img, noise=NOISE, saturation=sat)
    assert t.flags & Flag.SATURATED


@pytest.mark.parametrize("method", ALL)
def test_spot_at_the_edge_is_flagged(method):
    img = _spot(0.4, 4.1)
    r = centroid(img, method, noise=NOISE, **KW[method])
    assert r.flags & Flag.EDGE


def test_spot_at_the_edge_gauss_position_still_honest():
    img = _spot(0.4, 4.1, F=3.0e4, seed=2)
    r = centroid_gauss(img, sigma_px=1.0, noise=NOISE)
    assert r.flags & Flag.EDGE and r.valid
    assert abs(r.u - 0.4) < 4 * r.sigma_u and abs(r.v - 4.1) < 4 * r.sigma_v


def test_two_spots_in_one_roi_are_blended():
    rng = np.random.default_rng(1)
    exp = gaussian_spots((15, 15), 4.5, 7.0, 2.0e4, 1.0, 20.0) + gaussian_spots((15, 15), 9.8, 7.2, 1.5e4, 1.0)
    img = add_noise(exp, NOISE, rng)
    for m in ALL:
        r = centroid(img, m, noise=NOISE, **KW[m])
        assert r.flags & Flag.BLENDED, m
    single = _spot(7.2, 7.1, shape=(15, 15), F=1e5)
    for m in ALL:
        assert not centroid(single, m, noise=NOISE, **KW[m]).flags & Flag.BLENDED, m


def test_boundary_errors_are_ours():
    with pytest.raises(ValueError, match="shape"):
        centroid_gauss(np.zeros(5), sigma_px=1.0)
    with pytest.raises(TypeError, match="numeric"):
        centroid_gauss(np.array([["a"] * 3] * 3), sigma_px=1.0)
    with pytest.raises(ValueError, match="sigma_px"):
        centroid_gauss(np.zeros((9, 9)))
    with pytest.raises(ValueError, match="sigma_px"):
        centroid_gauss(np.zeros((9, 9)), sigma_px=-1.0)
    with pytest.raises(ValueError, match="window_sigma_px"):
        centroid(np.zeros((9, 9)), "wcom", window_sigma_px=0.5)
    with pytest.raises(ValueError, match="method"):
        centroid(np.zeros((9, 9)), "nope")
    with pytest.raises(ValueError, match="gain"):
        NoiseModel(0.0, 1.0)
    with pytest.raises(ValueError, match="background"):
        centroid_tcom(np.zeros((3, 9, 9)), background=np.zeros(2))


# ------------------------------------------------------------------------- frames, detection
@pytest.mark.parametrize(
    "frame,flag",
    [
        (np.full((40, 40), np.nan), Flag.NAN | Flag.EMPTY),
        (np.zeros((40, 40)), Flag.EMPTY),
        (np.full((40, 40), 65535, dtype=np.uint16), Flag.SATURATED | Flag.EMPTY),
        (np.zeros((0, 0)), Flag.EMPTY),
    ],
)
def test_bad_frames_detection(frame, flag):
    d = detect(frame)
    assert len(d) == 0 and (d.frame_flags & flag) == flag
    res, d2 = find_spots(frame)
    assert len(res) == 0 and (d2.frame_flags & flag) == flag
    b = estimate_background(frame)
    if frame.size == 0 or np.all(np.isnan(frame)):
        assert b.flags & Flag.EMPTY and math.isnan(b.level)


def test_extract_rois_at_corner():
    img = np.arange(100.0).reshape(10, 10)
    r = extract_rois(img, [0.2, 5.0], [0.4, 5.0], 5)
    assert r.flags[0] & Flag.EDGE and not r.flags[1] & Flag.EDGE
    assert np.isnan(r.stack[0, 0, 0]) and r.stack[0, 2, 2] == img[0, 0]
    assert np.array_equal(r.origin_uv[1], [3.0, 3.0]) and r.stack[1, 0, 0] == img[3, 3]
    with pytest.raises(ValueError, match="odd"):
        extract_rois(img, [1.0], [1.0], 4)


def test_edge_fits_on_bad_frames():
    for frame in (np.zeros((30, 30)), np.full((30, 30), np.nan), np.zeros((0, 0)) + 1):
        if frame.size == 0:
            continue
        c = fit_circle(frame)
        assert c.flags & Flag.INVALID and math.isnan(c.u)
        e = fit_ellipse(frame)
        assert e.flags & Flag.INVALID and math.isnan(e.u)
        assert len(edge_points(frame).uv) == 0


_any_float = st.floats(allow_nan=True, allow_infinity=True, width=64)
_sensor_like = st.one_of(st.floats(-1e3, 1e6), st.sampled_from([np.nan, np.inf, -np.inf, 0.0]))
_shapes = st.tuples(st.integers(0, 12), st.integers(0, 12))


def _check_result(img, r):
    if r.valid:
        h, w = img.shape
        assert -0.5 <= r.u <= w - 0.5 and -0.5 <= r.v <= h - 0.5
        assert np.isfinite(r.sigma_u) and np.isfinite(r.sigma_v)
    else:
        assert math.isnan(r.u) and math.isnan(r.v)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(hnp.arrays(np.float64, _shapes, elements=_any_float))
def test_property_any_floats_never_raise(img):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # overflow near 1e308 may warn, but must not raise
        for m in ALL:
            _check_result(img, centroid(img, m, **KW[m]))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(hnp.arrays(np.float64, _shapes, elements=_sensor_like))
def test_property_sensor_range_no_warnings(img):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # not even a RuntimeWarning from numpy
        for m in ALL:
            _check_result(img, centroid(img, m, **KW[m]))
