import numpy as np
import pytest

from rigsim.frames import ARCSEC_PER_RAD, Rot_X, Rot_Y, angle_between
from rigsim.rig import load_rig
from rigsim.rig.turntable import TurntableModel


def test_nominal_chain_is_product_of_eq9_10():
    m = TurntableModel.nominal(["X", "Y"])
    a, b = 0.4, -1.1
    np.testing.assert_allclose(m.R_rot_from_mount({"X": a, "Y": b}), Rot_X(a) @ Rot_Y(b), atol=1e-15)
    m2 = TurntableModel.nominal(["Y", "X"])
    np.testing.assert_allclose(m2.R_rot_from_mount({"X": a, "Y": b}), Rot_Y(b) @ Rot_X(a), atol=1e-15)


def test_misalignment_sets_the_non_perpendicularity():
    rig = load_rig("sun_sensor_2axis_diaphragm")  # inner axis misaligned by 1.6″ about Z'
    m = TurntableModel.true(rig.turntable)
    ang = angle_between(m.axes[0].direction, m.axes[1].direction)
    # +1.6″ about +Z turns Y' away from +X': the axes are 90° + 1.6″ apart
    assert (ang - np.pi / 2) * ARCSEC_PER_RAD == pytest.approx(1.6, abs=1e-6)


def test_wobble_tilts_the_axis_by_its_amplitude_with_turning_azimuth():
    from rigsim.rig.turntable import AxisKinematics

    w = 5.0 / ARCSEC_PER_RAD
    ax = AxisKinematics("Y", np.array([0.0, 1.0, 0.0]), wobble_rad=w)
    ideal = AxisKinematics("Y", np.array([0.0, 1.0, 0.0]))
    tilts = []
    for th in np.radians([0, 90, 180, 270]):
        D = ax.matrix(th) @ ideal.matrix(th).T  # the wobble rotation alone
        rv = np.array([D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]]) / 2
        assert np.linalg.norm(rv) == pytest.approx(w, rel=1e-6)
        assert abs(rv[1]) < 1e-12  # tilt is perpendicular to the axis
        tilts.append(rv)
    # the tilt azimuth turns with the angle: opposite at 0° and 180°
    np.testing.assert_allclose(tilts[0], -tilts[2], atol=1e-12)


# ---------------------------------------------------------------- kinematics against scipy rotations and by hand
def _rv(v):
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(np.asarray(v, float)).as_matrix()


def test_nominal_axes_are_the_unit_axes_and_a_missing_angle_is_zero():
    m = TurntableModel.nominal(["Y", "X", "Z"])
    np.testing.assert_array_equal([a.direction for a in m.axes], [[0, 1, 0], [1, 0, 0], [0, 0, 1]])
    # only X given: Y and Z at zero
    np.testing.assert_allclose(m.R_rot_from_mount({"X": 0.7}), _rv([0.7, 0, 0]), atol=1e-15)


def test_axis_kinematics_is_immutable():
    from dataclasses import FrozenInstanceError

    from rigsim.rig.turntable import AxisKinematics

    ax = AxisKinematics("Y", np.array([0.0, 1.0, 0.0]))
    with pytest.raises(FrozenInstanceError):
        ax.wobble_rad = 1e-5


@pytest.mark.parametrize("phase", [0.0, 0.6])
def test_wobble_azimuth_of_a_y_axis_by_hand(phase):
    """Convention: the tilt's rotation vector is w·(cos(θ+φ)·e1 + sin(θ+φ)·e2), e1 = unit(a × Z′) while
    |a_z| < 0.9, e2 = a × e1. For a = Y′: e1 = X′, e2 = −Z′. θ given as an array (a sweep)."""
    from rigsim.rig.turntable import AxisKinematics

    w = 40.0 / ARCSEC_PER_RAD
    kw = {} if phase == 0.0 else {"wobble_phase_rad": phase}  # phase 0: the default
    ax = AxisKinematics("Y", np.array([0.0, 1.0, 0.0]), wobble_rad=w, **kw)
    th = np.array([0.3, 1.1, -2.0])
    M = ax.matrix(th)
    assert M.shape == (3, 3, 3)
    for i, t in enumerate(th):
        ph = t + phase
        np.testing.assert_allclose(M[i], _rv(w * np.array([np.cos(ph), 0.0, -np.sin(ph)])) @ _rv([0, t, 0]), atol=1e-15)


@pytest.mark.parametrize("label,a,e1", [
    ("X", [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]),                      # X′ × Z′ = −Y′
    ("Z", [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]),                       # |a_z| >= 0.9: Z′ × X′ = Y′
    ("Z", [np.sqrt(0.19), 0.0, 0.9], [0.0, 1.0, 0.0]),             # the boundary |a_z| = 0.9 takes X′: a × X′ ∝ Y′
    ("Z", [0.1, 0.2, 0.974679434480896], [0.0, 0.974679434480896, -0.2]),  # a × X′ = (0, a_z, −a_y), unit here
])
def test_wobble_azimuth_reference_of_other_axes(label, a, e1):
    from rigsim.rig.turntable import AxisKinematics

    a = np.asarray(a)
    e1 = np.asarray(e1) / np.linalg.norm(e1)
    e2 = np.array([a[1] * e1[2] - a[2] * e1[1], a[2] * e1[0] - a[0] * e1[2], a[0] * e1[1] - a[1] * e1[0]])  # a × e1
    w, phase, t = 25.0 / ARCSEC_PER_RAD, 0.4, 0.9
    M = AxisKinematics(label, a, wobble_rad=w, wobble_phase_rad=phase).matrix(t)
    ph = t + phase
    np.testing.assert_allclose(M, _rv(w * (np.cos(ph) * e1 + np.sin(ph) * e2)) @ _rv(t * a / np.linalg.norm(a)), atol=1e-15)


