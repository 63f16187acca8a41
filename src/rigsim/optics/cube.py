"""Mirror-cube faces: nominal and true outward normals."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.frames import RAD_PER_ARCSEC

FACE_NORMALS = {
    "+X": np.array([1.0, 0.0, 0.0]), "-X": np.array([-1.0, 0.0, 0.0]),
    "+Y": np.array([0.0, 1.0, 0.0]), "-Y": np.array([0.0, -1.0, 0.0]),
    "+Z": np.array([0.0, 0.0, 1.0]), "-Z": np.array([0.0, 0.0, -1.0]),
}
"""Outward normals in the cube frame. The documents' XY face is "+Z", XZ is "+Y", YZ is "+X"."""

DOCUMENT_FACE_NAMES = {"+Z": "XY", "-Z": "XY", "+Y": "XZ", "-Y": "XZ", "+X": "YZ", "-X": "YZ"}


def face_normal_cube(face: str, face_tilt_arcsec: dict | None = None) -> np.ndarray:
    """Outward normal of ``face`` in the (ideal) cube frame, including its true tilt if given."""
    n = FACE_NORMALS[face]
    if face_tilt_arcsec and face in face_tilt_arcsec:
        n = Rotation.from_rotvec(np.asarray(face_tilt_arcsec[face]) * RAD_PER_ARCSEC).as_matrix() @ n
    return n / np.linalg.norm(n)


def reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror reflection of propagation direction ``d`` off a plane with unit normal ``n``."""
    d = np.asarray(d, float)
    n = np.asarray(n, float)
    return d - 2.0 * np.sum(d * n, axis=-1, keepdims=True) * n
