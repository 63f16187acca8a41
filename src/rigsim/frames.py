"""Rotations and frame conventions.

Convention: ``R_b_from_a`` maps a vector's coordinates in frame *a* to frame *b*,
``v_b = R_b_from_a @ v_a``. This is the source documents' ``R(b←a)``.

Everything is built on :mod:`scipy.spatial.transform`; rigsim has no quaternion code
of its own. Functions broadcast over leading dimensions where stated.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

ARCSEC_PER_RAD = 180.0 / np.pi * 3600.0
RAD_PER_ARCSEC = 1.0 / ARCSEC_PER_RAD

_AXES = {"x": np.array([1.0, 0.0, 0.0]), "y": np.array([0.0, 1.0, 0.0]), "z": np.array([0.0, 0.0, 1.0])}


def arcsec(rad):
    """Radians → arcseconds (arrays welcome)."""
    return np.asarray(rad, dtype=float) * ARCSEC_PER_RAD


def from_arcsec(asec):
    """Arcseconds → radians (arrays welcome)."""
    return np.asarray(asec, dtype=float) * RAD_PER_ARCSEC


def deg(rad):
    return np.degrees(rad)


def rad(degrees):
    return np.radians(degrees)


def rot_axis(axis: np.ndarray | str, theta_rad) -> np.ndarray:
    """Active right-handed rotation by ``theta_rad`` about a unit ``axis``.

    Broadcasts over ``theta_rad``: returns shape ``(*theta.shape, 3, 3)``.
    """
    a = _AXES[axis.lower()] if isinstance(axis, str) else np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    th = np.asarray(theta_rad, dtype=float)
    rv = th[..., None] * a
    return Rotation.from_rotvec(rv.reshape(-1, 3)).as_matrix().reshape(*th.shape, 3, 3)


def Rot_X(theta_rad) -> np.ndarray:
    """Rot(X', θ) exactly as seed 000 eq 9: [[1,0,0],[0,c,−s],[0,s,c]]."""
    return rot_axis("x", theta_rad)


def Rot_Y(theta_rad) -> np.ndarray:
    """Rot(Y', θ) exactly as seed 000 eq 10: [[c,0,s],[0,1,0],[−s,0,c]]."""
    return rot_axis("y", theta_rad)


def Rot_Z(theta_rad) -> np.ndarray:
    """Rot(Z', θ): [[c,−s,0],[s,c,0],[0,0,1]] (same handedness as eqs 9–10)."""
    return rot_axis("z", theta_rad)


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Angle (rad) of the rotation taking ``R_b`` to ``R_a`` (geodesic distance on SO(3)).

    Broadcasts over leading dimensions.
    """
    R_a = np.asarray(R_a, dtype=float)
    R_b = np.asarray(R_b, dtype=float)
    D = np.einsum("...ij,...kj->...ik", R_a, R_b)  # R_a @ R_b^T
    shape = D.shape[:-2]
    ang = Rotation.from_matrix(D.reshape(-1, 3, 3)).magnitude()
    return ang.reshape(shape)


def small_angle_error(R_est: np.ndarray, R_true: np.ndarray) -> np.ndarray:
    """Per-axis error (rad) of ``R_est`` against ``R_true``, both ``R_b_from_a``.

    Returns the rotation vector ``δ`` with ``R_est = exp([δ]×) @ R_true``: the error is a
    small rotation of the *target* frame b, expressed about b's x, y, z axes. For small
    errors the components are the per-axis angles an autocollimator would read on b's
    faces. Broadcasts over leading dimensions.
    """
    R_est = np.asarray(R_est, dtype=float)
    R_true = np.asarray(R_true, dtype=float)
    D = np.einsum("...ij,...kj->...ik", R_est, R_true)
    shape = D.shape[:-2]
    return Rotation.from_matrix(D.reshape(-1, 3, 3)).as_rotvec().reshape(*shape, 3)


def from_euler(seq: str, angles_rad, ) -> np.ndarray:
    """Rotation matrix from Euler angles with an explicit scipy sequence.

    Upper-case ``seq`` (e.g. ``"XYZ"``) is intrinsic, lower-case extrinsic (scipy's rule).
    """
    return Rotation.from_euler(seq, angles_rad).as_matrix()


def to_euler(seq: str, R: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(R).as_euler(seq)


def random_rotations(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` rotations uniform on SO(3), drawn from ``rng`` (reproducible)."""
    return Rotation.random(n, random_state=rng).as_matrix()


def perturb(R: np.ndarray, rotvec_rad: np.ndarray) -> np.ndarray:
    """Apply a small rotation ``exp([rotvec]×)`` on the left: the target frame moves."""
    return Rotation.from_rotvec(np.asarray(rotvec_rad, dtype=float)).as_matrix() @ R


def unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad) between vectors, robust near 0 and π (atan2 form)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c = np.linalg.norm(np.cross(a, b), axis=-1)
    d = np.sum(a * b, axis=-1)
    return np.arctan2(c, d)
