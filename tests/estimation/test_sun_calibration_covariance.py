"""The sweep fit's covariance and its small pieces against truths computed without the module.

The sweep is made as in test_sun_calibration's scipy/OpenCV test (the sun along the rot frame's z, the 2-axis
table's chain R(rot←mount) = Rx(θx)·Ry(θy) from scipy, centroids by cv2.projectPoints), with Gaussian centroid
noise. The covariance's truth: the Jacobian of the same residuals, written here with cv2.projectPoints and
scipy rotations (R(sun←mount) = exp([δ]×)·R_fit, δ about the sensor axes), by central differences at the fit's
solution; then s²·(JᵀJ)⁻¹ with s² = RSS/dof from the fit's residuals, or σ² for a given σ."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rigsim.estimation.sun_calibration import _so3_left_jacobian, calibrate_sun_sensor, sweep_poses
from rigsim.rig.turntable import TurntableModel, TurntableReading

FX, FY, CX, CY, W, H = 272.7, 272.9, 515.3, 508.7, 1024, 1024
DIST = np.array([-0.021, 0.0012, 2e-3, -1.5e-3, 0.0])
R_SUN = Rotation.from_euler("xyz", [0.35, -0.6, 12.0], degrees=True).as_matrix()
NAMES = ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"]


def _project(s, p):
    K = np.array([[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1.0]])
    uv, _ = cv2.projectPoints(s.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, np.array([*p[4:8], 0.0]))
    return uv.reshape(-1, 2)


def _sweep():
    """(readings, sun directions in the mount frame (N, 3), exact centroids (N, 2)) on the detector."""
    g = np.radians(np.arange(-60.0, 60.1, 6.0))
    tx, ty = (a.ravel() for a in np.meshgrid(g, g))
    m = Rotation.from_euler("XY", np.column_stack([tx, ty])).as_matrix().transpose(0, 2, 1) @ np.array([0.0, 0, 1])
    s = m @ R_SUN.T
    uv = _project(s, [FX, FY, CX, CY, *DIST[:4]])
    keep = (s[:, 2] > 0.3) & (uv >= 3).all(1) & (uv[:, 0] <= W - 4) & (uv[:, 1] <= H - 4)
    return TurntableReading({"X": tx[keep], "Y": ty[keep]}), m[keep], uv[keep]


READINGS, M, UV = _sweep()
MODEL = TurntableModel.nominal(["X", "Y"])


def _calibrate(uv, **kw):
    return calibrate_sun_sensor(READINGS, uv, MODEL, W, H, f_guess_px=270.0, **kw)


def _jtj_inv(cal, m=M):
    """(JᵀJ)⁻¹ of the residuals at the fit's solution, J by central differences of the OpenCV model."""
    x0 = np.concatenate([cal.params[:-3], np.zeros(3)])

    def res(x):
        R = Rotation.from_rotvec(x[-3:]).as_matrix() @ cal.R_sun_from_rot
        return _project(m @ R.T, x[:8]).ravel()

    J = np.empty((2 * len(m), len(x0)))
    for k in range(len(x0)):
        h = 1e-4 * max(1.0, abs(x0[k])) if k < 4 else 1e-6
        e = np.zeros_like(x0)
        e[k] = h
        J[:, k] = (res(x0 + e) - res(x0 - e)) / (2 * h)
    return np.linalg.inv(J.T @ J)


def _noisy(seed, sigma=0.05):
    return UV + np.random.default_rng(seed).normal(0.0, sigma, UV.shape)


def _rss_dof(cal):
    r = cal.residuals_px.ravel()
    return float(r @ r), r.size - len(cal.params)


def test_covariance_is_the_residual_scatter_times_the_inverse_normal_matrix():
    uv = _noisy(1)
    cal = _calibrate(uv)
    assert cal.param_names == NAMES + ["rx", "ry", "rz"]
    # the residuals are the OpenCV model's at the solution; rms_px is that of their 2-D lengths
    r = _project(M @ cal.R_sun_from_rot.T, cal.params[:8]) - uv
    np.testing.assert_allclose(cal.residuals_px, r, rtol=0, atol=1e-9)
    assert cal.rms_px == pytest.approx(np.sqrt(np.mean(np.sum(r**2, axis=1))), rel=1e-9)
    rss, dof = _rss_dof(cal)
    want = rss / dof * _jtj_inv(cal)
    np.testing.assert_allclose(cal.covariance, want, rtol=1e-4, atol=0)
    # the rotation block is the last 3×3, about the sensor axes
    assert cal.rotation_covariance_rad2.shape == (3, 3)
    np.testing.assert_allclose(cal.rotation_covariance_rad2, want[-3:, -3:], rtol=1e-4, atol=0)
    np.testing.assert_allclose([cal.sigma[k] for k in cal.param_names], np.sqrt(np.diag(want)), rtol=1e-4)


