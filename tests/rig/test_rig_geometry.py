"""The rig's geometry summary: the default rigs pass, inconsistent geometry is refused naming the
fields, and the sweep's landing count agrees with the truth layer's own projection."""

import math

import numpy as np
import pytest

from rigsim.errors import RigError
from rigsim.rig.geometry import check_geometry, geometry_summary, sweep_landing
from rigsim.rig.load import load_rig


def _custom(rig, **ss):
    return rig.model_copy(update={"sun_sensor": rig.sun_sensor.model_copy(update=ss)})


@pytest.mark.parametrize("name", ["sun_sensor_2axis_diaphragm", "sun_sensor_3axis_autocollimator"])
def test_default_rigs_pass(name):
    lines = check_geometry(load_rig(name))
    assert all(g.status == "ok" for g in lines)


def test_landing_count_agrees_with_the_truth_layer():
    """An f = 20 mm, 5.5 µm, 2048² sensor (±15.8° field) under the ±60° sweep: the count from the
    nominal rig equals the ideal realisation's projection (truth layer, a second code path)."""
    from rigsim.estimation.sun_calibration import sweep_poses
    from rigsim.truth.cube_mirror.realization import realization_from_rig

    rig = _custom(load_rig("sun_sensor_2axis_diaphragm"), resolution_px=[2048, 2048], pixel_pitch_um=5.5,
                  focal_length_mm=20.0, principal_point_px=[1030.3, 1017.4])
    landed, n = sweep_landing(rig)
    real = realization_from_rig(rig, ideal=True)
    cam = rig.sun_sensor.camera()
    p = rig.procedure
    poses = sweep_poses(p.sweep_axes, p.sweep_range_deg, p.sweep_step_deg)
    count = 0
    for i in range(n):
        R = real.turntable.R_rot_from_mount({k: v[i] for k, v in poses.items()})
        s = real.R_sun_from_mount @ (R.T @ real.d_sun_rot)
        uv, ok = cam.project_valid(s[None] / np.linalg.norm(s))
        count += bool(ok[0] and cam.on_detector(uv, margin_px=3.0)[0])
    assert (landed, n) == (count, 625) and landed == 39
    sweep = next(g for g in geometry_summary(rig) if g.item == "sweep")
    assert sweep.status == "error" and "39 of 625" in sweep.value and "±15.8°" in sweep.value


def test_inconsistent_geometry_is_refused_naming_the_fields():
    rig = load_rig("sun_sensor_2axis_diaphragm")
    big = rig.model_copy(update={"diaphragm_screen": rig.diaphragm_screen.model_copy(update={"hole_diameter_mm": 30.0}),
                                 "cube": rig.cube.model_copy(update={"edge_mm": 10.0})})
    with pytest.raises(RigError, match=r"diaphragm_screen\.hole_diameter_mm, cube\.edge_mm: hole vs face: Ø 30 mm beam "
                                       r"on a 10 mm face"):
        check_geometry(big)
    # a sweep that never reaches the detector: the calibration would have no point
    narrow = _custom(rig, focal_length_mm=200.0)
    narrow = narrow.model_copy(update={"procedure": narrow.procedure.model_copy(update={"sweep_step_deg": 20.0})})
    with pytest.raises(RigError, match=r"procedure\.sweep_range_deg.*sweep: ±60° every 20° about X/Y: \d of 49 poses"):
        check_geometry(narrow)
    # the divergent return against the aiming camera's field: 2·650 mm·tan(16′) + hole = 8.6 mm more than the hole
    ds = rig.diaphragm_screen
    expected = ds.hole_diameter_mm + 4 * ds.distance_to_cube_mm * math.tan(math.radians(32 / 60) / 2)
    ac = next(g for g in geometry_summary(rig) if g.item == "aiming camera")
    assert f"Ø {expected:.1f} mm" in ac.value


