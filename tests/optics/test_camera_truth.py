"""rigsim.optics.camera against truths of its own: OpenCV's projectPoints (and its Jacobian by central
differences) for the fold of the distortion map, hand-worked detector edges and domains, the shape checks.
Written from the mutation run's survivors (docs/testing.md, "Camera model")."""

import cv2
import numpy as np
import pytest

from rigsim.optics import camera as C
from rigsim.optics.camera import PinholeBrown, distort, project, unproject

# strong barrel-free distortion with a tangential term: the map folds (negative Jacobian) inside r2_max
FOLD = np.array([1000.0, 1000.0, 500.0, 400.0, 0.8, -0.1, 0.3, 0.0, -0.2])


def _cv2_uv(xy, prm):
    xy = np.atleast_2d(xy)
    P = np.concatenate([xy, np.ones((len(xy), 1))], -1).reshape(-1, 1, 3)
    K = np.array([[prm[0], 0, prm[2]], [0, prm[1], prm[3]], [0, 0, 1.0]])
    return cv2.projectPoints(P, np.zeros(3), np.zeros(3), K, prm[4:])[0].reshape(-1, 2)


def _cv2_det(xy, prm, h=1e-6):
    """det ∂(u, v)/∂(x, y) of OpenCV's model by central differences."""
    ex, ey = np.array([h, 0.0]), np.array([0.0, h])
    du_dx = (_cv2_uv(xy + ex, prm) - _cv2_uv(xy - ex, prm)) / (2 * h)
    du_dy = (_cv2_uv(xy + ey, prm) - _cv2_uv(xy - ey, prm)) / (2 * h)
    return du_dx[:, 0] * du_dy[:, 1] - du_dy[:, 0] * du_dx[:, 1]


def test_a_pixel_on_the_fold_has_no_inverse_there():
    """At xy0 OpenCV's map has a negative Jacobian (it is folded) though x² + y² < r2_max: the pixel it
    lands on must not be inverted to xy0. Every pixel of a grid that is inverted lands on a point where
    OpenCV's Jacobian is positive and that OpenCV projects back onto the pixel."""
    xy0 = np.array([-0.928, -0.571])
    assert _cv2_det(xy0, FOLD)[0] < 0
    assert xy0 @ xy0 < C.radial_r2_max(FOLD[4], FOLD[5], FOLD[8])
    q0 = _cv2_uv(xy0, FOLD)[0]
    xy = unproject(q0, FOLD)
    assert np.isnan(xy).all() or np.linalg.norm(xy - xy0) > 1e-3
    assert not PinholeBrown(*FOLD).backproject(q0)[1]
    g = np.linspace(-2.0, 2.0, 61)
    q = np.stack(np.meshgrid(FOLD[2] + 1000 * g, FOLD[3] + 1000 * g), -1).reshape(-1, 2)
    xy = unproject(q, FOLD)
    ok = np.isfinite(xy).all(-1)
    assert ok.sum() > 500
    assert (_cv2_det(xy[ok], FOLD) > 0).all()
    np.testing.assert_allclose(_cv2_uv(xy[ok], FOLD), q[ok], atol=1e-6)


def test_newton_stops_once_converged():
    """brown_undistort stops when every point has converged (quadratic convergence: a few steps), not after
    its 20-iteration cap."""
    calls = []
    real = C.brown_distort

    def counting(*a):
        calls.append(1)
        return real(*a)

    xd = np.array([0.1, -0.3, 0.25])
    yd = np.array([0.2, 0.05, -0.3])
    C.brown_distort, saved = counting, C.brown_distort
    try:
        x, y, ok = C.brown_undistort(xd, yd, -0.2, 0.05, 1e-3, -1e-3, 0.0)
    finally:
        C.brown_distort = saved
    assert ok.all() and len(calls) <= 8
    calls.clear()  # points beyond |x| = 1 or |y| = 1 as well
    C.brown_distort = counting
    try:
        x2, y2, ok2 = C.brown_undistort(np.array([1.5, -2.0, 0.3]), np.array([0.3, 1.0, -1.6]), 0.01, 0.0, 0.0, 0.0, 0.0)
    finally:
        C.brown_distort = saved
    assert ok2.all() and len(calls) <= 8
    np.testing.assert_allclose(_cv2_uv(np.stack([x, y], -1), np.r_[1.0, 1.0, 0.0, 0.0, -0.2, 0.05, 1e-3, -1e-3, 0.0]),
                               np.stack([xd, yd], -1), atol=1e-14)


