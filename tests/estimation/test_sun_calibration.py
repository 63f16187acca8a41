"""Unified intrinsic + extrinsic calibration (seed 001 step B) against truth and Monte Carlo."""

import numpy as np
import pytest

from rigsim.estimation.sun_calibration import calibrate_sun_sensor
from rigsim.frames import small_angle_error
from rigsim.procedures.cube_mirror import campaign as cm
from rigsim.rig import load_rig
from rigsim.rig.turntable import TurntableModel
from rigsim.truth.cube_mirror.realization import realization_from_rig

RIG = load_rig("sun_sensor_2axis_diaphragm")


def _truth_vector(rig, names):
    ss = rig.sun_sensor
    t = {"fx": ss.fx_px, "fy": ss.fy_px, "cx": ss.principal_point_px[0], "cy": ss.principal_point_px[1], **ss.distortion.model_dump()}
    return np.array([t[n] for n in names])


def _fit(rig, sigma_px, rng):
    real = realization_from_rig(rig, ideal=True)
    noise = cm.Noise(centroid_sigma_px=sigma_px)
    readings, uv = cm.simulate_sweep(rig, real, noise, rng)
    ss = rig.sun_sensor
    cal = calibrate_sun_sensor(readings, uv, TurntableModel.nominal_for(rig.turntable), *ss.resolution_px, f_guess_px=ss.fx_px)
    return cal, real


def test_sweep_keeps_only_poses_on_the_detector():
    readings, uv = cm.simulate_sweep(RIG, realization_from_rig(RIG, ideal=True), cm.Noise(), np.random.default_rng(0))
    assert 400 < len(uv) < 625  # 25×25 grid, the diagonal corners fall off the 1024² detector
    assert uv.min() >= 2.5 and uv.max() <= 1020.5


def test_noise_free_fit_is_exact():
    cal, real = _fit(RIG, 0.0, np.random.default_rng(0))
    names = cal.param_names[:-3]
    np.testing.assert_allclose(cal.params[:-3], _truth_vector(RIG, names), rtol=1e-8, atol=1e-9)
    assert np.abs(small_angle_error(cal.R_sun_from_rot, real.R_sun_from_mount)).max() < 1e-10
    assert cal.rms_px < 1e-8


def test_monte_carlo_matches_predicted_covariance():
    """100 trials at 0.05 px: ≥ 99 % of (trial, parameter) within 3σ of truth, and the predicted σ
    agrees with the Monte-Carlo scatter to within 20 % for every parameter and rotation axis."""
    rng = np.random.default_rng(2024)
    n = 100
    errs, sigmas = [], []
    for _ in range(n):
        cal, real = _fit(RIG, 0.05, rng)
        names = cal.param_names[:-3]
        e_int = cal.params[:-3] - _truth_vector(RIG, names)
        e_rot = small_angle_error(cal.R_sun_from_rot, real.R_sun_from_mount)
        errs.append(np.concatenate([e_int, e_rot]))
        sigmas.append(np.sqrt(np.diag(cal.covariance)))
    errs, sigmas = np.array(errs), np.array(sigmas)
    z = errs / sigmas
    assert np.mean(np.abs(z) < 3) >= 0.99
    ratio = errs.std(axis=0, ddof=1) / sigmas.mean(axis=0)
    assert np.all(np.abs(ratio - 1) < 0.20), dict(zip(cal.param_names, ratio.round(3)))


def test_too_few_points_is_a_clear_error():
    with pytest.raises(ValueError, match="at least 8 points"):
        calibrate_sun_sensor({"X": np.zeros(3), "Y": np.zeros(3)}, np.zeros((3, 2)), TurntableModel.nominal(["X", "Y"]), 1024, 1024, 270.0)


def test_analytic_jacobian_matches_central_differences():
    """The fit's Jacobian is analytic (camera model + SO(3) left Jacobian), not finite differences.

    Per column, central differences with step h err by rounding ≈ ε·max|r|/h plus truncation,
    estimated by Richardson from the steps h and 2h as |D(2h) − D(h)|/3; allowed: 4× their sum
    (and, as before, 1e-7 of the column's largest entry)."""
    from scipy.spatial.transform import Rotation

    from rigsim.estimation.sun_calibration import INTRINSIC_NAMES, SweepModel

    rng = np.random.default_rng(1)
    m = rng.normal(size=(50, 3))
    m[:, 2] = np.abs(m[:, 2]) + 2
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    sm = SweepModel(m, rng.normal(500, 50, (50, 2)), INTRINSIC_NAMES)
    x = np.array([272.7, 272.8, 515.3, 508.7, -0.021, 0.0012, 2e-4, -1.5e-4, 1e-5, 0.01, -0.02, 0.03])
    R_ref = Rotation.from_rotvec([0.1, 0.2, -0.3]).as_matrix()
    J = sm.jacobian(x, R_ref)

    def central(k, h):
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        rp, rm = sm.residual(xp, R_ref), sm.residual(xm, R_ref)
        return (rp - rm) / (2 * h), max(np.abs(rp).max(), np.abs(rm).max())

    for k in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[k]))
        d1, rmax = central(k, h)
        d2, _ = central(k, 2 * h)
        tol = 4.0 * (np.finfo(float).eps * rmax / h + np.abs(d2 - d1) / 3.0)
        assert np.all(np.abs(J[:, k] - d1) <= tol), (INTRINSIC_NAMES + ["rx", "ry", "rz"])[k]
        assert np.abs(J[:, k] - d1).max() < 1e-7 * np.abs(d1).max()


