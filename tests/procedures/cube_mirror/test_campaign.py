"""TRIAD, the exact null geometry, round trips and the analytic campaign against truth."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rigsim.errors import GeometryError
from rigsim.estimation.cube_attitude import cube_from_rot_triad
from rigsim.estimation.triad import triad
from rigsim.frames import ARCSEC_PER_RAD, Rot_X, Rot_Y, angle_between, random_rotations, rotation_angle
from rigsim.optics.cube import FACE_NORMALS, reflect
from rigsim.procedures.cube_mirror import campaign as cm
from rigsim.rig import load_rig
from rigsim.rig.turntable import TurntableModel
from rigsim.truth.cube_mirror.realization import realization_from_rig

D = np.array([0.0, 0.0, 1.0])
TABLE1 = [{"X": np.radians(181.398), "Y": np.radians(0.528)}, {"X": np.radians(91.386), "Y": np.radians(-0.048)}]


def test_triad_maps_r1_to_n1_exactly_and_matches_wahba_for_exact_data():
    rng = np.random.default_rng(0)
    for R in random_rotations(50, rng):
        n1, n2 = FACE_NORMALS["+Z"], FACE_NORMALS["+Y"]
        r1, r2 = R.T @ n1, R.T @ n2
        Rt = triad(n1, n2, r1, r2)
        np.testing.assert_allclose(Rt @ r1, n1, atol=1e-14)
        assert rotation_angle(Rt, R) < 1e-12
        # second method: scipy's Wahba solver on the same (exact) pair
        Rw = Rotation.align_vectors(np.stack([n1, n2]), np.stack([r1, r2]))[0].as_matrix()
        assert rotation_angle(Rt, Rw) < 1e-12


def test_triad_with_inconsistent_pair_honours_r1_exactly():
    n1, n2 = FACE_NORMALS["+Z"], FACE_NORMALS["+Y"]
    r1 = Rot_X(0.01) @ n1
    r2 = Rot_Y(0.02) @ n2  # not perpendicular to r1 any more
    R = triad(n1, n2, r1, r2)
    np.testing.assert_allclose(R @ r1, n1, atol=1e-14)
    assert abs(np.linalg.det(R) - 1) < 1e-14


def test_table1_readings():
    Ra, r1, r2 = cube_from_rot_triad(TABLE1, ["+Z", "+Y"], "XY")
    Rb, _, _ = cube_from_rot_triad(TABLE1, ["+Z", "+Y"], "YX")
    np.testing.assert_allclose(Ra @ Ra.T, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(Ra @ r1, [0, 0, 1], atol=1e-14)
    # closed form of eq 7 with d = (0,0,1): r1 = Rot(Y',θ2)⁻¹ Rot(X',θ1)⁻¹ d
    t1, t2 = TABLE1[0]["X"], TABLE1[0]["Y"]
    np.testing.assert_allclose(r1, Rot_Y(-t2) @ Rot_X(-t1) @ D, atol=1e-15)
    # the two nesting readings differ by about 1° (DOMAIN.md)
    assert np.degrees(rotation_angle(Ra, Rb)) == pytest.approx(1.057, abs=0.002)
    # Table 1's two normals are 90.012° apart (a perfect cube gives 90°)
    assert np.degrees(angle_between(r1, r2)) == pytest.approx(90.0121, abs=1e-4)


def test_printed_eq8_is_degenerate():
    """Eq 8 as printed rotates n2 = (0,1,0) instead of the beam: r2 ends up 0.576° from r1. The reading is
    selectable (eq8="printed") and its conditioning says so: ×99 amplification, 89.4° inconsistent with a cube."""
    from rigsim.estimation.triad import triad_conditioning

    t3, t4 = TABLE1[1]["X"], TABLE1[1]["Y"]
    r1 = Rot_Y(-TABLE1[0]["Y"]) @ Rot_X(-TABLE1[0]["X"]) @ FACE_NORMALS["+Z"]
    r2_printed = Rot_Y(-t4) @ Rot_X(-t3) @ FACE_NORMALS["+Y"]
    assert np.degrees(angle_between(r1, r2_printed)) == pytest.approx(0.5760, abs=1e-4)
    R, q1, q2 = cube_from_rot_triad(TABLE1, ["+Z", "+Y"], "XY", eq8="printed")
    np.testing.assert_allclose(q1, r1, atol=1e-15)
    np.testing.assert_allclose(q2, r2_printed, atol=1e-15)
    c = triad_conditioning(FACE_NORMALS["+Z"], FACE_NORMALS["+Y"], q1, q2)
    assert c["degenerate"] and c["amplification"] == pytest.approx(1 / np.sin(np.radians(0.5760)), rel=1e-3)
    assert c["inconsistency_deg"] == pytest.approx(0.5760 - 90.0, abs=1e-4)
    Rb, _, _ = cube_from_rot_triad(TABLE1, ["+Z", "+Y"], "XY")
    assert not triad_conditioning(FACE_NORMALS["+Z"], FACE_NORMALS["+Y"], *cube_from_rot_triad(TABLE1, ["+Z", "+Y"], "XY")[1:])["degenerate"]
    assert np.degrees(rotation_angle(R, Rb)) > 80  # the printed reading's TRIAD is not the cube
    with pytest.raises(ValueError, match="eq8"):
        cube_from_rot_triad(TABLE1, ["+Z", "+Y"], "XY", eq8="rows")


@pytest.mark.parametrize("order", ["XY", "YX"])
def test_round_trip_random_orientations_2axis(order):
    """Random true cube orientations → exact null angles → TRIAD → orientation (≤ 1e-9 rad)."""
    rng = np.random.default_rng(11)
    model = TurntableModel.nominal(list(order))
    starts = [{"X": np.radians(x), "Y": np.radians(y)} for x in (0, 90, 180, 270) for y in (-60, 0, 60)]
    worst = 0.0
    for R_cm in random_rotations(40, rng):
        poses = []
        for face in ("+Z", "+Y"):
            n_mount = R_cm.T @ FACE_NORMALS[face]
            for s in starts:
                try:
                    poses.append(model.solve_alignment(n_mount, D, ["X", "Y"], s, max_move_rad=np.pi))
                    break
                except GeometryError:
                    continue
        # independent check of the null: the beam reflects straight back on itself
        for face, p in zip(("+Z", "+Y"), poses):
            n_rot = model.R_rot_from_mount(p) @ (R_cm.T @ FACE_NORMALS[face])
            np.testing.assert_allclose(reflect(-D, n_rot), D, atol=1e-12)
        R_est, _, _ = cube_from_rot_triad(poses, ["+Z", "+Y"], order)
        worst = max(worst, rotation_angle(R_est, R_cm))
    assert worst <= 1e-9


def test_round_trip_3axis():
    rng = np.random.default_rng(5)
    model = TurntableModel.nominal(["Y", "X", "Z"])
    for R_small in random_rotations(20, rng):
        # cube near the seed-001 mounting (faces reachable from middle 90°/180°), random within ±5°
        rv = Rotation.from_matrix(R_small).as_rotvec()
        R_cm = Rotation.from_rotvec(rv / np.linalg.norm(rv) * np.radians(5) * rng.random()).as_matrix() @ Rot_X(np.pi / 2)
        poses = [
            model.solve_alignment(R_cm.T @ FACE_NORMALS["+Z"], D, ["X", "Y"], {"X": np.pi / 2, "Y": 0, "Z": 0}),
            model.solve_alignment(R_cm.T @ FACE_NORMALS["+Y"], D, ["X", "Y"], {"X": np.pi, "Y": 0, "Z": 0}),
        ]
        R_est, _, _ = cube_from_rot_triad(poses, ["+Z", "+Y"], "YXZ")
        assert rotation_angle(R_est, R_cm) <= 1e-9


@pytest.mark.parametrize("rig_name", ["sun_sensor_2axis_diaphragm", "sun_sensor_3axis_autocollimator"])
def test_ideal_campaign_recovers_truth(rig_name):
    rig = load_rig(rig_name)
    res = cm.run_campaign(rig, realization_from_rig(rig, ideal=True), cm.Noise(), np.random.default_rng(0))
    assert np.all(np.abs(res.error_arcsec) < 1e-6)  # 1e-6″ ≈ 5e-12 rad
    assert rotation_angle(res.R_cube_from_sun_est, rig.R_cube_from_sun()) < 1e-10


def test_seed000_default_rig_reproduces_table1_final_angles():
    rig = load_rig("sun_sensor_2axis_diaphragm")
    res = cm.run_campaign(rig, realization_from_rig(rig, ideal=True), cm.Noise(), np.random.default_rng(0), fit_calibration=False)
    p1, p2 = res.null_poses_deg
    assert p1["X"] == pytest.approx(181.398, abs=1e-5) and p1["Y"] == pytest.approx(0.528, abs=1e-5)
    assert p2["X"] == pytest.approx(91.386, abs=0.015) and p2["Y"] == pytest.approx(-0.048, abs=0.015)


def test_wrong_axis_order_reading_costs_about_a_degree():
    rig = load_rig("sun_sensor_2axis_diaphragm")
    real = realization_from_rig(rig, ideal=True)
    res = cm.run_campaign(rig, real, cm.Noise(), np.random.default_rng(0), axis_order="YX")
    # TRIAD alone: about 1° (the two readings of Table 1 differ by 1.06°)
    assert 0.5 < np.degrees(rotation_angle(res.R_cube_from_rot_est, res.R_cube_from_rot_true)) < 2.0
    # the ±60° sweep fit with the wrong nesting cannot fit the data: its residuals give it away
    assert res.calibration.rms_px > 1.0
    assert np.degrees(rotation_angle(res.R_cube_from_sun_est, res.R_cube_from_sun_true)) > 0.5


def test_rig_true_errors_show_up_and_match_their_size():
    """Only the aiming-camera mounting bias (1.3″, −0.9″ on both faces): the error is of that size."""
    rig = load_rig("sun_sensor_2axis_diaphragm")
    real = realization_from_rig(rig, ideal=True)
    real.null_bias_rad = [np.array([1.3, -0.9]) / ARCSEC_PER_RAD] * 2
    res = cm.run_campaign(rig, real, cm.Noise(), np.random.default_rng(0), fit_calibration=False)
    err = np.linalg.norm(res.error_arcsec)
    assert 1.0 < err < 3.0 * np.hypot(1.3, 0.9)


def test_null_error_budget_matches_closed_form():
    """σ1 alone: a null error ε (per axis, σ = 1 px·15 µm/(2·650 mm) = 2.38″) on each face gives a
    per-axis σ of R(cube←sun) of σ1 about every cube axis (r1 fixes x and y, r2 the rotation about r1)."""
    rig = load_rig("sun_sensor_2axis_diaphragm")
    sigma1 = 1 * 15e-3 / (2 * 650) * ARCSEC_PER_RAD
    assert sigma1 == pytest.approx(2.380, abs=1e-3)  # the paper prints 2.34″ (docs/readings.md)
    rng = np.random.default_rng(7)
    noise = cm.Noise(null_sigma_rad=sigma1 / ARCSEC_PER_RAD)
    n = 400
    errs = np.array([
        cm.run_campaign(rig, realization_from_rig(rig, ideal=True), noise, rng, fit_calibration=False).error_arcsec
        for _ in range(n)
    ])
    # sample σ of 400 normal draws: relative standard error 1/sqrt(2·399) = 3.5 %; allow 4 of those
    np.testing.assert_allclose(errs.std(axis=0, ddof=1), sigma1, rtol=0.14)
    np.testing.assert_allclose(errs.mean(axis=0), 0.0, atol=4 * sigma1 / np.sqrt(n))


def test_unreachable_face_is_reported():
    rig = load_rig("sun_sensor_2axis_diaphragm")
    bad = rig.model_copy(update={"procedure": rig.procedure.model_copy(update={"faces": ["-X", "+Y"]})})
    with pytest.raises(GeometryError, match="aligns the face normal"):
        cm.run_campaign(bad, realization_from_rig(bad, ideal=True), cm.Noise(), np.random.default_rng(0), fit_calibration=False)