def test_a_known_centroid_sigma_replaces_the_scatter():
    cal = _calibrate(_noisy(2), centroid_sigma_px=0.2)
    np.testing.assert_allclose(cal.covariance, 0.2**2 * _jtj_inv(cal), rtol=1e-4, atol=0)


def test_sigma_uv_within_the_noise_gives_the_noise_model_covariance():
    """σ of 0.04 and 0.06 px on alternate frames (rms 0.051), noise 0.05 px: χ² (over the rms σ) below dof, so
    the covariance is σ̄²·(JᵀJ)⁻¹, unscaled."""
    sig = np.where((np.arange(len(UV)) % 2 == 0)[:, None], 0.04, 0.06) * np.ones((1, 2))
    cal = _calibrate(_noisy(3), sigma_uv=sig)
    rss, dof = _rss_dof(cal)
    s2 = (0.04**2 + 0.06**2) / 2 if len(UV) % 2 == 0 else np.mean(sig[:, 0] ** 2)
    assert rss / s2 < dof  # the seed's premise: within the noise
    assert cal.fit is not None and cal.fit.chi2 == pytest.approx(rss / s2, rel=1e-9) and cal.fit.dof == dof
    np.testing.assert_allclose(cal.covariance, s2 * _jtj_inv(cal), rtol=1e-4, atol=0)


def test_sigma_uv_below_the_noise_gives_the_scatter_covariance():
    """σ 0.01 px given, noise 0.05 px: χ²/dof ≈ 25, beyond chance, so the covariance is RSS/dof·(JᵀJ)⁻¹."""
    cal = _calibrate(_noisy(4), sigma_uv=np.full(UV.shape, 0.01))
    rss, dof = _rss_dof(cal)
    assert cal.fit.chi2 / cal.fit.dof == pytest.approx(rss / 0.01**2 / dof, rel=1e-9) and rss / 0.01**2 / dof > 10
    np.testing.assert_allclose(cal.covariance, rss / dof * _jtj_inv(cal), rtol=1e-4, atol=0)


@pytest.mark.parametrize("bad", [0.0, -0.05])
def test_sigma_uv_with_a_zero_is_not_judged(bad):
    """A σ of 0 or below among the used frames: no judgement, the residual scatter's covariance."""
    sig = np.full(UV.shape, 0.05)
    sig[5] = bad
    cal = _calibrate(_noisy(5), sigma_uv=sig)
    assert cal.fit is None
    rss, dof = _rss_dof(cal)
    np.testing.assert_allclose(cal.covariance, rss / dof * _jtj_inv(cal), rtol=1e-4, atol=0)


def test_the_noise_sigma_of_frames_left_out_does_not_count():
    """A frame 40 px off with σ = 1 px is an outlier (40σ); the judgement's rms σ is over the frames kept (0.05)."""
    uv = _noisy(6)
    uv[10] += 40.0
    sig = np.full(UV.shape, 0.05)
    sig[10] = 1.0
    cal = _calibrate(uv, sigma_uv=sig, outlier_sigma=8.0)
    assert cal.outliers.tolist() == [10] and cal.n_points == len(UV) - 1
    assert cal.fit.noise_rms == pytest.approx(0.05, rel=1e-12)
    rss, dof = _rss_dof(cal)
    assert rss / 0.05**2 < dof  # the seed's premise: within the noise, unscaled
    np.testing.assert_allclose(cal.covariance, 0.05**2 * _jtj_inv(cal, np.delete(M, 10, 0)), rtol=1e-4, atol=0)


@pytest.mark.parametrize("norm", [0.0, 1e-9, 3e-7, 9e-7, 2e-6, 1e-3, 0.3, 1.5])
def test_so3_left_jacobian_satisfies_its_defining_identity(norm):
    """J_l(δ)·[δ]× = exp([δ]×) − I (the series Σ Kⁿ/(n+1)! times K), exp from scipy; on both sides of
    the 1e-6 switch to the series. And J_l(δ)·ε = the first-order change of log(exp([δ+ε]×)·exp([δ]×)ᵀ)."""
    d = np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81]) * norm
    K = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
    Jl = _so3_left_jacobian(d)
    np.testing.assert_allclose(Jl @ K, Rotation.from_rotvec(d).as_matrix() - np.eye(3), rtol=0,
                               atol=1e-15 + 1e-13 * norm)
    # J_l(δ) = ∫₀¹ exp(s[δ]×) ds, by Gauss–Legendre quadrature of scipy's rotation matrices: resolves the
    # K²/6 term of the series (≈1e-13 at |δ| = 1e-6) to float64 rounding
    xg, wg = np.polynomial.legendre.leggauss(20)
    quad = sum(w / 2 * Rotation.from_rotvec((x + 1) / 2 * d).as_matrix() for x, w in zip(xg, wg))
    np.testing.assert_allclose(Jl, quad, rtol=0, atol=2e-15)
    R = Rotation.from_rotvec(d)
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1e-6
        num = ((Rotation.from_rotvec(d + e) * R.inv()).as_rotvec() - (Rotation.from_rotvec(d - e) * R.inv()).as_rotvec()) / 2e-6
        np.testing.assert_allclose(Jl[:, k], num, rtol=0, atol=1e-8)