def test_points_behind_the_camera_are_outside_the_domain():
    """z ≤ 0 is behind the pinhole, z ∈ (−1, 0] included."""
    cam = PinholeBrown(800.0, 800.0, 512.0, 512.0, k1=-0.05)
    P = np.array([[0.01, 0.02, -0.5], [0.0, 0.0, -1e-3], [0.0, 0.0, 0.0], [0.01, 0.02, 0.5]])
    _, valid = cam.project_valid(P)
    assert valid.tolist() == [False, False, False, True]
    assert np.isnan(cam.project(P)[:3]).all() and np.isfinite(cam.project(P)[3]).all()


@pytest.mark.parametrize("edge", ["left", "right", "top", "bottom"])
def test_on_detector_margin_at_each_edge(edge):
    """A point 0.3 px inside one edge and far from the others: on the detector without a margin, off it with
    a 0.5 px margin, on it again 0.7 px inside; 0.3 px and 20 px outside it: off (detector [-0.5, W-0.5) x
    [-0.5, H-0.5))."""
    cam = PinholeBrown(100.0, 100.0, 10.0, 20.0, width=64, height=48)
    for inside, want in ((0.3, (True, False)), (0.7, (True, True)), (-0.3, (False, False)), (-20.0, (False, False))):
        uv = {"left": (-0.5 + inside, 24.0), "right": (63.5 - inside, 24.0),
              "top": (32.0, -0.5 + inside), "bottom": (32.0, 47.5 - inside)}[edge]
        got = (bool(cam.on_detector([uv])[0]), bool(cam.on_detector([uv], margin_px=0.5)[0]))
        assert got == want, (edge, inside)


def test_wrong_trailing_sizes_are_refused():
    with pytest.raises(ValueError, match=r"xy must have shape \(\.\.\., 2\)"):
        distort(np.zeros((4, 3)), np.zeros(5))
    with pytest.raises(ValueError, match=r"dist must have shape \(\.\.\., 5\)"):
        distort(np.zeros((4, 2)), np.zeros(6))
    with pytest.raises(ValueError, match=r"p must have shape \(\.\.\., 3\)"):
        project(np.ones((4, 4)), FOLD)
    with pytest.raises(ValueError, match=r"params must have shape \(\.\.\., 9\)"):
        project(np.ones((4, 3)), np.r_[FOLD, 0.0])
    with pytest.raises(ValueError, match=r"uv must have shape \(\.\.\., 2\)"):
        unproject(np.ones((4, 3)), FOLD)
    # trailing sizes smaller than required too
    with pytest.raises(ValueError, match=r"xy must have shape \(\.\.\., 2\)"):
        distort(np.zeros((4, 1)), np.zeros(5))
    with pytest.raises(ValueError, match=r"p must have shape \(\.\.\., 3\)"):
        project(np.ones((4, 2)), FOLD)
    with pytest.raises(ValueError, match=r"params must have shape \(\.\.\., 9\)"):
        project(np.ones((4, 3)), FOLD[:8])


def test_radial_fold_of_a_pure_k3_term():
    """k3 = −1/7 alone: d/dr[r(1 + k3 r⁶)] = 1 + 7k3 s³ = 1 − s³ vanishes at s = r² = 1 (by hand); no
    radial term at all: no fold (the cap)."""
    assert C.radial_r2_max(0.0, 0.0, -1.0 / 7.0) == pytest.approx(1.0, rel=1e-12)
    assert C.radial_r2_max(0.0, -1.0 / 5.0, 0.0) == pytest.approx(1.0, rel=1e-12)
    assert C.radial_r2_max(0.0, 0.0, 0.0) == 1e6


@pytest.mark.parametrize("shape", [(), (3,), (2, 3)])
def test_unproject_directions_of_any_batch_shape(shape):
    """Without distortion a pixel's direction is ((u − cx)/fx, (v − cy)/fy, 1) normalised (by hand)."""
    cam = PinholeBrown(800.0, 700.0, 300.0, 200.0, width=640, height=480)
    rng = np.random.default_rng(1)
    uv = rng.uniform(0, 480, shape + (2,))
    want = np.stack([(uv[..., 0] - 300.0) / 800.0, (uv[..., 1] - 200.0) / 700.0, np.ones(shape)], -1)
    want /= np.linalg.norm(want, axis=-1, keepdims=True)
    np.testing.assert_allclose(cam.unproject(uv), want, atol=1e-15)
    d, valid = cam.backproject(uv)
    np.testing.assert_allclose(d, want, atol=1e-15)
    assert np.shape(valid) == shape and np.all(valid)


