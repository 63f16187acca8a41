"""rigsim.optics.camera: the one pinhole + Brown model — values against OpenCV, analytic Jacobians
against OpenCV's and central differences, broadcasting, domain, and PinholeBrown's old behaviour."""

import json

import cv2
import numpy as np
import pytest
from scipy.optimize import brentq

from rigsim.optics import camera as C
from rigsim.optics.camera import (
    PARAM_NAMES,
    PinholeBrown,
    TelecentricCamera,
    distort,
    project,
    radial_r2_max,
    unproject,
)

W = H = 1024


def _random_params(rng, n):
    f = rng.uniform(200, 3000, (n, 1))
    return np.concatenate([
        f * rng.uniform(0.97, 1.03, (n, 1)), f,  # fx, fy
        rng.uniform(0, W - 1, (n, 2)),  # cx, cy
        rng.uniform(-0.3, 0.3, (n, 1)), rng.uniform(-0.1, 0.1, (n, 1)),  # k1, k2
        rng.uniform(-1e-3, 1e-3, (n, 2)), rng.uniform(-0.05, 0.05, (n, 1)),  # p1, p2, k3
    ], axis=1)


def _points_in_domain(rng, params, n, r_max=0.8):
    """Points (n, 3) at depth 0.5..10 with x² + y² < min(r_max², 0.8 r2_max)."""
    r2lim = min(r_max ** 2, 0.8 * radial_r2_max(*params[[4, 5, 8]]))
    r = np.sqrt(rng.uniform(0, r2lim, n))
    ph = rng.uniform(0, 2 * np.pi, n)
    z = rng.uniform(0.5, 10.0, n)
    return np.stack([r * np.cos(ph) * z, r * np.sin(ph) * z, z], -1)


def _cv2_project(P, params):
    K = np.array([[params[0], 0, params[2]], [0, params[1], params[3]], [0, 0, 1.0]])
    uv, J = cv2.projectPoints(P.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, params[4:])
    # jacobian rows interleave (u_i, v_i); columns: rvec(3), tvec(3), fx, fy, cx, cy, k1, k2, p1, p2, k3
    return uv.reshape(-1, 2), np.stack([J[0::2], J[1::2]], axis=1)


PARAM_SETS = _random_params(np.random.default_rng(42), 6)


def test_param_names_order():
    assert PARAM_NAMES == ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


@pytest.mark.parametrize("i", range(len(PARAM_SETS)))
def test_project_and_jacobians_match_cv2(i):
    rng = np.random.default_rng(i)
    prm = PARAM_SETS[i]
    P = _points_in_domain(rng, prm, 300)
    uv, du_dp, du_dk = project(P, prm, get_gradients=True)
    ref, Jcv = _cv2_project(P, prm)
    np.testing.assert_allclose(uv, ref, rtol=0, atol=1e-9)
    assert np.allclose(project(P, prm), uv, rtol=0, atol=0)  # same values without gradients
    # intrinsic + distortion columns; tvec columns are ∂uv/∂p (the point is p + t)
    np.testing.assert_allclose(du_dk, Jcv[:, :, 6:15], rtol=1e-9, atol=1e-9 * np.abs(Jcv[:, :, 6:15]).max())
    np.testing.assert_allclose(du_dp, Jcv[:, :, 3:6], rtol=1e-9, atol=1e-9 * np.abs(du_dp).max())