def test_sweep_poses_is_the_grid_by_hand():
    p = sweep_poses(["X", "Y"], 10.0, 5.0, fixed={"Z": 0.25})
    a = np.radians([-10.0, -5.0, 0.0, 5.0, 10.0])
    np.testing.assert_allclose(p["X"], np.repeat(a, 5), atol=1e-15)
    np.testing.assert_allclose(p["Y"], np.tile(a, 5), atol=1e-15)
    np.testing.assert_array_equal(p["Z"], np.full(25, 0.25))
    assert sorted(p) == ["X", "Y", "Z"]
    assert list(sweep_poses(["A", "B"], 60.0, 5.0)) == ["A", "B"] and len(sweep_poses(["A", "B"], 60.0, 5.0)["A"]) == 625


def test_too_few_points_names_the_field_only_when_it_left_frames_out():
    """The message names the field limit only when the limit left frames out."""
    few = TurntableReading({k: np.asarray(READINGS[k])[:7] for k in READINGS})
    with pytest.raises(ValueError, match=r"at least 8 points on the detector, got 7$"):
        calibrate_sun_sensor(few, UV[:7], MODEL, W, H, f_guess_px=270.0)
    r = np.hypot(UV[:, 0] - (W - 1) / 2, UV[:, 1] - (H - 1) / 2)
    n_in = int(np.sum(r <= 270.0 * np.tan(np.radians(8.0))))  # the nominal camera's 8° circle
    assert 0 < n_in < 8
    with pytest.raises(ValueError, match=rf"got {n_in} within 8° of the axis"):
        calibrate_sun_sensor(READINGS, UV, MODEL, W, H, f_guess_px=270.0, max_field_deg=8.0)


@pytest.mark.parametrize("limit", [90.0, 90.5, 100.0, 180.0])
def test_a_field_limit_of_90_degrees_or_more_keeps_every_frame(limit):
    cal = _calibrate(_noisy(7), max_field_deg=limit)
    assert cal.n_points == len(UV) and len(cal.outside_field) == 0


def test_an_unknown_sigma_takes_the_median_in_the_outlier_test():
    """Frame 20 has no σ (NaN) and is 1 px off: with the others' median σ (0.05 px) that is 20σ, an outlier
    at the limit 8; were its σ taken as 1 px it would stay."""
    uv = _noisy(8)
    uv[20, 0] += 1.0
    sig = np.full(UV.shape, 0.05)
    sig[20] = np.nan
    assert _calibrate(uv, sigma_uv=sig, outlier_sigma=8.0).outliers.tolist() == [20]


def test_a_limit_of_one_robust_sigma_still_tests():
    """Any limit > 0 switches the test on, 1 included: a frame 5 px off (≈100 robust σ) is left out."""
    uv = _noisy(9)
    uv[30, 1] += 5.0
    cal = _calibrate(uv, outlier_sigma=1.0)
    assert 30 in cal.outliers.tolist() and cal.n_points == len(UV) - len(cal.outliers)


def test_a_negative_sigma_is_unknown_in_the_outlier_test():
    """A σ ≤ 0 is no σ: frame 40, 1 px off with σ = −0.05 px, is judged with the median σ and left out."""
    uv = _noisy(10)
    uv[40, 1] += 1.0
    sig = np.full(UV.shape, 0.05)
    sig[40] = -0.05
    assert _calibrate(uv, sigma_uv=sig, outlier_sigma=8.0).outliers.tolist() == [40]


def test_eight_frames_are_enough():
    """8 frames (16 equations, 11 unknowns): the fit runs and returns the noise-free camera's centroids."""
    i = np.linspace(0, len(UV) - 1, 8).round().astype(int)
    few = TurntableReading({k: np.asarray(READINGS[k])[i] for k in READINGS})
    cal = calibrate_sun_sensor(few, UV[i], MODEL, W, H, f_guess_px=270.0)
    assert cal.n_points == 8 and cal.rms_px < 1e-6


