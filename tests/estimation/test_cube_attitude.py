"""The mount-frame normal of a nulled face (cube_attitude.normal_in_mount) against scipy's rotations: at a
null the face normal is the beam direction seen from the mount, R_rot_from_mount(θ)ᵀ·d̂, for a beam given
with any length and for the default beam +Z′."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rigsim.estimation.cube_attitude import normal_in_mount
from rigsim.rig.turntable import TurntableModel


def _R_xy(a, b):  # X′ outer carrying Y′: Rot(X′, a)·Rot(Y′, b), active right-handed (scipy)
    return (Rotation.from_rotvec([a, 0.0, 0.0]) * Rotation.from_rotvec([0.0, b, 0.0])).as_matrix()


@pytest.mark.parametrize("a,b", [(0.3, -0.7), (-1.2, 0.45)])
def test_normal_in_mount_is_the_unit_beam_in_the_mount_frame(a, b):
    m = TurntableModel.nominal(["X", "Y"])
    R = _R_xy(a, b)
    d = np.array([0.0, 3.0, 4.0])  # length 5: the result must be the unit direction
    n = normal_in_mount(m, {"X": a, "Y": b}, d)
    np.testing.assert_allclose(n, R.T @ np.array([0.0, 0.6, 0.8]), atol=1e-14)
    assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-14)


def test_normal_in_mount_default_beam_is_plus_z():
    m = TurntableModel.nominal(["X", "Y"])
    a, b = 0.3, -0.7
    n = normal_in_mount(m, {"X": a, "Y": b})
    # Rᵀ·(0, 0, 1) by hand: Rot(X, a)·Rot(Y, b) has third row (−cos a sin b, sin a, cos a cos b)
    np.testing.assert_allclose(n, [-np.cos(a) * np.sin(b), np.sin(a), np.cos(a) * np.cos(b)], atol=1e-14)