def test_true_model_takes_the_wobble_in_arcsec_and_its_phase_in_degrees():
    from rigsim.rig.cube_mirror import Turntable, TurntableAxis

    tt = Turntable(kind="2-axis", axes=[TurntableAxis(name="outer", label="X", wobble_arcsec=30.0, wobble_phase_deg=40.0),
                                        TurntableAxis(name="inner", label="Y")])
    m = TurntableModel.true(tt)
    assert m.axes[0].wobble_rad == pytest.approx(30.0 * np.pi / (180 * 3600), rel=1e-12)
    assert m.axes[0].wobble_phase_rad == pytest.approx(40.0 * np.pi / 180, rel=1e-12)
    np.testing.assert_allclose(m.axes[1].direction, [0, 1, 0], atol=0)


@pytest.mark.parametrize("order", ["XZ", "XX"])
def test_nominal_for_refuses_an_order_that_is_not_a_permutation(order):
    from rigsim.rig.cube_mirror import Turntable, TurntableAxis

    tt = Turntable(kind="2-axis", axes=[TurntableAxis(name="outer", label="X"), TurntableAxis(name="inner", label="Y")])
    with pytest.raises(ValueError, match="permutation"):
        TurntableModel.nominal_for(tt, order)
    assert TurntableModel.nominal_for(tt, "YX").labels == ["Y", "X"]


def test_solve_alignment_with_vectors_of_any_length_and_a_missing_start_angle():
    m = TurntableModel.nominal(["X", "Y"])
    a = 0.3
    d = _rv([a, 0, 0]) @ np.array([0.0, 0.0, 1.0])  # Z′ turned by X′ = a (Y′ at zero)
    pose = m.solve_alignment(np.array([0.0, 0.0, 3.0]), 2.0 * d, free=["X"], start={"X": 0.1})
    assert pose["X"] == pytest.approx(a, abs=1e-12) and pose["Y"] == 0.0


def test_solve_alignment_reports_an_unreachable_direction():
    from rigsim.errors import GeometryError

    m = TurntableModel.nominal(["X", "Y"])
    # turning about X′ keeps Z′ in the Y′Z′ plane: the nearest miss of a direction 17° out of it is 0.29
    with pytest.raises(GeometryError):
        m.solve_alignment([0.0, 0.0, 1.0], [0.3, 0.0, 1.0], free=["X"], start={})


@pytest.mark.parametrize("move_deg,ok", [(19.5, True), (20.5, False)])
def test_solve_alignment_searches_within_20_degrees_of_the_start(move_deg, ok):
    from rigsim.errors import GeometryError

    m = TurntableModel.nominal(["X", "Y"])
    a = np.radians(move_deg)
    d = [0.0, -np.sin(a), np.cos(a)]  # Rot(X′, a)·Z′
    if ok:
        assert m.solve_alignment([0, 0, 1], d, free=["X"], start={"X": 0.0})["X"] == pytest.approx(a, abs=1e-12)
    else:
        with pytest.raises(GeometryError, match="within 20°"):
            m.solve_alignment([0, 0, 1], d, free=["X"], start={"X": 0.0})


def test_solve_alignment_message_gives_the_start_in_degrees_to_3_decimals():
    from rigsim.errors import GeometryError

    m = TurntableModel.nominal(["X", "Y"])
    with pytest.raises(GeometryError) as e:
        m.solve_alignment([0, 0, 1], [1.0, 0.0, 0.0], free=["X"], start={"X": np.radians(12.345678)})
    assert "'X': 12.346," in str(e.value)


def test_angles_from_and_to_degrees_keep_arrays_and_floats():
    from rigsim.rig.turntable import TurntableReading

    r = TurntableReading.from_deg({"X": 90.0, "Y": np.array([0.0, 180.0])})
    assert type(r["X"]) is float and r["X"] == pytest.approx(np.pi / 2, abs=1e-15)
    np.testing.assert_allclose(r["Y"], [0.0, np.pi], atol=1e-15)
    d = r.deg()
    assert type(d["X"]) is float and d["X"] == pytest.approx(90.0, abs=1e-12)
    np.testing.assert_allclose(d["Y"], [0.0, 180.0], atol=1e-12)


def test_as_reading_takes_readings_and_mappings_and_refuses_a_true_pose():
    from rigsim.rig.turntable import TruePose, TurntableReading, as_reading

    r = TurntableReading({"X": 0.1})
    assert as_reading(r) is r
    m = as_reading({"X": 0.2})
    assert type(m) is TurntableReading and m["X"] == 0.2
    with pytest.raises(TypeError, match="TruePose"):
        as_reading(TruePose({"X": 0.1}))
    with pytest.raises(TypeError):
        as_reading([0.1, 0.2])
