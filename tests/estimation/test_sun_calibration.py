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
    """The fit's Jacobian is analytic (camera model + SO(3) left Jacobian), not finite differences."""
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
    Jn = np.zeros_like(J)
    for k in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[k]))
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        Jn[:, k] = (sm.residual(xp, R_ref) - sm.residual(xm, R_ref)) / (2 * h)
    rel = np.max(np.abs(J - Jn), axis=0) / np.abs(Jn).max(axis=0)
    assert np.all(rel < 1e-7), rel
