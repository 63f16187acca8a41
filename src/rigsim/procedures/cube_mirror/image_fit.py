"""Image-based calibration of the sun sensor: its intrinsics and R(sun←rot) fitted to the pixels of
every sweep frame jointly, through the forward model of the spot (docs/forward-model.md).

The expected DN of pixel k of frame i is Fᵢ·Pᵢ(uᵢ(θ), vᵢ(θ)) + Bᵢ: the frame's spot model Pᵢ
(:class:`rigsim.optics.sun_spot_model.SunSpotModel`, shaped once by the centroid-then-fit
calibration's camera) placed where the calibration θ (intrinsics, distortion, R(sun←rot)) projects
the sun at that frame's turntable reading; Fᵢ and Bᵢ are each frame's own flux and background.
Gauss–Newton on θ with every frame's Fᵢ, Bᵢ eliminated exactly (Schur complement) at each step;
the weights are the detector's noise model at the expected DN. The covariance is the inverse of the
reduced normal matrix: the image's own Fisher information about θ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.estimation.fit_quality import FitQuality, judge_chi2
from rigsim.estimation.sun_calibration import SunCalibration, SweepModel, sun_directions_in_mount
from rigsim.imaging.forward_model import model_derivatives
from rigsim.procedures.cube_mirror.spot_fit import SunSpotFitter, _window, fit_window_px
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import NOMINAL_D, TurntableModel

__all__ = ["ImageCalibration", "fit_sweep_images"]


@dataclass
class ImageCalibration:
    """The image-based fit: the calibration (as :class:`SunCalibration` holds it), the pixels' χ²
    against the noise model, the iterations it took."""

    calibration: SunCalibration
    fit: FitQuality
    iterations: int
    n_frames: int
    n_pixels: int


def fit_sweep_images(rig: CubeMirrorRig, windows, readings, start: SunCalibration, uv, axis_order: str,
                     max_iter: int = 15, tol: float = 1e-3) -> ImageCalibration:
    """Fit θ to the frames' pixels (module docstring). ``windows``: each kept frame's (dn, origin_uv);
    ``readings``: their turntable readings {axis: (N,) rad}; ``start``: the centroid-then-fit
    calibration on the same frames (θ's start and the spots' shapes); ``uv``: the frames' forward-model
    centroids (where each model is shaped). Stops when every step moves θ by less than ``tol`` of its
    σ."""
    tt = TurntableModel.nominal(list(axis_order))
    m_dirs = sun_directions_in_mount(tt, readings, NOMINAL_D)
    names = start.param_names[:-3]
    sm = SweepModel(m_dirs, np.zeros((len(m_dirs), 2)), names)
    fitter = SunSpotFitter(rig, camera=start.camera)
    size = fit_window_px(rig)
    shape = (rig.sun_sensor.resolution_px[1], rig.sun_sensor.resolution_px[0])
    frames = []
    for j, (dn, origin) in enumerate(windows):
        win, o = _window(np.asarray(dn, float), origin, uv[j], size, shape)
        reading = {ax: float(np.asarray(r)[j]) for ax, r in readings.items()}
        axis = fitter.gradient_axis(start.R_sun_from_rot, tt.R_rot_from_mount(reading)) if fitter.needs_axis else None
        model = fitter.model(uv[j], o, win.shape, axis)
        frames.append((win.ravel(), (win < fitter.saturation_dn).ravel(), model))
    R_ref = start.R_sun_from_rot
    x = np.concatenate([start.params[:-3], np.zeros(3)])
    P = len(x)
    noise = fitter.noise
    it, chi2, npix = 0, 0.0, 0
    for it in range(1, max_iter + 1):
        proj = sm.residual(x, R_ref).reshape(-1, 2)
        J = sm.jacobian(x, R_ref).reshape(-1, 2, P)
        N = np.zeros((P, P))
        g = np.zeros(P)
        chi2, npix = 0.0, 0
        for i, (d, keep, model) in enumerate(frames):
            p, du, dv = (a.ravel()[keep] for a in model_derivatives(model, *proj[i]))
            y = d[keep]
            C = np.stack([p, np.ones_like(p)], axis=1)
            # the frame's flux and background at this position, weighted by the noise at the model
            mu0 = np.maximum(C @ np.linalg.lstsq(C, y, rcond=None)[0], 0.0)
            w = 1.0 / noise.variance(mu0)
            CtW = C.T * w
            fb = np.linalg.solve(CtW @ C, CtW @ y)
            r = y - C @ fb
            A = fb[0] * (du[:, None] * J[i, 0][None, :] + dv[:, None] * J[i, 1][None, :])
            AtW = A.T * w
            K = np.linalg.solve(CtW @ C, CtW @ A)  # (2, P): the nuisance's response to θ
            N += AtW @ A - (AtW @ C) @ K
            g += AtW @ r - (CtW @ A).T @ np.linalg.solve(CtW @ C, CtW @ r)
            chi2 += float(np.sum(w * r * r))
            npix += len(y)
        step = np.linalg.solve(N, g)
        x = x + step
        sig = np.sqrt(np.maximum(np.diag(np.linalg.inv(N)), 1e-300))
        if np.all(np.abs(step) < tol * sig):
            break
    R = Rotation.from_rotvec(x[-3:]).as_matrix() @ R_ref
    cov = np.linalg.inv(N)
    dof = npix - 2 * len(frames) - P
    q = judge_chi2(chi2, dof, "the detector's noise model at each pixel", unit="DN")
    cam = fitter.camera.__class__(**{k: dict(zip(names, x[:len(names)])).get(k, 0.0)
                                     for k in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")},
                                  width=rig.sun_sensor.resolution_px[0], height=rig.sun_sensor.resolution_px[1])
    res = (sm.residual(x, R_ref).reshape(-1, 2) - np.asarray(uv, float))
    cal = SunCalibration(cam, R, list(start.param_names), np.concatenate([x[:-3], np.zeros(3)]), cov,
                         float(np.sqrt(np.mean(res**2) * 2)), len(frames), res, np.asarray(uv, float), fit=q)
    return ImageCalibration(cal, q, it, len(frames), npix)