def _fold_by_hand(k1, k2, k3):
    """First s = r² > 0 where 1 + 3k1 s + 5k2 s² + 7k3 s³ = 0, by Brent's method on a sign change (scipy)."""
    from scipy.optimize import brentq

    g = lambda s: 1.0 + 3.0 * k1 * s + 5.0 * k2 * s * s + 7.0 * k3 * s ** 3  # noqa: E731
    s = np.linspace(0.0, 100.0, 100001)
    i = np.flatnonzero(g(s) <= 0)
    return 1e6 if i.size == 0 else brentq(g, s[i[0] - 1], s[i[0]], xtol=1e-15)


@pytest.mark.parametrize("k", [
    [[-0.3, 0.0, 0.01], [-0.2, 0.0, 0.02], [-0.5, 0.0, 0.05]],     # cubic with k2 = 0, k3 > 0
    [[-0.3, -0.05, 0.0], [0.1, -0.2, 0.0], [0.0, -0.1, 0.0]],      # quadratic only (no cubic in the batch)
    [[-0.3, 0.0, 0.0], [-0.1, 0.0, 0.0], [0.2, 0.0, 0.0]],         # linear only
    [[-0.3, 0.0, 0.0], [-0.1, 0.02, 0.0]],                         # two sets
    [[-0.3, 0.0, -0.01], [0.1, 0.0, -0.02]],                       # cubic with k2 = 0, k3 < 0
])
def test_vectorised_fold_of_each_polynomial_degree(k):
    """The batched fold equals the first root found by Brent's method, for batches holding one degree of
    polynomial only, and for cubic ones without a quadratic term."""
    k = np.array(k)
    want = [_fold_by_hand(*r) for r in k]
    np.testing.assert_allclose(C._radial_r2_max_array(k[:, 0], k[:, 1], k[:, 2]), want, rtol=1e-9)
    n = len(k)
    prm = np.concatenate([np.tile([500.0, 500.0, 300.0, 300.0], (n, 1)), k[:, :2], np.zeros((n, 2)), k[:, 2:]], 1)
    # a point just beyond each set's fold is outside the domain, one just inside is projected
    for f, finite in ((1.001, False), (0.999, True)):
        r = np.sqrt(np.minimum(want, 1e4) * f)
        uv = project(np.stack([r, 0 * r, np.ones(n)], -1), prm)
        assert (np.isfinite(uv).all(-1) == (finite | (np.array(want) == 1e6))).all()


def test_empty_batches():
    assert project(np.zeros((0, 3)), np.zeros((0, 9))).shape == (0, 2)
    assert unproject(np.zeros((0, 2)), np.zeros((0, 9))).shape == (0, 2)
    assert C._radial_r2_max_array(np.zeros(0), np.zeros(0), np.zeros(0)).shape == (0,)


SLOW_NEWTON = np.array([1000.0, 1000.0, 500.0, 500.0, -0.3849, 0.2654, 0.0406, -0.2161, 0.0064])


def test_pixels_whose_newton_needs_its_20_steps_are_inverted():
    """With a strong tangential term Newton's walk from the distorted point takes close to its 20 steps for
    these pixels; each has a preimage in the domain (OpenCV projects it back onto the pixel, OpenCV's
    Jacobian is positive there), so every entry point inverts them."""
    q = np.array([[1265.0, 763.5], [1029.1, 5.2], [1067.7, -168.2]])
    cam = PinholeBrown(*SLOW_NEWTON)
    r2max = C.radial_r2_max(*SLOW_NEWTON[[4, 5, 8]])
    d, valid = cam.backproject(q)
    assert valid.all()
    x, y, ok = C.brown_undistort((q[:, 0] - 500.0) / 1000.0, (q[:, 1] - 500.0) / 1000.0, *SLOW_NEWTON[4:])
    assert ok.all()
    for xy in (np.stack([x, y], -1), unproject(q, SLOW_NEWTON), cam.pixel_to_normalized(q), cam.unproject(q)[:, :2] / cam.unproject(q)[:, 2:],
               d[:, :2] / d[:, 2:]):
        assert np.isfinite(xy).all()
        np.testing.assert_allclose(_cv2_uv(xy, SLOW_NEWTON), q, atol=1e-6)
        assert (_cv2_det(xy, SLOW_NEWTON) > 0).all() and (np.sum(xy * xy, -1) < r2max).all()


