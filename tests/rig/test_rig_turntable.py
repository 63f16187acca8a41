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
