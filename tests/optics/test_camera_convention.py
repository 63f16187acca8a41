"""The camera model is OpenCV's: same projection as cv2.projectPoints, same pixel origin."""

import cv2
import numpy as np

from rigsim.optics.camera import PinholeBrown


def _cam():
    return PinholeBrown(272.7, 272.9, 515.3, 508.7, -0.021, 0.0012, 2e-4, -1.5e-4, 1e-5, 1024, 1024)


def test_project_matches_cv2_projectPoints():
    cam = _cam()
    rng = np.random.default_rng(0)
    # directions up to 60° off axis
    th = np.radians(rng.uniform(0, 60, 500))
    ph = rng.uniform(0, 2 * np.pi, 500)
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    uv = cam.project(d)
    ref, _ = cv2.projectPoints(d.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.camera_matrix(), cam.dist_coeffs())
    np.testing.assert_allclose(uv, ref.reshape(-1, 2), atol=1e-9)


def test_pixel_origin_and_axes():
    cam = PinholeBrown(100.0, 100.0, 10.0, 20.0, width=64, height=64)
    # the principal ray lands exactly on (cx, cy): pixel centres are at integer coordinates
    np.testing.assert_allclose(cam.project(np.array([0, 0, 1.0])), [10.0, 20.0])
    # +x of the camera frame is +u (columns, right), +y is +v (rows, down)
    uv = cam.project(np.array([[0.01, 0, 1], [0, 0.01, 1]]))
    assert uv[0, 0] > 10 and abs(uv[0, 1] - 20) < 1e-12
    assert uv[1, 1] > 20 and abs(uv[1, 0] - 10) < 1e-12
    # cv2.moments of a single lit pixel at img[v=20, u=10] gives centroid (10, 20)
    img = np.zeros((64, 64), np.float32)
    img[20, 10] = 1.0
    m = cv2.moments(img)
    assert (m["m10"] / m["m00"], m["m01"] / m["m00"]) == (10.0, 20.0)


def test_unproject_inverts_project():
    cam = _cam()
    rng = np.random.default_rng(1)
    d = rng.normal(size=(200, 3))
    d[:, 2] = np.abs(d[:, 2]) + 1.0
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_allclose(cam.unproject(cam.project(d)), d, atol=1e-10)


def test_behind_camera_is_nan_and_off_detector():
    cam = _cam()
    uv = cam.project(np.array([[0, 0, -1.0], [0.0, 0.0, 1.0]]))
    assert np.isnan(uv[0]).all()
    assert cam.on_detector(uv).tolist() == [False, True]
