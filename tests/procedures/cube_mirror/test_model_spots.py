"""``method="model"`` of the cube-mirror file stages (rigsim.procedures.cube_mirror.model_spots):
the autocollimator's reading and the aiming camera's hole/spot offset from synthetic frames whose
truth is known, against the current centroiders on the same frames."""

import math

import numpy as np
import pytest

from rigsim.errors import InputError
from rigsim.imaging.screen import plane_to_uv
from rigsim.optics.aiming import nominal_screen_homography
from rigsim.optics.autocollimator import retilt
from rigsim.optics.autocollimator_spot_model import AutocollimatorSpotModel
from rigsim.optics.screen_spot_model import ScreenSpotModel
from rigsim.procedures.cube_mirror.model_spots import screen_spot_radii_mm
from rigsim.procedures.cube_mirror.null_files import autocollimator_optics, measure_concentricity, read_autocollimator
from rigsim.rig import load_rig


@pytest.mark.slow  # a named option, not the default: its model is checked in the default stage (optics/test_autocollimator_spot_model.py)
def test_the_autocollimator_reading_from_the_model_is_the_mirrors_tilt():
    """A face frame (the spot's exact image at a 23″, −41″ tilt, peak at half the full well, the
    detector's noise): the model's spot lies within 4σ of the rays' centroid, its σ is the fit's
    bound (0.002–0.004 px), and the reading is the calibrated reading of that centroid. Without the
    frame's mirror the model is refused."""
    rig = load_rig("sun_sensor_3axis_autocollimator")
    ac, det = rig.autocollimator, rig.autocollimator.detector
    optics = autocollimator_optics(rig)
    m = retilt(optics.centred_mirror("square", rig.cube.edge_mm), np.array([23.0, -41.0]) / 206264.806)
    sp = optics.spot(m, n_rays=600_000)
    c = sp.mean_uv
    o = np.floor(c + 0.5).astype(int) - 40
    img = AutocollimatorSpotModel(optics, m, o, (81, 81), diffraction_half_px=39, n_rays=600_000)(*c)
    rng = np.random.default_rng(2)
    e = np.full((ac.resolution_px[1], ac.resolution_px[0]), det.dark_current_e_per_s * det.exposure_s)
    e[o[1]:o[1] + 81, o[0]:o[0] + 81] += 0.5 * det.full_well_e * img / img.max()
    dn = np.round(det.gain_dn_per_e * (rng.poisson(e) + rng.normal(0.0, det.read_noise_e, e.shape)) + det.offset_dn)
    reading, sig, sm = read_autocollimator(rig, dn, optics, "face", method="model")
    assert sm.ok
    assert np.all(np.abs(sm.uv - c) < 4 * sm.sigma_uv), (sm.uv - c, sm.sigma_uv)
    assert np.all((sm.sigma_uv > 0.0015) & (sm.sigma_uv < 0.004))
    assert reading == pytest.approx(optics.reading(sm.uv) * 206264.806, abs=1e-6)
    with pytest.raises(InputError):
        read_autocollimator(rig, dn, optics, None, method="model")


@pytest.mark.slow  # a named option, not the default: its model is checked in the default stage (optics/test_screen_spot_model.py)
def test_the_concentricity_offset_from_the_model_has_no_holes_bias():
    """Hole and spot frames of the aiming camera (the divergent spot 0.37, −0.52 mm from the hole,
    its light into the hole lost, the hole glowing at the plateau's level, the detector's noise): the
    model's offset is the true one to 0.02 object px; the moments' is 4.5 % too long (the light
    the hole takes pulls their centroid away from it: 1.9 px here)."""
    rig = load_rig("sun_sensor_2axis_diaphragm")
    ac, det = rig.aiming_camera, rig.aiming_camera.detector
    H = nominal_screen_homography(ac)
    a, R = screen_spot_radii_mm(rig)
    Hd, Wd = ac.resolution_px[1], ac.resolution_px[0]
    c = np.array([0.37, -0.52])
    m = ScreenSpotModel(H, (0, 0), (Hd, Wd), a, R, hole_centre_st=(0.0, 0.0), hole_radius_mm=a)
    plateau_e = 0.5 * det.full_well_e
    bg_e = det.dark_current_e_per_s * det.exposure_s
    rng = np.random.default_rng(4)

    def draw(mu):
        return np.round(det.gain_dn_per_e * (rng.poisson(mu) + rng.normal(0.0, det.read_noise_e, mu.shape))
                        + det.offset_dn)

    glow = m.hole_coverage * plateau_e
    hole = draw(bg_e + glow)
    spot = draw(plateau_e * m(*plane_to_uv(H, c)) + bg_e + glow)
    true_px = c / ac.object_pixel_mm
    mod = measure_concentricity(rig, hole, spot, method="model")
    mom = measure_concentricity(rig, hole, spot)
    assert mod["spot_problem"] is None and mod["spot_chi2_dof"] < 1.1
    assert np.abs(mod["offset_px"] - true_px).max() < 0.02
    assert np.all(mod["spot_sigma_mm"] / ac.object_pixel_mm < 0.005)
    loss = (a / R) ** 2
    assert mom["offset_px"] == pytest.approx(true_px / (1 - loss), rel=0.01)
    assert math.hypot(*(mom["offset_px"] - true_px)) > 1.5