def test_a_sun_image_under_two_pixels_is_refused():
    """A 576² sensor of 4 µm with ±60° of field (f = 0.6567 mm) images the 21′ sun into
    2·tan(10.5′)·656.7 µm / 4 µm = 1.00 px: the frame stage cannot find it (≥ 3 connected pixels)."""
    rig = load_rig("sun_sensor_2axis_diaphragm")
    rig = rig.model_copy(update={"sun_simulator": rig.sun_simulator.model_copy(update={"collimation_full_angle_arcmin": 21.0})})
    wide = _custom(rig, resolution_px=[576, 576], pixel_pitch_um=4.0, focal_length_mm=0.6567,
                   principal_point_px=[287.5, 287.5])
    expected = 2 * math.tan(math.radians(21 / 60) / 2) * 656.7 / 4.0
    line = next(g for g in geometry_summary(wide) if g.item == "sun image")
    assert line.status == "error" and f"Ø {expected:.2f} px on axis" in line.value and expected == pytest.approx(1.003, abs=1e-3)
    with pytest.raises(RigError, match=r"sun_sensor\.focal_length_mm.*sun image: Ø 1\.00 px on axis.*at least 2 px"):
        check_geometry(wide)
    # twice the focal length: 2.0 px, accepted by this line
    ok = _custom(wide, focal_length_mm=2 * 0.6567 * 1.001)
    assert next(g for g in geometry_summary(ok) if g.item == "sun image").status == "ok"


def test_a_cube_around_the_sensor_is_refused():
    """The sensor's optical centre is the mount's origin; a 25 mm cube reaches any point within
    25·√3/2 = 21.65 mm of its centre."""
    rig = load_rig("sun_sensor_2axis_diaphragm")

    def at(c):
        return rig.model_copy(update={"cube": rig.cube.model_copy(update={"centre_in_mount_mm": c})})

    with pytest.raises(RigError, match=r"cube\.centre_in_mount_mm, cube\.edge_mm: cube: .*reaches the sensor's optical centre"):
        check_geometry(at([0.0, 0.0, -21.6]))
    assert next(g for g in geometry_summary(at([0.0, 0.0, -21.7])) if g.item == "cube").status == "ok"


def test_a_sensor_facing_away_is_refused_with_the_likely_cause():
    from rigsim.rig.cube_mirror import Orientation

    rig = load_rig("sun_sensor_2axis_diaphragm")
    away = rig.model_copy(update={"sun_sensor": rig.sun_sensor.model_copy(
        update={"R_sun_from_mount": Orientation(euler_seq="xyz", euler_deg=[180.35, -0.6, 12.0])})})
    assert sweep_landing(away)[0] == 0
    with pytest.raises(RigError, match=r"R_sun_from_mount: sweep: .* 0 of 625 poses .*face away"):
        check_geometry(away)


def test_a_return_mostly_lost_into_the_hole_is_a_warning():
    """Default rig: blur 2·650·tan(16′) = 6.05 mm around a Ø 2.5 mm pencil reads 1.04× the offset. A rig with a
    Ø 3.524 mm hole 312.5 mm from the cube and a 20.24′ simulator (blur 1.84 mm ≈ the hole's radius) reads
    1.92× (its rendered frame measured 1.86×): a warning, not a refusal."""
    rig = load_rig("sun_sensor_2axis_diaphragm")
    line = next(g for g in geometry_summary(rig) if g.item == "return vs hole")
    assert line.status == "ok" and "R = 6.05 mm" in line.value and "1.04×" in line.value
    short = rig.model_copy(update={
        "diaphragm_screen": rig.diaphragm_screen.model_copy(update={"hole_diameter_mm": 3.524, "distance_to_cube_mm": 312.5}),
        "sun_simulator": rig.sun_simulator.model_copy(update={"collimation_full_angle_arcmin": 20.24})})
    line = next(g for g in geometry_summary(short) if g.item == "return vs hole")
    assert line.status == "warning" and "R = 1.84 mm" in line.value and "1.92×" in line.value
