"""TRIAD against rotations chosen with scipy: the known rotation back from two vector pairs, batched, from
vectors of any length; the conditioning's thresholds."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rigsim.estimation.triad import triad, triad_conditioning


def test_triad_gives_back_a_known_rotation_batched_and_from_vectors_of_any_length():
    rng = np.random.default_rng(3)
    R = Rotation.random(5, random_state=4)
    r1, r2 = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    n1, n2 = R.apply(r1), R.apply(r2)
    got = triad(n1 * 3.0, n2 * 0.2, r1 * 7.0, r2)  # lengths are not directions
    np.testing.assert_allclose(got, R.as_matrix(), atol=1e-12)
    for k in range(5):
        np.testing.assert_allclose(triad(n1[k], n2[k], r1[k], r2[k]), R[k].as_matrix(), atol=1e-12)
    # r1 is followed exactly, r2 only for the rotation about it: a noisy n2 leaves R·r1 = n1
    bad = triad(n1[0], n2[0] + [0.01, -0.02, 0.0], r1[0], r2[0])
    np.testing.assert_allclose(bad @ r1[0] / np.linalg.norm(r1[0]), n1[0] / np.linalg.norm(n1[0]), atol=1e-12)
    with pytest.raises(ValueError, match="parallel"):
        triad(n1[0], 2 * n1[0], r1[0], r2[0])


def _pair(angle_deg):
    a = np.radians(angle_deg)
    return np.array([0.0, 0.0, 1.0]), np.array([np.sin(a), 0.0, np.cos(a)])


@pytest.mark.parametrize("ang_r, ang_n, degenerate", [(9.5, 9.5, True), (5.0, 5.0, True), (10.5, 10.5, False),
                                                      (30.0, 30.0, False), (30.0, 31.5, True), (30.0, 30.5, False)])
def test_conditioning_thresholds(ang_r, ang_n, degenerate):
    r1, r2 = _pair(ang_r)
    n1, n2 = _pair(ang_n)
    c = triad_conditioning(n1, n2, r1, r2)
    assert c["degenerate"] is degenerate
    assert c["angle_r_deg"] == pytest.approx(ang_r) and c["angle_n_deg"] == pytest.approx(ang_n)
    assert c["inconsistency_deg"] == pytest.approx(ang_r - ang_n)
    assert c["amplification"] == pytest.approx(1.0 / np.sin(np.radians(ang_r)))