def _central(fun, x, steps):
    """Central differences of fun (…, 2) wrt the last axis of x (…, n) → (…, 2, n)."""
    cols = []
    for j, h in enumerate(steps):
        e = np.zeros(x.shape[-1])
        e[j] = h
        cols.append((fun(x + e) - fun(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


PARAM_STEPS = np.array([1e-3, 1e-3, 1e-3, 1e-3, 1e-6, 1e-6, 1e-7, 1e-7, 1e-6])


def _assert_jac(ana, num, rel=1e-7):
    # per column, relative to the column's magnitude over all points
    scale = np.abs(num).max(axis=(0, 1), keepdims=True) + 1e-300
    err = np.abs(ana - num) / scale
    assert np.isfinite(ana).all() and err.max() < rel, err.max(axis=(0, 1))


@pytest.mark.parametrize("i", [0, 3, 5])
def test_project_gradients_central_differences(i):
    rng = np.random.default_rng(10 + i)
    prm = PARAM_SETS[i]
    P = _points_in_domain(rng, prm, 200)
    _, du_dp, du_dk = project(P, prm, get_gradients=True)
    num_p = _central(lambda q: project(q, prm), P, [1e-6 * 5] * 3)
    num_k = _central(lambda k: project(P, k), prm, PARAM_STEPS)
    _assert_jac(du_dp, num_p)
    _assert_jac(du_dk, num_k)


def test_distort_gradients():
    rng = np.random.default_rng(3)
    dist = PARAM_SETS[1, 4:]
    xy = rng.uniform(-0.5, 0.5, (100, 2))
    xyd, J, D = distort(xy, dist, get_gradients=True)
    np.testing.assert_array_equal(xyd, np.stack(C.brown_distort(xy[:, 0], xy[:, 1], *dist), -1))
    _assert_jac(J, _central(lambda q: distort(q, dist), xy, [1e-6, 1e-6]))
    _assert_jac(D, _central(lambda k: distort(xy, k), dist, PARAM_STEPS[4:]))


@pytest.mark.parametrize("i", [0, 2, 4])
def test_unproject_round_trip_and_gradients(i):
    rng = np.random.default_rng(20 + i)
    prm = PARAM_SETS[i]
    P = _points_in_domain(rng, prm, 200)
    uv = project(P, prm)
    xy, dxy_duv, dxy_dk = unproject(uv, prm, get_gradients=True)
    np.testing.assert_allclose(xy, P[:, :2] / P[:, 2:], rtol=0, atol=1e-12)
    uv2 = project(np.concatenate([xy, np.ones((len(xy), 1))], -1), prm)
    np.testing.assert_allclose(uv2, uv, rtol=0, atol=1e-10)
    _assert_jac(dxy_duv, _central(lambda q: unproject(q, prm), uv, [1e-3, 1e-3]))
    _assert_jac(dxy_dk, _central(lambda k: unproject(uv, k), prm, PARAM_STEPS))
    # dxy/duv is the inverse of ∂uv/∂(x, y) at z = 1
    _, du_dp, _ = project(np.concatenate([xy, np.ones((len(xy), 1))], -1), prm, get_gradients=True)
    np.testing.assert_allclose(du_dp[:, :, :2] @ dxy_duv, np.broadcast_to(np.eye(2), (len(xy), 2, 2)), atol=1e-9)


def _loop_equal(fun, a, b, outs):
    """outs from fun(a, b) broadcast; compare with the per-element calls."""
    shape = np.broadcast_shapes(a.shape[:-1], b.shape[:-1])
    A = np.broadcast_to(a, shape + a.shape[-1:])
    B = np.broadcast_to(b, shape + b.shape[-1:])
    for idx in np.ndindex(*shape):
        for o, r in zip(outs, fun(A[idx], B[idx])):
            np.testing.assert_allclose(o[idx], r, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("pshape,kshape", [((4, 5), ()), ((5,), (5,)), ((), (2, 1))])
def test_broadcasting(pshape, kshape):
    rng = np.random.default_rng(7)
    n = int(np.prod(pshape))
    P = _points_in_domain(rng, PARAM_SETS[0], n, r_max=0.3).reshape(pshape + (3,))
    k = (PARAM_SETS[:int(np.prod(kshape))] if kshape else PARAM_SETS[0]).reshape(kshape + (9,))
    k = k.copy()
    k[..., 4:] *= 0.2  # keep every point inside every set's domain
    shape = np.broadcast_shapes(pshape, kshape)
    outs = project(P, k, get_gradients=True)
    assert [o.shape for o in outs] == [shape + (2,), shape + (2, 3), shape + (2, 9)]
    assert np.isfinite(outs[0]).all()
    _loop_equal(lambda a, b: project(a, b, get_gradients=True), P, k, outs)
    uv = outs[0]
    uouts = unproject(uv, k, get_gradients=True)
    assert [o.shape for o in uouts] == [shape + (2,), shape + (2, 2), shape + (2, 9)]
    _loop_equal(lambda a, b: unproject(a, b, get_gradients=True), uv, k, uouts)
    xy = P[..., :2] / P[..., 2:]
    douts = distort(xy, k[..., 4:], get_gradients=True)
    assert [o.shape for o in douts] == [shape + (2,), shape + (2, 2), shape + (2, 5)]
    _loop_equal(lambda a, b: distort(a, b, get_gradients=True), xy, k[..., 4:], douts)


def test_domain_is_nan_with_nan_gradients():
    prm = np.array([800.0, 800.0, 512.0, 512.0, -0.3, 0.0, 0.0, 0.0, 0.0])
    r2max = radial_r2_max(-0.3, 0.0, 0.0)
    assert r2max == pytest.approx(1 / 0.9, rel=1e-14)
    rin, rout = np.sqrt(0.999 * r2max), np.sqrt(1.001 * r2max)
    P = np.array([[0.1, 0.2, 0.0], [0.1, 0.2, -1.0], [rout, 0, 1], [0, 2 * rout, 2], [rin, 0, 1], [0.1, 0.1, 1]])
    uv, du_dp, du_dk = project(P, prm, get_gradients=True)
    bad = np.array([True, True, True, True, False, False])
    assert (np.isnan(uv).all(-1) == bad).all() and np.isfinite(uv[~bad]).all()
    assert np.isnan(du_dp[bad]).all() and np.isfinite(du_dp[~bad]).all()
    assert np.isnan(du_dk[bad]).all() and np.isfinite(du_dk[~bad]).all()
    cam = PinholeBrown.from_params(prm, W, H)
    uvv, valid = cam.project_valid(P)
    np.testing.assert_array_equal(valid, ~bad)
    np.testing.assert_array_equal(uvv[valid], uv[valid])
    assert np.isfinite(uvv[1:]).all()  # project_valid does not clear uv behind the camera
    # pixels whose distorted radius exceeds the fold (max r·radial = (2/3)·sqrt(r2max)) have no inverse
    rd_fold = np.sqrt(r2max) * (1 - 0.3 * r2max)
    q = np.array([[512 + 800 * 1.05 * rd_fold, 512.0], [512 + 800 * 0.9 * rd_fold, 512.0]])
    xy, dxy_duv, dxy_dk = unproject(q, prm, get_gradients=True)
    assert np.isnan(xy[0]).all() and np.isnan(dxy_duv[0]).all() and np.isnan(dxy_dk[0]).all()
    assert np.isfinite(xy[1]).all() and np.isfinite(dxy_dk[1]).all()
    d, ok = cam.backproject(q)
    assert ok.tolist() == [False, True] and np.isnan(cam.unproject(q)[0]).all()
    # keep_invalid: Newton's values stay (finite) and the valid mask says which ones hold
    xk, duk, dkk, valid = unproject(q, prm, get_gradients=True, keep_invalid=True)
    assert valid.tolist() == [False, True] and np.isfinite(xk).all() and np.isfinite(dkk).all()
    np.testing.assert_array_equal(xk[1], xy[1])
    np.testing.assert_array_equal(dkk[1], dxy_dk[1])
    xk2, valid2 = unproject(q, prm, keep_invalid=True)
    np.testing.assert_array_equal(xk2, xk)
    np.testing.assert_array_equal(valid2, valid)


def _first_fold_by_scan(k1, k2, k3, cap=1e6):
    """Independent reference: the first s = r² > 0 where d/dr[r·radial(r)] ∝ 1 + 3k1 s + 5k2 s² + 7k3 s³
    changes sign, by a dense log-spaced scan and Brent's method (no polynomial roots)."""
    g = lambda s: 1.0 + s * (3.0 * k1 + s * (5.0 * k2 + 7.0 * k3 * s))  # noqa: E731
    s = np.concatenate([[0.0], np.logspace(-6, np.log10(cap), 20001)])
    v = g(s)
    neg = np.nonzero(v <= 0.0)[0]
    if len(neg) == 0:
        return cap
    i = neg[0]
    return brentq(g, s[i - 1], s[i], xtol=1e-15, rtol=1e-14)


def test_radial_r2_max_scalar_and_vectorised_equal_scan():
    rng = np.random.default_rng(11)
    k = np.stack([rng.uniform(-0.5, 0.5, 300), rng.uniform(-0.2, 0.2, 300), rng.uniform(-0.1, 0.1, 300)], -1)
    k[::5, 2] = 0.0
    k[::7, 1:] = 0.0
    k[::11] = 0.0
    old = np.array([_first_fold_by_scan(*r) for r in k])
    new = np.array([radial_r2_max(*r) for r in k])
    vec = C._radial_r2_max_array(k[:, 0], k[:, 1], k[:, 2])
    np.testing.assert_allclose(new, old, rtol=1e-9)
    np.testing.assert_allclose(vec, new, rtol=1e-12)
    assert (old < 1e6).sum() > 100 and (old == 1e6).sum() > 10


class _OldPinholeBrown:
    """The formulas of PinholeBrown before the rewrite (on_detector was closed at the top edge)."""

    def __init__(self, *p, width=1024, height=1024):
        self.p = np.array(p, float)
        self.width, self.height = width, height

    def project(self, dirs):
        fx, fy, cx, cy, k1, k2, p1, p2, k3 = self.p
        z = dirs[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = dirs[..., :2] / z[..., None]
        xd, yd = C.brown_distort(xy[..., 0], xy[..., 1], k1, k2, p1, p2, k3)
        uv = np.stack([fx * xd + cx, fy * yd + cy], axis=-1)
        r2 = np.sum(xy * xy, axis=-1)
        uv[(z <= 0) | ~(r2 < _first_fold_by_scan(k1, k2, k3))] = np.nan
        return uv

    def pixel_to_normalized(self, uv):
        fx, fy, cx, cy, k1, k2, p1, p2, k3 = self.p
        x, y, ok = C.brown_undistort((uv[..., 0] - cx) / fx, (uv[..., 1] - cy) / fy, k1, k2, p1, p2, k3,
                                     _first_fold_by_scan(k1, k2, k3), 20)
        xy = np.stack([x, y], -1)
        xy[~ok] = np.nan
        return xy


def test_pinholebrown_keeps_old_results():
    rng = np.random.default_rng(5)
    for prm in PARAM_SETS[:3]:
        cam, old = PinholeBrown(*prm), _OldPinholeBrown(*prm)
        d = rng.normal(size=(400, 3))
        d[:, 2] = np.abs(d[:, 2]) * 2
        d[:20, 2] *= -1  # some behind the camera
        uv = cam.project(d)
        np.testing.assert_array_equal(uv, old.project(d))
        assert np.isnan(uv).any() and np.isfinite(uv).any()
        uvg, du_dd, du_dk = cam.project(d, get_gradients=True)
        np.testing.assert_array_equal(uvg, uv)
        assert du_dd.shape == (400, 2, 3) and du_dk.shape == (400, 2, 9)
        q = np.concatenate([uv[np.isfinite(uv).all(-1)][:50], rng.uniform(-2000, 3000, (50, 2))])
        np.testing.assert_array_equal(cam.pixel_to_normalized(q), old.pixel_to_normalized(q))
        xy = rng.uniform(-0.3, 0.3, (10, 2))
        np.testing.assert_array_equal(cam.normalized_to_pixel(xy),
                                      project(np.concatenate([xy, np.ones((10, 1))], -1), prm))
        s = cam.unproject(q)
        ok = np.isfinite(s).all(-1)
        np.testing.assert_allclose(np.linalg.norm(s[ok], axis=-1), 1.0, atol=1e-15)
        dirs, valid = cam.backproject(q)
        np.testing.assert_array_equal(valid, ok)
        np.testing.assert_array_equal(dirs[ok], s[ok])


def test_pinholebrown_accessors():
    prm = PARAM_SETS[2]
    cam = PinholeBrown.from_params(prm, 640, 480)
    np.testing.assert_array_equal(cam.params(), prm)
    np.testing.assert_array_equal(cam.dist_coeffs(), prm[4:])
    np.testing.assert_array_equal(cam.camera_matrix(), [[prm[0], 0, prm[2]], [0, prm[1], prm[3]], [0, 0, 1]])
    d = cam.as_dict()
    assert list(d) == list(PARAM_NAMES) + ["width", "height"]
    assert PinholeBrown(**json.loads(json.dumps(d))) == cam
    assert type(d["width"]) is int and type(d["fx"]) is float
    c2 = cam.with_params(k1=0.0, width=100)
    assert (c2.k1, c2.width, c2.fx) == (0.0, 100, cam.fx) and cam.k1 == prm[4]
    assert cam.r2_max == radial_r2_max(cam.k1, cam.k2, cam.k3)
    assert PinholeBrown(10.0, 10.0, 0, 0, width=np.int64(8), height=8.0).as_dict()["height"] == 8
    a, b, c, dd = cam.distort_jacobian(0.1, -0.2)
    assert (a, b, c, dd) == C.brown_jacobian(0.1, -0.2, *prm[4:])


def test_on_detector_is_half_open_and_false_for_nan():
    cam = PinholeBrown(100.0, 100.0, 10.0, 20.0, width=64, height=48)
    uv = np.array([[-0.5, -0.5], [63.5 - 1e-9, 47.5 - 1e-9], [63.5, 0], [0, 47.5], [-0.5 - 1e-9, 0],
                   [np.nan, 0], [0, np.inf]])
    assert cam.on_detector(uv).tolist() == [True, True, False, False, False, False, False]
    assert cam.on_detector(uv[:2], margin_px=0.5).tolist() == [False, False]
    assert cam.on_detector([[0.0, 0.0]], margin_px=0.5).tolist() == [True]


def test_flux_weight():
    cam0 = PinholeBrown(500.0, 500.0, 511.5, 511.5)
    assert cam0.flux_weight(np.array([511.5, 511.5])) == pytest.approx(1.0, abs=1e-15)
    uv = np.array([[800.0, 200.0], [20.0, 900.0]])
    ct = cam0.backproject(uv)[0][:, 2]
    np.testing.assert_allclose(cam0.flux_weight(uv), ct ** 4, rtol=1e-13)
    # with distortion: ∝ cosθ · dΩ/dA, with dΩ = cos³θ dx dy and dA = |∂uv/∂xy| dx dy
    prm = PARAM_SETS[1]
    cam = PinholeBrown(*prm)
    q = project(_points_in_domain(np.random.default_rng(9), prm, 50), prm)
    xy, dxy_duv, _ = unproject(q, prm, get_gradients=True)
    ct = 1 / np.sqrt(1 + np.sum(xy * xy, -1))
    np.testing.assert_allclose(cam.flux_weight(q), prm[0] * prm[1] * ct ** 4 * np.linalg.det(dxy_duv), rtol=1e-12)
    far = np.array([[1e7, 0.0]])
    assert cam.flux_weight(far).tolist() == [0.0] or np.isfinite(cam.unproject(far)).all()


def test_validation_messages():
    with pytest.raises(ValueError, match=r"PinholeBrown\.fx = -1\.0: must be a finite number > 0"):
        PinholeBrown(fx=-1.0, fy=1.0, cx=0.0, cy=0.0)
    with pytest.raises(ValueError, match=r"PinholeBrown\.fy = 0\.0"):
        PinholeBrown(1.0, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match=r"PinholeBrown\.k2 = nan: must be a finite"):
        PinholeBrown(1.0, 1.0, 0.0, 0.0, k2=float("nan"))
    with pytest.raises(ValueError, match=r"PinholeBrown\.width = 0: must be an integer >= 1"):
        PinholeBrown(1.0, 1.0, 0.0, 0.0, width=0)
    with pytest.raises(ValueError, match=r"PinholeBrown\.height = 2\.5"):
        PinholeBrown(1.0, 1.0, 0.0, 0.0, height=2.5)
    with pytest.raises(ValueError, match="fx"):
        PinholeBrown(1.0, 1.0, 0.0, 0.0).with_params(fx=float("inf"))


def test_telecentric_camera():
    cam = TelecentricCamera(pixel_size_mm=0.01, cx=100.0, cy=50.0, width=200, height=100)
    uv, valid = cam.project(np.array([[0.1, -0.2, 1.0], [0.0, 0.0, -1.0]]))
    np.testing.assert_allclose(uv, [[110.0, 30.0], [100.0, 50.0]])
    assert valid.tolist() == [True, False]
    assert cam.as_dict() == {"pixel_size_mm": 0.01, "cx": 100.0, "cy": 50.0, "width": 200, "height": 100}
    with pytest.raises(ValueError, match="pixel_size_mm"):
        TelecentricCamera(pixel_size_mm=-1.0, cx=0.0, cy=0.0, width=10, height=10)
