"""One JSON shape for every cube-mirror campaign, analytic or rendered (``campaign.json``, ``--json-out``): the
three recovered rotations in the same blocks as the file stages' (``calibrate``, ``triad``, ``compose``: matrix,
Euler angles, covariance in arcsec²) with the truth and the error beside them. Published as the JSON Schema
``rigsim/schemas/cube-mirror-campaign.schema.json``."""

from __future__ import annotations

import math

import numpy as np

from rigsim.frames import ARCSEC_PER_RAD
from rigsim.procedures.cube_mirror.files import reading_sigma_rad, triad_fit_quality, triad_with_covariance
from rigsim.procedures.results import rotation_block
from rigsim.rig.turntable import TurntableReading

CAMPAIGN_FORMAT = "rigsim.cube-mirror-campaign/1"


def campaign_json(res, rig, *, mode: str, seed: int, rig_file=None, ideal: bool = False) -> dict:
    """The campaign's result record. ``res``: a :class:`~rigsim.procedures.cube_mirror.campaign.CampaignResult`.
    Covariances: R(sun←rot) from the sweep fit; R(cube←rot) propagated from the null readings' σ (each axis's
    encoder ⊕ the null's pointing σ, as ``rigsim triad``); R(cube←sun) = Σ_cube + R·Σ_sun·Rᵀ (as ``rigsim
    compose``). The estimators never saw the ``true_matrix`` fields: they are the rendered truth."""
    sigma = reading_sigma_rad(rig)
    readings = [TurntableReading({k: math.radians(v) for k, v in p.items()}) for p in res.null_poses_deg]
    faces = list(rig.procedure.faces)
    _, C_cube = triad_with_covariance(readings, faces, res.axis_order, sigma)
    triad_fit = triad_fit_quality(readings, faces, res.axis_order, sigma)  # as `rigsim triad` judges it
    C_cube = C_cube * triad_fit.covariance_scale
    cal = res.calibration
    C_sun = np.asarray(cal.rotation_covariance_rad2) if cal is not None else np.zeros((3, 3))
    R = res.R_cube_from_sun_est
    C_cs = C_cube + R @ C_sun @ R.T

    def block(est, true, cov, err):
        return {**rotation_block(est, cov), "true_matrix": np.asarray(true).tolist(),
                "error_arcsec": np.asarray(err).tolist()}

    out = {
        "format": CAMPAIGN_FORMAT, "procedure": "cube-mirror", "mode": mode,
        "rig": rig.name, "rig_file": None if rig_file is None else str(rig_file), "seed_document": rig.seed_document,
        "seed": int(seed), "axis_order": res.axis_order, "ideal": bool(ideal), "faces": faces,
        "null_readings_deg": res.null_poses_deg,
        "reading_sigma_arcsec": {k: v * ARCSEC_PER_RAD for k, v in sigma.items()},
        "error_arcsec": res.error_arcsec.tolist(),
        "R_sun_from_rot": block(res.R_sun_from_rot_est, res.R_sun_from_rot_true, C_sun, res.sun_error_arcsec),
        "R_cube_from_rot": block(res.R_cube_from_rot_est, res.R_cube_from_rot_true, C_cube, res.cube_error_arcsec),
        "R_cube_from_sun": block(res.R_cube_from_sun_est, res.R_cube_from_sun_true, C_cs, res.error_arcsec),
        "triad_fit": triad_fit.as_dict(),
    }
    if cal is not None:
        n_int = len(cal.param_names) - 3
        sig = np.sqrt(np.diag(cal.covariance))
        out["intrinsics"] = dict(zip(cal.param_names[:n_int], cal.params[:n_int].tolist()))
        out["calibration"] = {"names": list(cal.param_names), "params": cal.params.tolist(), "sigma": sig.tolist(),
                              "rms_px": float(cal.rms_px), "n_points": int(cal.n_points),
                              "fit": None if cal.fit is None else cal.fit.as_dict()}
    return out
