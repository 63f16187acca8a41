"""The analysis of a printed matrix: is it a rotation, and which sign slip makes it one."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rigsim.estimation.rotation_check import analyse_rotation_matrix, nearest_rotation

PATENT = [[0.9998, -0.0204, -0.0028], [0.0203, -0.9989, -0.0430], [0.0037, 0.0430, 0.9991]]


def _det_by_cofactors(M):
    (a, b, c), (d, e, f), (g, h, i) = M
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def test_the_patents_printed_matrix_is_improper_and_one_sign_repairs_it():
    """Seed 001's example R(ref←sun): det −0.9955 (cofactor expansion by hand); flipping the sign of element (2,2)
    alone makes it a rotation within 4-decimal print precision; no row or column flip does."""
    a = analyse_rotation_matrix(PATENT)
    assert a["determinant"] == pytest.approx(_det_by_cofactors(PATENT), abs=1e-12)
    assert a["determinant"] == pytest.approx(-0.99555, abs=1e-5)
    assert a["improper"] and not a["proper"]
    r = a["sign_repair"]
    assert r["change"] == "element (2,2)" and r["n_signs"] == 1 and r["alternatives"] == []
    F = np.array(PATENT)
    F[1, 1] *= -1
    assert r["determinant"] == pytest.approx(_det_by_cofactors(F), abs=1e-12)
    assert r["max_abs_MMt_minus_I"] < 1e-4
    # a whole row or column flipped leaves M·Mᵀ off by ~0.086 (the two small off-diagonal pairs no longer cancel)
    for k in range(3):
        G = np.array(PATENT)
        G[k] *= -1
        assert np.max(np.abs(G @ G.T - np.eye(3))) > 0.08


def test_a_rounded_rotation_is_proper_and_close_to_its_nearest():
    rng = np.random.default_rng(4)
    for q in Rotation.random(20, random_state=rng):
        R = q.as_matrix()
        a = analyse_rotation_matrix(np.round(R, 4))
        assert a["proper"] and a["sign_repair"] is None
        assert np.max(np.abs(np.array(a["nearest_rotation"]) - R)) < 1e-4


@pytest.mark.parametrize("k", range(9))
def test_one_flipped_element_is_found(k):
    """A rotation with one element's sign flipped (and not tiny): the repair names that element and restores R."""
    rng = np.random.default_rng(k)
    while True:
        R = Rotation.random(random_state=rng).as_matrix()
        if abs(R.flat[k]) > 0.2:
            break
    M = R.copy()
    M.flat[k] *= -1
    r = analyse_rotation_matrix(M)["sign_repair"]
    assert r["change"] == f"element ({k // 3 + 1},{k % 3 + 1})"
    np.testing.assert_allclose(r["repaired"], R, atol=1e-15)


def test_a_mirrored_axis_is_repaired_by_a_row_or_column_and_the_alternatives_are_listed():
    R = Rotation.from_euler("xyz", [10, -20, 30], degrees=True).as_matrix()
    M = R.copy()
    M[1] *= -1
    a = analyse_rotation_matrix(M)
    assert a["improper"] and a["max_abs_MMt_minus_I"] < 1e-12  # orthogonal, det −1: a reflection
    r = a["sign_repair"]
    assert r["n_signs"] == 3 and len(r["alternatives"]) == 5  # any of the 3 rows or 3 columns restores det +1
    assert np.linalg.det(r["repaired"]) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(nearest_rotation(R), R, atol=1e-12)


def test_bad_shape_is_refused():
    with pytest.raises(ValueError, match="3×3"):
        analyse_rotation_matrix([[1, 0], [0, 1]])
