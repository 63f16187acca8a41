import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rigsim import frames as F


@pytest.mark.parametrize("theta", [0.0, 0.3, -1.2, np.pi, 3.0])
def test_rot_matrices_are_seed000_eqs_9_10(theta):
    c, s = np.cos(theta), np.sin(theta)
    np.testing.assert_allclose(F.Rot_X(theta), [[1, 0, 0], [0, c, -s], [0, s, c]], atol=1e-15)
    np.testing.assert_allclose(F.Rot_Y(theta), [[c, 0, s], [0, 1, 0], [-s, 0, c]], atol=1e-15)
    np.testing.assert_allclose(F.Rot_Z(theta), [[c, -s, 0], [s, c, 0], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(F.Rot_X(theta), Rotation.from_euler("x", theta).as_matrix(), atol=1e-15)


def test_rot_broadcasts():
    th = np.linspace(-1, 1, 7)
    R = F.Rot_Y(th)
    assert R.shape == (7, 3, 3)
    np.testing.assert_allclose(R[3], np.eye(3), atol=1e-15)


def test_arcsec_helpers():
    assert F.arcsec(np.pi / 180) == pytest.approx(3600.0)
    assert F.from_arcsec(3600.0) == pytest.approx(np.pi / 180)
    assert F.arcsec(F.from_arcsec(2.34)) == pytest.approx(2.34)


def test_rotation_angle_closed_form():
    a, b = 0.7, -0.2
    assert F.rotation_angle(F.Rot_X(a), F.Rot_X(b)) == pytest.approx(0.9, abs=1e-12)
    # composition about orthogonal axes: cos(angle) = (trace - 1)/2
    R1 = F.Rot_X(0.1) @ F.Rot_Y(0.2)
    expected = np.arccos((np.trace(R1) - 1) / 2)
    assert F.rotation_angle(R1, np.eye(3)) == pytest.approx(expected, abs=1e-12)


def test_small_angle_error_recovers_perturbation():
    rng = np.random.default_rng(3)
    R_true = F.random_rotations(20, rng)
    delta = rng.normal(0, F.from_arcsec(5.0), (20, 3))
    R_est = np.stack([F.perturb(R, d) for R, d in zip(R_true, delta)])
    np.testing.assert_allclose(F.small_angle_error(R_est, R_true), delta, atol=1e-15)
    np.testing.assert_allclose(F.rotation_angle(R_est, R_true), np.linalg.norm(delta, axis=1), rtol=1e-9)


def test_angle_between_is_accurate_near_zero():
    a = np.array([0, 0, 1.0])
    b = F.Rot_X(F.from_arcsec(0.01)) @ a
    assert F.arcsec(F.angle_between(a, b)) == pytest.approx(0.01, rel=1e-6)
