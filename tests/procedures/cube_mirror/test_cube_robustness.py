"""The cube-mirror rigs' robustness trials: the campaign they run is the main job's, scored against the truth."""

import math

import numpy as np
import pytest

from rigsim.procedures.robustness import ALL, IDEAL, configs_for, rig_with
from rigsim.rig.load import load_any_rig


@pytest.fixture(scope="module")
def diaphragm_rig():
    return load_any_rig("sun_sensor_2axis_diaphragm")


def test_each_method_studies_the_sun_sensor_and_its_own_instrument():
    from rigsim.procedures.cube_mirror.robustness import effect_names
    from rigsim.rig.effects_autocollimator import AutocollimatorEffects
    from rigsim.rig.effects_screen import ScreenEffects
    from rigsim.rig.effects_sun import SunSensorEffects

    dia = effect_names(load_any_rig("sun_sensor_2axis_diaphragm"))
    auto = effect_names(load_any_rig("sun_sensor_3axis_autocollimator"))
    assert set(dia) == set(SunSensorEffects.names()) | set(ScreenEffects.names())
    assert set(auto) == set(SunSensorEffects.names()) | set(AutocollimatorEffects.names())


def test_the_budgets_are_the_documents(diaphragm_rig):
    from rigsim.procedures.cube_mirror.robustness import quantities

    q = {x.key: x for x in quantities(diaphragm_rig)}
    a = 3.69 / math.sqrt(3.0)                      # seed 000: 3.69″ RSS
    assert q["cube_sun_x_arcsec"].budget == q["sun_rot_z_arcsec"].budget == pytest.approx(a)
    ss = diaphragm_rig.sun_sensor                  # the same angle on the sun sensor's detector
    assert q["sun_u0_px"].budget == pytest.approx(a / 206264.806 * ss.focal_length_mm / (ss.pixel_pitch_um * 1e-3))
    assert q["null_measurement_rms"].budget == diaphragm_rig.aiming_camera.null_sigma_px == 1.0   # Table 1: 1 px
    assert q["sweep_points_count"].kind == "count"
    rig3 = load_any_rig("sun_sensor_3axis_autocollimator")
    q3 = {x.key: x for x in quantities(rig3)}
    assert q3["cube_sun_x_arcsec"].budget == 6.0   # seed 001: the turntable's 0.1′
    assert q3["null_measurement_rms"].unit == "arcsec" and q3["null_measurement_rms"].budget == 0.1


def test_rig_with_switches_exactly_the_configured_effects(diaphragm_rig):
    from rigsim.procedures.cube_mirror.robustness import effect_names

    names = effect_names(diaphragm_rig)
    if not names:
        pytest.skip("no cube-mirror effects modelled")
    assert rig_with(diaphragm_rig, IDEAL, names).effects.enabled == ()
    assert set(rig_with(diaphragm_rig, ALL, names).effects.enabled) == set(names)
    assert rig_with(diaphragm_rig, names[0], names).effects.enabled == (names[0],)
    assert configs_for(names)[0] == IDEAL


def test_an_ideal_trial_is_the_main_jobs_campaign_scored_against_truth(diaphragm_rig):
    from rigsim.procedures.cube_mirror.robustness import campaign_trial, quantities

    out = campaign_trial(diaphragm_rig, (), IDEAL, 0)
    v = out["as configured"]
    assert set(v) == {q.key for q in quantities(diaphragm_rig)}
    # the rig file's true errors and noise: R(cube←sun) inside 3σ of the document's per-axis budget
    assert all(abs(v[f"cube_sun_{a}_arcsec"]) < 3 * 2.13 for a in "xyz")
    # the sweep: every spot on the detector but the two at the field's corners, centroids near the exact centre
    assert v["sweep_points_count"] >= 560
    assert v["sun_centroid_rms_px"] < 0.02
    assert abs(v["sun_fx_px"]) < 0.05 and abs(v["sun_u0_px"]) < 0.05 and abs(v["sun_v0_px"]) < 0.05
    # near the null the aiming camera's offset is measured to a small fraction of a pixel
    assert 0.0 < v["null_measurement_rms"] < 0.3
    assert out["_render_ms_per_frame"] > 0
    again = campaign_trial(diaphragm_rig, (), IDEAL, 0)["as configured"]
    assert again == v                                  # same seed, same campaign
    other = campaign_trial(diaphragm_rig, (), IDEAL, 1)["as configured"]
    assert not np.isclose(other["sun_centroid_rms_px"], v["sun_centroid_rms_px"], rtol=0, atol=1e-12)
