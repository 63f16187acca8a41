"""The sweep fit weighted by each centroid's σ with the floor the residuals show (``weighted=True``):
on synthetic sweeps (the rig's exact projection plus Gaussian noise of a known σ per frame and a
known floor), the floor is found, the covariance predicts the Monte-Carlo scatter, and where the
frames' σ differ (a diffracted spot far off axis is 10× noisier than near it) the weighted fit is
the more accurate, as least squares with the right weights must be."""

import numpy as np
import pytest

from rigsim.estimation.sun_calibration import calibrate_sun_sensor, noise_floor
from rigsim.frames import small_angle_error
from rigsim.procedures.cube_mirror import campaign as cm
from rigsim.rig import load_rig
from rigsim.rig.turntable import TurntableModel
from rigsim.truth.cube_mirror.realization import realization_from_rig

RIG = load_rig("sun_sensor_2axis_diaphragm")
SS = RIG.sun_sensor
REAL = realization_from_rig(RIG, ideal=True)
READINGS, UV = cm.simulate_sweep(RIG, REAL, cm.Noise(), np.random.default_rng(0))
R = np.hypot(UV[:, 0] - SS.resolution_px[0] / 2, UV[:, 1] - SS.resolution_px[1] / 2)
SIG = np.repeat((0.01 + 0.1 * (R / R.max()) ** 4)[:, None], 2, axis=1)  # 0.01 px on axis to 0.11 px at the corner


def fit(uv, weighted, sig=SIG):
    return calibrate_sun_sensor(READINGS, uv, TurntableModel.nominal_for(RIG.turntable), *SS.resolution_px,
                                f_guess_px=SS.fx_px, sigma_uv=sig, weighted=weighted)


def test_noise_floor_is_what_the_residuals_show_beyond_the_sigma():
    """Residuals drawn with σᵢ² + s²: the floor found is s (0.02 px) to 5 %; residuals within their σ
    give 0."""
    rng = np.random.default_rng(1)
    sig = rng.uniform(0.005, 0.1, (4000, 2))
    r = rng.normal(0.0, np.sqrt(sig**2 + 0.02**2))
    assert noise_floor(r, sig, 10) == pytest.approx(0.02, rel=0.05)
    assert noise_floor(rng.normal(0.0, sig) * 0.9, sig, 10) == 0.0


def test_weighted_fit_is_more_accurate_and_its_covariance_is_right():
    """40 sweeps with each frame's noise σᵢ: the weighted fit's R(sun←rot) scatters less than the
    unweighted one's (by a third or more about every axis), its predicted σ matches its scatter to
    25 %, and its floor is ~0 (the σ explain the residuals)."""
    rng = np.random.default_rng(7)
    ew, eu, sw, floors = [], [], [], []
    for _ in range(40):
        uv = UV + rng.normal(0.0, SIG)
        a, b = fit(uv, True), fit(uv, False)
        ew.append(small_angle_error(a.R_sun_from_rot, REAL.R_sun_from_mount))
        eu.append(small_angle_error(b.R_sun_from_rot, REAL.R_sun_from_mount))
        sw.append(np.sqrt(np.diag(a.rotation_covariance_rad2)))
        floors.append(a.noise_floor_px)
    ew, eu, sw = np.array(ew), np.array(eu), np.array(sw)
    rms_w, rms_u = np.sqrt(np.mean(ew**2, axis=0)), np.sqrt(np.mean(eu**2, axis=0))
    assert np.all(rms_w < 0.67 * rms_u), (rms_w, rms_u)
    assert np.all(np.abs(rms_w / sw.mean(axis=0) - 1) < 0.25), rms_w / sw.mean(axis=0)
    assert np.median(floors) < 0.005


def test_a_floor_is_added_when_the_sigma_are_too_small():
    """The frames' σ claimed 4× too small: the floor takes up the excess (the weighted χ²/dof is then 1), the
    fit is judged against the claimed σ (χ²/dof ≫ 1: the report says the data do not fit the centroids'
    noise, and names the floor), and its σ of R(sun←rot) are within 30 % of the fit with the true σ's."""
    rng = np.random.default_rng(8)
    uv = UV + rng.normal(0.0, SIG)
    a, b = fit(uv, True, SIG / 4), fit(uv, True)
    assert a.noise_floor_px > 0.005 and b.noise_floor_px < 0.002
    assert a.fit.chi2 / a.fit.dof > 10 and a.fit.floor == a.noise_floor_px and "floor" in a.fit.describe()
    np.testing.assert_allclose(np.sqrt(np.diag(a.rotation_covariance_rad2)), np.sqrt(np.diag(b.rotation_covariance_rad2)),
                               rtol=0.3)


def test_equal_sigma_is_the_unweighted_fit():
    """Every frame with the same σ: the weights change nothing, so the unweighted fit is returned (its
    covariance the noise model's, scaled by χ²/dof beyond chance)."""
    rng = np.random.default_rng(9)
    uv = UV + rng.normal(0.0, 0.02, UV.shape)
    a, b = fit(uv, True, np.full_like(SIG, 0.005)), fit(uv, False, np.full_like(SIG, 0.005))
    np.testing.assert_array_equal(a.params, b.params)
    np.testing.assert_array_equal(a.covariance, b.covariance)
    assert a.fit.floor == 0.0 and a.fit.covariance_scale > 10
