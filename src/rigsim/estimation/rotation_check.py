"""Is a printed 3×3 matrix a rotation? Determinant, row and column norms, the angles between columns, the
nearest rotation (polar decomposition) and the smallest change of signs that makes the matrix proper."""

from __future__ import annotations

from itertools import combinations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["analyse_rotation_matrix", "nearest_rotation"]


def nearest_rotation(M) -> np.ndarray:
    """The rotation closest to ``M`` in the Frobenius norm: U·diag(1, 1, det(UVᵀ))·Vᵀ of M = U·S·Vᵀ."""
    U, _, Vt = np.linalg.svd(np.asarray(M, float))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def _orthogonality(M) -> float:
    return float(np.max(np.abs(M @ M.T - np.eye(3))))


def _sign_changes():
    """Candidate repairs by stage, the simplest slips first: (0) one element, (1) one row or one column (a
    mirrored axis), (2) two elements."""
    for i in range(9):
        yield 0, f"element ({i // 3 + 1},{i % 3 + 1})", [i]
    for r in range(3):
        yield 1, f"row {r + 1}", [3 * r + c for c in range(3)]
    for c in range(3):
        yield 1, f"column {c + 1}", [3 * r + c for r in range(3)]
    for a, b in combinations(range(9), 2):
        yield 2, f"elements ({a // 3 + 1},{a % 3 + 1}) and ({b // 3 + 1},{b % 3 + 1})", [a, b]


def analyse_rotation_matrix(M, *, tolerance: float | None = None) -> dict:
    """The analysis of a printed matrix ``M`` (3×3). ``tolerance``: the largest |M·Mᵀ − I| entry that the print
    precision allows (default 3e-4: a 4-decimal print's rounding, ±5e-5 per element, moves an entry of M·Mᵀ by
    up to 2·3·5e-5).

    Returns determinant, row and column norms, the angles between columns (deg), max |M·Mᵀ − I|, ``proper``
    (a rotation within the tolerance), the nearest rotation and its largest element difference from M,
    and ``sign_repair``: the simplest sign change (one element; else one row or column; else two elements) after
    which the matrix is a proper rotation within the tolerance (the best-fitting one if several, the others in
    ``alternatives``), or None."""
    M = np.asarray(M, float)
    if M.shape != (3, 3) or not np.all(np.isfinite(M)):
        raise ValueError(f"expected a finite 3×3 matrix, got shape {M.shape}")
    tol = 3e-4 if tolerance is None else float(tolerance)
    cols = M / np.linalg.norm(M, axis=0, keepdims=True)
    ang = {f"{i + 1}-{j + 1}": float(np.degrees(np.arccos(np.clip(cols[:, i] @ cols[:, j], -1, 1))))
           for i, j in ((0, 1), (0, 2), (1, 2))}
    det = float(np.linalg.det(M))
    orth = _orthogonality(M)
    R = nearest_rotation(M)
    out = {"matrix": M.tolist(), "determinant": det, "row_norms": np.linalg.norm(M, axis=1).tolist(),
           "column_norms": np.linalg.norm(M, axis=0).tolist(), "column_angles_deg": ang,
           "max_abs_MMt_minus_I": orth, "tolerance": tol, "proper": bool(det > 0 and orth <= tol),
           "improper": bool(det < 0), "nearest_rotation": R.tolist(),
           "nearest_rotation_euler_xyz_deg": Rotation.from_matrix(R).as_euler("xyz", degrees=True).tolist(),
           "max_abs_M_minus_nearest": float(np.max(np.abs(M - R))), "sign_repair": None}
    if out["proper"]:
        return out
    found = []
    for stage, label, idx in _sign_changes():
        if found and stage > found[0][3]:
            break
        F = M.copy().ravel()
        F[idx] *= -1.0
        F = F.reshape(3, 3)
        if np.linalg.det(F) > 0 and _orthogonality(F) <= tol:
            found.append((label, idx, F, stage))
    if found:  # the best-fitting of the repairs with the fewest changed signs; the others listed
        label, idx, F, _ = min(found, key=lambda t: _orthogonality(t[2]))
        Rf = nearest_rotation(F)
        out["sign_repair"] = {"change": label, "n_signs": len(idx), "repaired": F.tolist(),
                              "determinant": float(np.linalg.det(F)), "max_abs_MMt_minus_I": _orthogonality(F),
                              "nearest_rotation": Rf.tolist(),
                              "euler_xyz_deg": Rotation.from_matrix(Rf).as_euler("xyz", degrees=True).tolist(),
                              "max_abs_repaired_minus_nearest": float(np.max(np.abs(F - Rf))),
                              "alternatives": [t[0] for t in found if t[0] != label]}
    return out
