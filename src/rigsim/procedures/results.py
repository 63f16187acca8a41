"""Blocks shared by every procedure's JSON result: a recovered rotation with its covariance and,
when the truth is known, the true matrix and the error beside it (:func:`rotation_block`); the
common header (:func:`result_header`). The shapes are published as JSON Schema files in
``rigsim/schemas`` (docs/formats.md)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.files import covariance_block
from rigsim.frames import ARCSEC_PER_RAD, small_angle_error

ROTATION_CONVENTION = "R_true ≈ exp([δ]×)·R, δ = (δx, δy, δz) about the target frame's axes, arcsec"
ARCSEC3 = ["arcsec"] * 3  # per parameter; the matrix is in arcsec²


def rotation_block(R, cov_rad2, true=None) -> dict:
    """One recovered rotation R(b←a): matrix, intrinsic-xyz Euler angles, the covariance of the small
    rotation about b's axes (arcsec²) and, with ``true``, the true matrix and the error δ (arcsec)
    with R = exp([δ]×)·R_true."""
    R = np.asarray(R, float)
    out = {"matrix": R.tolist(), "euler_xyz_deg": Rotation.from_matrix(R).as_euler("xyz", degrees=True).tolist(),
           "covariance": covariance_block(["dx", "dy", "dz"], np.asarray(cov_rad2, float) * ARCSEC_PER_RAD**2, ARCSEC3),
           "convention": ROTATION_CONVENTION}
    if true is not None:
        out["true_matrix"] = np.asarray(true, float).tolist()
        out["error_arcsec"] = (small_angle_error(R, true) * ARCSEC_PER_RAD).tolist()
    return out


def result_header(fmt: str, procedure: str, mode: str, rig, *, seed=None, rig_file=None) -> dict:
    """The keys every result starts with: format (name/version), procedure, mode (``files`` for a user's
    files, ``analytic`` or ``rendered`` for rigsim's own campaigns), the rig and the seed (null for files)."""
    return {"format": fmt, "procedure": procedure, "mode": mode, "rig": rig.name,
            "rig_file": None if rig_file is None else str(rig_file), "seed_document": getattr(rig, "seed_document", None),
            "seed": None if seed is None else int(seed)}