def test_radial_fold_when_a_leading_coefficient_is_one():
    """Polynomials 1 + 3k1 s + 5k2 s² + 7k3 s³ whose leading coefficient is exactly 1, roots by hand:
    s² − 3s + 1 → (3 − √5)/2; s³ − 3s + 1 → 2·cos(4π/9) (the trigonometric solution)."""
    assert C.radial_r2_max(-1.0, 0.2, 0.0) == pytest.approx((3 - np.sqrt(5)) / 2, rel=1e-12)
    assert C.radial_r2_max(-1.0, 0.0, 1.0 / 7.0) == pytest.approx(2 * np.cos(4 * np.pi / 9), rel=1e-12)


@pytest.mark.parametrize("shape", [(), (4,), (2, 3)])
def test_project_valid_and_normalized_to_pixel_of_any_batch_shape(shape):
    prm = np.array([900.0, 880.0, 320.0, 250.0, -0.2, 0.05, 1e-3, -2e-3, 0.01])
    cam = PinholeBrown(*prm, width=640, height=480)
    rng = np.random.default_rng(2)
    P = np.concatenate([rng.uniform(-0.3, 0.3, shape + (2,)), np.ones(shape + (1,))], -1) * 2.5
    want = _cv2_uv(P.reshape(-1, 3)[:, :2] / P.reshape(-1, 3)[:, 2:], prm).reshape(shape + (2,))
    uv, valid = cam.project_valid(P)
    np.testing.assert_allclose(uv, want, atol=1e-9)
    assert np.shape(valid) == shape and np.all(valid)
    np.testing.assert_allclose(cam.normalized_to_pixel(P[..., :2] / P[..., 2:]), want, atol=1e-9)
    np.testing.assert_allclose(cam.project(P), want, atol=1e-9)


def test_unproject_one_pixel_through_a_batch_of_cameras():
    """One pixel (2,) and three distortion-free cameras (3, 9): xy = ((u − cx)/fx, (v − cy)/fy) each, by hand."""
    prm = np.zeros((3, 9))
    prm[:, :4] = [[800.0, 810.0, 300.0, 200.0], [500.0, 520.0, 310.0, 190.0], [1000.0, 990.0, 290.0, 240.0]]
    q = np.array([412.0, 333.0])
    want = np.stack([(q[0] - prm[:, 2]) / prm[:, 0], (q[1] - prm[:, 3]) / prm[:, 1]], -1)
    np.testing.assert_allclose(unproject(q, prm), want, atol=1e-15)
    xy, dxy_duv, dxy_dk = unproject(q, prm, get_gradients=True)
    np.testing.assert_allclose(xy, want, atol=1e-15)
    np.testing.assert_allclose(dxy_duv, [np.diag([1 / p[0], 1 / p[1]]) for p in prm], rtol=1e-12)
    assert dxy_dk.shape == (3, 2, 9)


def test_project_distort_unproject_take_their_arrays_by_keyword_and_the_gradients_flag_only_by_keyword():
    """project(p=…, params=…), distort(xy=…, dist=…), unproject(uv=…, params=…) are allowed, project(p, params, True) is not
    (get_gradients is keyword-only); a distortion-free pixel is (fx·X/Z + cx, fy·Y/Z + cy) by hand."""
    prm = np.array([800.0, 700.0, 300.0, 200.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    P = np.array([0.2, -0.1, 2.0])
    np.testing.assert_allclose(project(p=P, params=prm), [380.0, 165.0], atol=1e-12)
    with pytest.raises(TypeError):
        project(P, prm, True)
    np.testing.assert_allclose(distort(xy=[0.1, -0.05], dist=np.zeros(5)), [0.1, -0.05], atol=1e-15)
    with pytest.raises(TypeError):
        distort([0.1, -0.05], np.zeros(5), True)
    np.testing.assert_allclose(unproject(uv=[380.0, 165.0], params=prm), [0.1, -0.05], atol=1e-15)
    with pytest.raises(TypeError):
        unproject([380.0, 165.0], prm, True)