def _finite_difference_fit(readings, uv, rig):
    """The fit as it was before the analytic Jacobian: MINPACK's forward differences (scipy's
    default for method="lm"), two re-linearised passes at 1e-14 and a final one at 1e-15."""
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    from rigsim.estimation.sun_calibration import SweepModel, sun_directions_in_mount
    from rigsim.optics.camera import PinholeBrown

    ss = rig.sun_sensor
    w, h = ss.resolution_px
    m = sun_directions_in_mount(TurntableModel.nominal_for(rig.turntable), readings)
    names = ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"]
    cam0 = PinholeBrown(ss.fx_px, ss.fx_px, (w - 1) / 2, (h - 1) / 2, width=w, height=h)
    R_ref = Rotation.align_vectors(cam0.unproject(uv), m)[0].as_matrix()
    x = np.array([ss.fx_px, ss.fx_px, (w - 1) / 2, (h - 1) / 2, 0, 0, 0, 0, 0, 0, 0], float)
    sm = SweepModel(m, uv, names)
    for tol in (1e-14, 1e-14, 1e-15):
        sol = least_squares(sm.residual, x, args=(R_ref,), method="lm", xtol=tol, ftol=tol, gtol=tol, x_scale="jac")
        R_ref = Rotation.from_rotvec(sol.x[-3:]).as_matrix() @ R_ref
        x = np.concatenate([sol.x[:-3], np.zeros(3)])
    return x[:-3], R_ref


def test_analytic_jacobian_fit_equals_the_finite_difference_fit():
    """Same minimum as the finite-difference fit, within what its Jacobian error allows: forward
    differences err by ~√ε relative, which moves the solution of Jᵀr = 0 by ≲ √ε·√(2N) parameter σ
    (‖δJᵀr‖ ≤ ‖δJ‖‖r‖, ‖r‖ ≈ σ_centroid·√(2N)); allowed: twice that."""
    rng = np.random.default_rng(11)
    for _ in range(3):
        real = realization_from_rig(RIG, ideal=True)
        readings, uv = cm.simulate_sweep(RIG, real, cm.Noise(centroid_sigma_px=0.01), rng)
        ss = RIG.sun_sensor
        cal = calibrate_sun_sensor(readings, uv, TurntableModel.nominal_for(RIG.turntable), *ss.resolution_px,
                                   f_guess_px=ss.fx_px)
        x_fd, R_fd = _finite_difference_fit(readings, uv, RIG)
        sig = np.sqrt(np.diag(cal.covariance))
        tol = 2.0 * np.sqrt(np.finfo(float).eps) * np.sqrt(2 * len(uv))
        z_int = np.abs(cal.params[:-3] - x_fd) / sig[:-3]
        z_rot = np.abs(small_angle_error(cal.R_sun_from_rot, R_fd)) / sig[-3:]
        assert z_int.max() < tol and z_rot.max() < tol, (z_int, z_rot, tol)


def test_fit_recovers_a_sweep_made_by_scipy_and_opencv():
    """A known answer computed without rigsim's turntable or camera: the sun fixed along the rot frame's z, the
    2-axis table's documented chain R(rot←mount) = Rx(θx)·Ry(θy) (scipy's intrinsic "XY"), a sensor rotated by a
    chosen R(sun←mount), centroids by OpenCV's cv2.projectPoints with tangential terms. The fit must return that
    camera and rotation: a wrong axis order, a transposed chain or a tangential term on the wrong axis in the
    model the simulation and the fit share (test_noise_free_fit_is_exact's round trip) fails here."""
    import cv2
    from scipy.spatial.transform import Rotation

    from rigsim.rig.turntable import TurntableReading

    fx, fy, cx, cy, W, H = 272.7, 272.9, 515.3, 508.7, 1024, 1024
    dist = np.array([-0.021, 0.0012, 2e-3, -1.5e-3, 0.0])
    R_sun = Rotation.from_euler("xyz", [0.35, -0.6, 12.0], degrees=True).as_matrix()
    g = np.radians(np.arange(-60.0, 60.1, 6.0))
    tx, ty = (a.ravel() for a in np.meshgrid(g, g))
    R_rot_from_mount = Rotation.from_euler("XY", np.column_stack([tx, ty])).as_matrix()
    s_sensor = (R_rot_from_mount.transpose(0, 2, 1) @ np.array([0.0, 0.0, 1.0])) @ R_sun.T
    uv, _ = cv2.projectPoints(s_sensor.reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                              np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]]), dist)
    uv = uv.reshape(-1, 2)
    keep = (s_sensor[:, 2] > 0.3) & (uv >= 3).all(1) & (uv[:, 0] <= W - 4) & (uv[:, 1] <= H - 4)
    assert keep.sum() > 300
    cal = calibrate_sun_sensor(TurntableReading({"X": tx[keep], "Y": ty[keep]}), uv[keep],
                               TurntableModel.nominal(["X", "Y"]), W, H, f_guess_px=270.0)
    got = dict(zip(cal.param_names, cal.params))
    want = {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "k1": dist[0], "k2": dist[1], "p1": dist[2], "p2": dist[3]}
    for k, v in want.items():
        assert got[k] == pytest.approx(v, abs=1e-6 * max(1.0, abs(v))), (k, got[k], v)
    assert np.abs(small_angle_error(cal.R_sun_from_rot, R_sun)).max() < 1e-8 and cal.rms_px < 1e-6
