"""Numpy camera model against OpenCV (the project's pixel convention is OpenCV's)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from rigsim.optics.camera import PinholeBrown, TelecentricCamera, radial_r2_max

WIDE = PinholeBrown(fx=500.0, fy=502.0, cx=515.3, cy=508.7, width=1024, height=1024,
                     k1=-0.15, k2=0.012, k3=-0.0003, p1=3e-4, p2=-2e-4)
NARROW = PinholeBrown(fx=1000.0, fy=1001.5, cx=511.5, cy=511.5, width=1024, height=1024,
                       k1=-0.05, k2=0.01, k3=0.0, p1=1e-4, p2=5e-5)


def _cv_project(cam: PinholeBrown, p):
    uv, _ = cv2.projectPoints(np.asarray(p, dtype=np.float64).reshape(-1, 1, 3),
                              np.zeros(3), np.zeros(3), cam.camera_matrix(), cam.dist_coeffs())
    return uv.reshape(-1, 2)


@pytest.mark.parametrize("cam", [WIDE, NARROW], ids=["wide", "narrow"])
def test_project_matches_cv2(cam):
    rng = np.random.default_rng(1)
    th = np.radians(rng.uniform(0.0, 60.0 if cam is WIDE else 25.0, 500))
    ph = rng.uniform(0.0, 2 * math.pi, 500)
    dist = rng.uniform(10.0, 5000.0, 500)
    p = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1) * dist[:, None]
    uv, ok = cam.project_valid(p)
    assert ok.all()
    np.testing.assert_allclose(uv, _cv_project(cam, p), atol=1e-9, rtol=0)


@pytest.mark.parametrize("cam", [WIDE, NARROW], ids=["wide", "narrow"])
def test_backproject_inverts_project(cam):
    rng = np.random.default_rng(2)
    uv = rng.uniform([0, 0], [cam.width - 1, cam.height - 1], size=(1000, 2))
    d, ok = cam.backproject(uv)
    # the wide lens folds back at r2_max: pixels beyond the image circle have no direction
    r2 = cam.r2_max
    rd_max = math.sqrt(r2) * (1 + cam.k1 * r2 + cam.k2 * r2 ** 2 + cam.k3 * r2 ** 3)
    rd = np.hypot((uv[:, 0] - cam.cx) / cam.fx, (uv[:, 1] - cam.cy) / cam.fy)
    assert np.all(ok[rd < 0.98 * rd_max]) and not np.any(ok[rd > 1.02 * rd_max])
    uv, d = uv[ok], d[ok]
    uv2, ok2 = cam.project_valid(d)
    assert ok2.all()
    np.testing.assert_allclose(uv2, uv, atol=1e-8)
    # and agrees with OpenCV's own (iterative) undistortPoints to its accuracy
    und = cv2.undistortPoints(uv.reshape(-1, 1, 2), cam.camera_matrix(), cam.dist_coeffs(),
                              criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14))
    np.testing.assert_allclose(und.reshape(-1, 2), d[:, :2] / d[:, 2:], atol=1e-7)


def test_pixel_convention_principal_point():
    cam = PinholeBrown(fx=800.0, fy=800.0, cx=100.0, cy=50.0, width=201, height=101)
    uv, _ = cam.project_valid([[0.0, 0.0, 1.0], [1.0, 0.0, 800.0], [0.0, 1.0, 800.0]])
    # the optical axis lands on the principal point; +x -> +u (right), +y -> +v (down)
    np.testing.assert_allclose(uv, [[100.0, 50.0], [101.0, 50.0], [100.0, 51.0]], atol=1e-12)
    assert cam.on_detector([[-0.5, -0.5]])[0] and not cam.on_detector([[200.5, 0.0]])[0]


def test_monotonic_domain():
    # 1 + 3 k1 s = 0 -> s = 1/(3*0.2)
    assert radial_r2_max(-0.2, 0.0, 0.0) == pytest.approx(1.0 / 0.6)
    assert radial_r2_max(0.1, 0.0, 0.0) > 1e5
    cam = PinholeBrown(fx=500.0, fy=500.0, cx=0.0, cy=0.0, width=10, height=10, k1=-0.2)
    s = cam.r2_max
    r = np.sqrt(np.array([0.9 * s, s * 0.999]))
    rd = r * (1 + cam.k1 * r * r)
    assert rd[1] > rd[0]                              # still increasing just inside the domain
    _, ok = cam.project_valid([[math.sqrt(1.01 * s), 0.0, 1.0]])
    assert not ok[0]                                  # beyond the fold: reported invalid
    _, ok = cam.project_valid([[0.0, 0.0, -1.0]])
    assert not ok[0]                                  # behind the camera


def test_flux_weight_is_cos4_without_distortion():
    cam = PinholeBrown(fx=400.0, fy=400.0, cx=200.0, cy=200.0, width=401, height=401)
    uv = np.array([[200.0, 200.0], [400.0, 200.0], [350.0, 380.0]])
    x = (uv[:, 0] - 200.0) / 400.0
    y = (uv[:, 1] - 200.0) / 400.0
    cos_t = 1.0 / np.sqrt(1 + x * x + y * y)
    np.testing.assert_allclose(cam.flux_weight(uv), cos_t ** 4, rtol=1e-12)


def test_bad_intrinsics_rejected_with_field_name():
    with pytest.raises(ValueError, match="fx"):
        PinholeBrown(fx=0.0, fy=1.0, cx=0.0, cy=0.0, width=10, height=10)
    with pytest.raises(ValueError, match="width"):
        PinholeBrown(fx=1.0, fy=1.0, cx=0.0, cy=0.0, width=0, height=10)
    with pytest.raises(ValueError, match="pixel_size_mm"):
        TelecentricCamera(pixel_size_mm=-1.0, cx=0.0, cy=0.0, width=10, height=10)


def test_project_valid_and_project_agree():
    """The two entry points of the one camera model: ``project_valid`` (uv and the domain mask, what
    the renderers use) and ``project`` (NaN outside the domain, what the estimators use)."""
    pb = PinholeBrown(fx=500.0, fy=502.0, cx=515.3, cy=508.7, k1=-0.15, k2=0.012,
                      p1=3e-4, p2=-2e-4, k3=-0.0003, width=1024, height=1024)
    cam = pb
    assert cam == WIDE
    rng = np.random.default_rng(5)
    d = rng.normal(size=(200, 3))
    d[:, 2] = np.abs(d[:, 2]) + 1.0
    uv, valid = cam.project_valid(d)
    uv_pb = pb.project(d)
    # identical where the model is valid; the analytic model returns NaN exactly where it is not
    np.testing.assert_allclose(uv[valid], uv_pb[valid], atol=1e-9)
    np.testing.assert_array_equal(np.isnan(uv_pb).any(axis=-1), ~valid)
    assert valid.sum() > 100 and (~valid).sum() > 0