def test_the_returned_camera_is_the_fitted_one_with_the_unfitted_terms_zero():
    """Without k3 (and without p1, p2) in the fit, the returned camera has them at 0: it projects the sweep
    as OpenCV does with the fitted intrinsics and the other terms 0."""
    uv = _noisy(11)
    for tangential in (True, False):
        cal = _calibrate(uv, fit_tangential=tangential)
        p = dict(zip(cal.param_names, cal.params))
        want = [p["fx"], p["fy"], p["cx"], p["cy"], p["k1"], p["k2"], p.get("p1", 0.0), p.get("p2", 0.0)]
        assert cal.camera.k3 == 0.0 and (tangential or cal.camera.p1 == cal.camera.p2 == 0.0)
        s = M @ cal.R_sun_from_rot.T
        np.testing.assert_allclose(cal.camera.project(s), _project(s, want), rtol=0, atol=1e-9)


def test_repr_leaves_out_the_per_frame_arrays():
    cal = _calibrate(_noisy(12))
    assert "residuals_px=" not in repr(cal) and "uv=" not in repr(cal) and "rms_px=" in repr(cal)


@pytest.mark.parametrize("side", [(1, 0), (-1, 0), (0, 1), (0, -1)])
def test_the_field_limit_is_measured_from_the_detector_centre(side):
    """The limit's circle is centred on ((W − 1)/2, (H − 1)/2) with radius f_guess·tan(limit): put its edge
    0.01 px beyond a frame about 300 px from the centre on each side; exactly the frames outside, counted by
    hand, are left out."""
    c = np.array([(W - 1) / 2, (H - 1) / 2])
    d = UV - c
    r = np.hypot(*d.T)
    i = int(np.argmin(np.abs(r - 300.0) + 1e3 * (d @ np.array(side) < 0.9 * r)))
    limit = np.degrees(np.arctan((r[i] + 0.01) / 270.0))
    cal = _calibrate(UV, max_field_deg=limit)
    np.testing.assert_array_equal(cal.outside_field, np.flatnonzero(r > r[i] + 0.01))
    assert i not in cal.outside_field


def test_a_frame_claiming_a_small_sigma_is_judged_by_it():
    """Frame 50 says σ = 0.01 px (the others 0.05) and is 1 px off: 100 of its σ, an outlier."""
    uv = _noisy(13)
    uv[50, 0] += 1.0
    sig = np.full(UV.shape, 0.05)
    sig[50] = 0.01
    assert _calibrate(uv, sigma_uv=sig, outlier_sigma=8.0).outliers.tolist() == [50]


def _nine(bad, seed):
    i = np.linspace(0, len(UV) - 1, 9).round().astype(int)
    few = TurntableReading({k: np.asarray(READINGS[k])[i] for k in READINGS})
    uv = UV[i] + np.random.default_rng(seed).normal(0.0, 0.01, (9, 2))
    uv[bad, 0] += 20.0
    return calibrate_sun_sensor(few, uv, MODEL, W, H, f_guess_px=270.0, outlier_sigma=8.0)


def test_a_nine_frame_sweep_loses_its_one_outlier():
    """8 frames are enough for the refit: of 9 frames, the middle one, 20 px off, is left out."""
    cal = _nine([4], 14)
    assert cal.outliers.tolist() == [4] and cal.n_points == 8 and cal.rms_px < 0.05


@pytest.mark.parametrize("bad", [[3, 4, 5], [4, 5]])
def test_the_outlier_test_never_leaves_fewer_than_eight_frames(bad):
    """Of 9 frames, 2 or 3 off by 20 px: leaving them out would leave 7 or 6 frames, so every frame is kept
    (the plain fit)."""
    cal = _nine(bad, 15)
    assert len(cal.outliers) == 0 and cal.n_points == 9


def test_every_sigma_unknown_is_the_same_as_none():
    """With no usable σ at all (NaN everywhere), the outlier test runs as without σ: frame 60, 3 px off, is out."""
    uv = _noisy(16)
    uv[60, 0] += 3.0
    none = _calibrate(uv, outlier_sigma=8.0)
    nan = _calibrate(uv, sigma_uv=np.full(UV.shape, np.nan), outlier_sigma=8.0)
    assert none.outliers.tolist() == nan.outliers.tolist() == [60] and nan.fit is None
    np.testing.assert_array_equal(nan.params, none.params)


def test_sun_directions_in_mount_are_unit_vectors_of_the_table_chain():
    """d_rot of any length: the unit sun direction R(rot←mount)ᵀ·d̂, R(rot←mount) = Rx(θx)·Ry(θy) from scipy."""
    from rigsim.estimation.sun_calibration import sun_directions_in_mount

    tx, ty = np.radians([10.0, -35.0, 50.0]), np.radians([-20.0, 5.0, 40.0])
    d = np.array([0.2, -0.1, 2.0])
    got = sun_directions_in_mount(MODEL, TurntableReading({"X": tx, "Y": ty}), d)
    R = Rotation.from_euler("XY", np.column_stack([tx, ty])).as_matrix()
    np.testing.assert_allclose(got, R.transpose(0, 2, 1) @ (d / np.linalg.norm(d)), atol=1e-15)
