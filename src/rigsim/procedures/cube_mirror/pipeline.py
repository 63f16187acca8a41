"""The cube-mirror pipeline (seeds 000/001) on observations and the nominal rig only (no truth, no
renderer: an import contract enforces it): the sun-sensor calibration from the sweep's turntable
readings and centroids (step 1 / B), TRIAD from the readings at the two face nulls (step 4 / C3),
and R(cube←sun) = R(cube←rot)·R(sun←rot)ᵀ (seed 001 eq 9)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rigsim.estimation.cube_attitude import cube_from_rot_triad
from rigsim.estimation.sun_calibration import SunCalibration, calibrate_sun_sensor
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import NOMINAL_D, TurntableModel, TurntableReading


@dataclass
class CubeMirrorEstimate:
    """What the procedure recovers from its observations and the nominal rig (no truth)."""

    axis_order: str
    calibration: SunCalibration | None  # step 1 / B; None: not run (see :func:`compare`)
    null_readings: list[TurntableReading]  # θ1, θ2 / θ3, θ4 as read at the two nulls
    R_cube_from_rot: np.ndarray

    @property
    def R_sun_from_rot(self) -> np.ndarray | None:
        return None if self.calibration is None else self.calibration.R_sun_from_rot

    @property
    def R_cube_from_sun(self) -> np.ndarray | None:
        """Seed 001 eq 9: R(cube←sun) = R(cube←rot)·R(sun←rot)ᵀ."""
        R_sun = self.R_sun_from_rot
        return None if R_sun is None else self.R_cube_from_rot @ R_sun.T


def fit_sun_sensor(rig: CubeMirrorRig, readings, uv, axis_order: str, d_rot=NOMINAL_D, *,
                   sigma_uv=None) -> SunCalibration:
    """Step 1 / B: intrinsics and R(sun←rot) by least squares from the sweep's turntable readings and
    sun-image centroids, with the nominal turntable (nesting ``axis_order``) and the design focal
    length as the start. Frames beyond ``procedure.sweep_max_field_deg`` from the axis or beyond
    ``procedure.sweep_outlier_sigma`` are left out (``sigma_uv``: the centroids' 1σ, which scales the
    outlier test, weights the fit when ``procedure.sweep_fit_weights`` says so, and the fit is judged
    against it, :func:`sweep_sigma`)."""
    ss = rig.sun_sensor
    sig, source = sweep_sigma(rig, sigma_uv, len(np.asarray(uv).reshape(-1, 2)))
    return calibrate_sun_sensor(readings, uv, TurntableModel.nominal(list(axis_order)), *ss.resolution_px,
                                f_guess_px=ss.fx_px, d_rot=d_rot, sigma_uv=sig, noise_source=source,
                                outlier_sigma=rig.procedure.sweep_outlier_sigma,
                                max_field_deg=rig.procedure.sweep_max_field_deg,
                                weighted=rig.procedure.sweep_fit_weights == "centroid_sigma")


def sweep_sigma(rig: CubeMirrorRig, sigma_uv, n: int) -> tuple[np.ndarray | None, str]:
    """The sweep centroids' 1σ (n, 2) the fit is judged against, and a phrase naming it: the
    centroider's per-frame σ (``sigma_uv``; where a frame has none, the median of the others), else
    the rig's ``sun_sensor.centroid_sigma_px`` for every frame; (None, "") when there is none (an
    ideal rig's σ of 0)."""
    s = None if sigma_uv is None else np.array(np.broadcast_to(np.asarray(sigma_uv, float), (n, 2)))
    good = np.zeros((n, 2), bool) if s is None else np.isfinite(s) & (s > 0)
    if good.all():
        return s, "the centroids' σ"
    if good.any():
        s[~good] = float(np.median(s[good]))
        return s, "the centroids' σ (their median where a frame has none)"
    nominal = float(rig.sun_sensor.centroid_sigma_px)
    if nominal > 0:
        return np.full((n, 2), nominal), f"the rig's sun_sensor.centroid_sigma_px = {nominal:g} px (no centroid σ given)"
    return None, ""


def estimate(rig: CubeMirrorRig, null_readings, axis_order: str, *, sweep_readings=None, sweep_uv=None,
             calibration: SunCalibration | None = None, d_rot=NOMINAL_D, sweep_sigma_uv=None) -> CubeMirrorEstimate:
    """Steps 1/B, 4/C3 and 5/D from the observations and the nominal rig: the sweep (its readings and
    sun-image centroids, or an existing ``calibration``) and the readings at the two nulls (TRIAD
    with the nominal turntable of nesting ``axis_order``)."""
    cal = calibration
    if sweep_readings is not None:
        cal = fit_sun_sensor(rig, sweep_readings, sweep_uv, axis_order, d_rot, sigma_uv=sweep_sigma_uv)
    R_cr, _, _ = cube_from_rot_triad(null_readings, rig.procedure.faces, axis_order, d_rot)
    return CubeMirrorEstimate(axis_order, cal, list(null_readings), R_cr)


def default_axis_order(rig: CubeMirrorRig) -> str:
    return "".join(a.label for a in rig.turntable.axes)
