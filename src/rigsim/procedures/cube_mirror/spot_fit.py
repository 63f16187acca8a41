"""The sun sensor's forward-model centroider: the spot image the rig's optics predict, fitted to a
frame's pixels by maximum likelihood (``rigsim.imaging.forward_model``), on the nominal rig only.

The model (``rigsim.optics.sun_spot_model``) is built from what the rig file says the instrument is:
the simulator's disk, the nominal camera (design focal length, principal point at the detector's
centre), and the optical effects the rig file declares on the instrument (the pinhole's
diffraction, the thick mask's vignetting, the sun's limb darkening, the simulator's angular
gradient). The gradient's direction across the disk depends on the pose: the caller gives it, from
the turntable's reading and a first calibration (:func:`gradient_axis`).
"""

from __future__ import annotations

import math

import numpy as np

from rigsim.imaging import NoiseModel
from rigsim.imaging.forward_model import ModelFit, fit_spot_model
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.sun_radiance import gradient_across
from rigsim.optics.sun_spot_model import SunSpotModel
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import NOMINAL_D

__all__ = ["MAX_CHI2_DOF", "SunSpotFitter", "fit_window_px", "model_centroids", "model_frame_spots", "sweep_fitter"]

MAX_CHI2_DOF = 3.0
"""A sweep frame whose fit has χ²/dof above this is left out (the frame does not show the modelled
spot: a second source, a defect, a wrong model)."""


class SunSpotFitter:
    """``fit(dn, origin_uv, uv0)``: the spot's centre (where the camera model projects the sun's
    centre) in a sun-sensor frame or readout window ``dn`` (DN, offset included) whose first pixel
    is ``origin_uv``, from a first estimate ``uv0``; ``axis``: the simulator's gradient direction in
    the camera frame (:meth:`gradient_axis`; without it a rig's gradient is left out of the model,
    its limb darkening too). ``camera``: the camera that shapes the spot
    (default the nominal one: design focal length, principal point at the detector's centre, no
    distortion)."""

    def __init__(self, rig: CubeMirrorRig, camera: PinholeBrown | None = None):
        ss = rig.sun_sensor
        w, h = ss.resolution_px
        self.camera = camera if camera is not None else PinholeBrown(ss.fx_px, ss.fx_px, (w - 1) / 2.0, (h - 1) / 2.0,
                                                                     0.0, 0.0, 0.0, 0.0, 0.0, w, h)
        self.full_angle_rad = math.radians(rig.sun_simulator.collimation_full_angle_arcmin / 60.0)
        eff = rig.effects
        self.radiance = eff.disk_radiance()
        self.needs_axis = self.radiance.g != 0.0
        self.gradient_rot = gradient_across(NOMINAL_D, eff.simulator_nonuniformity.direction_deg)
        self.pinhole = eff.thick_pinhole()
        self.psf = eff.pinhole_psf(ss.focal_length_mm)
        self.noise = NoiseModel.from_detector(ss.detector)
        self.saturation_dn = float(ss.detector.saturation_dn)

    def gradient_axis(self, R_sun_from_rot, R_rot_from_mount) -> np.ndarray:
        """The simulator's gradient direction in the camera frame at a pose (the rot frame's nominal
        beam, the calibrated R(sun←rot), the turntable's nominal rotation at its reading)."""
        return np.asarray(R_sun_from_rot) @ (np.asarray(R_rot_from_mount).T @ self.gradient_rot)

    def model(self, uv, origin_uv, shape_hw, axis=None) -> SunSpotModel:
        d = self.camera.unproject(np.asarray(uv, float).reshape(1, 2))[0]
        radiance = self.radiance if axis is not None or not self.needs_axis else None
        return SunSpotModel(self.camera, self.full_angle_rad, d, origin_uv, shape_hw, psf=self.psf,
                            radiance=radiance, radiance_axis=axis, pinhole=self.pinhole)

    def fit(self, dn, origin_uv, uv0, axis=None) -> ModelFit:
        a = np.asarray(dn, dtype=float)
        mask = a < self.saturation_dn
        uv = np.asarray(uv0, float).reshape(2)
        f = None
        for _ in range(2):  # the shape at the first estimate, then once more where the fit ends if it moved
            m = self.model(uv, origin_uv, a.shape, axis)
            f = fit_spot_model(a, m, self.noise, float(uv[0]), float(uv[1]), mask=mask, effects=m.effects)
            if not f.ok or math.hypot(f.u - uv[0], f.v - uv[1]) < 0.05:
                break
            uv = np.array([f.u, f.v])
        if f.ok and not f.chi2_dof <= MAX_CHI2_DOF:
            f = ModelFit(f.u, f.v, f.flux_dn, f.background_dn, f.cov, f.chi2, f.dof, f.iterations, f.converged,
                         f.effects, f"the spot model does not fit the pixels (χ²/dof {f.chi2_dof:.2f} > {MAX_CHI2_DOF:g})")
        return f


def fit_window_px(rig: CubeMirrorRig) -> int:
    """The side of the window the fit uses, centred on the spot's first estimate: the readout
    window the rig's sensor reads (the largest spot plus a margin, through the design camera) less
    2 px, so that it lies inside the readout window even when the first estimate rounds to the
    next pixel: a sweep's readout windows and whole frames written to files give the same fit."""
    from rigsim.optics.sun_disk import sun_window_px

    return sun_window_px(SunSpotFitter(rig).camera, math.radians(rig.sun_simulator.collimation_full_angle_arcmin / 60.0)) - 2


def _window(dn: np.ndarray, origin_uv, uv0, size: int, detector_hw):
    """The fit's window: ``size`` px centred on the pixel of ``uv0``, cut to ``dn``'s pixels and to the
    detector's; (its pixels, its first pixel's (u, v))."""
    o = np.asarray(origin_uv, int).reshape(2)
    c = np.floor(np.asarray(uv0, float) + 0.5).astype(int)
    lo = c - size // 2
    hi = lo + size
    h, w = detector_hw
    lo = np.maximum(lo, np.maximum(o, 0))
    hi = np.minimum(hi, np.minimum(o + np.array(dn.shape[::-1]), (w, h)))
    return dn[lo[1] - o[1]:hi[1] - o[1], lo[0] - o[0]:hi[0] - o[0]], lo


def sweep_fitter(rig: CubeMirrorRig, readings: dict, uv, sigma_uv, axis_order: str | None = None):
    """The forward-model centroider for a sweep's frames, and a function of a frame's turntable
    reading that gives the simulator's gradient direction there (None without a gradient). The
    spot's shape comes from the camera a first calibration finds on the frames' moment centroids
    (``uv``, ``sigma_uv`` at the turntable's ``readings``), the gradient's direction from its
    R(sun←rot); the nominal camera (and no gradient) when there are too few frames or that fit
    fails or is poor (a wrong angle log: the calibration that follows refuses it and names the cause). The shape of a spot far off axis follows the lens's distortion, which only the sweep
    itself measures."""
    from rigsim.procedures.cube_mirror.pipeline import default_axis_order, fit_sun_sensor
    from rigsim.rig.turntable import TurntableModel, TurntableReading

    order = axis_order or default_axis_order(rig)
    cal = None
    if len(uv) >= 8:  # what the calibration needs
        try:
            cal = fit_sun_sensor(rig, TurntableReading(readings), uv, order, sigma_uv=sigma_uv)
        except (ValueError, np.linalg.LinAlgError):
            cal = None
        if cal is not None and cal.fit is not None and cal.fit.poor:  # a wrong log: its camera would shape nothing right
            cal = None
    fitter = SunSpotFitter(rig, camera=None if cal is None else cal.camera)
    if cal is None or not fitter.needs_axis:
        return fitter, lambda reading: None
    tt = TurntableModel.nominal(list(order))
    return fitter, lambda reading: fitter.gradient_axis(cal.R_sun_from_rot, tt.R_rot_from_mount(reading))


def model_centroids(rig: CubeMirrorRig, frames, readings: dict | None, detector_hw, axis_order: str | None = None,
                    noise=None):
    """The forward-model centroid of every sweep frame, in two passes (docs/forward-model.md).
    ``frames``: (dn, origin_uv, spots) per frame, ``spots`` the frame's moment centroids
    (:func:`rigsim.imaging.frame_spots.measure_frame`, ``scurve``), brightest first; ``readings``:
    the turntable's readings {axis: (N,) rad} (None: no first calibration; the nominal camera shapes
    every spot). Each frame's brightest spot is replaced by its fit (u, v, σ; EDGE cleared: the
    model knows where the pixels end) and the frame's index of it returned (0), or None when it
    has no usable spot or the model does not fit it (the spot is then flagged INVALID, POOR_FIT).
    ``noise``: the frames' noise model, or one per frame (default the rig's sun-sensor detector's)."""
    from rigsim.imaging import Flag
    from rigsim.imaging.frame_spots import single_spot

    if readings is not None:
        first = [j for j, (_, _, sp) in enumerate(frames) if single_spot(sp) is not None]
        uv = np.array([[frames[j][2].u[0], frames[j][2].v[0]] for j in first]).reshape(-1, 2)
        sig = np.array([[frames[j][2].sigma_u[0], frames[j][2].sigma_v[0]] for j in first]).reshape(-1, 2)
        fitter, axis_at = sweep_fitter(rig, {ax: np.asarray(r)[first] for ax, r in readings.items()}, uv, sig,
                                       axis_order)
    else:
        fitter, axis_at = SunSpotFitter(rig), (lambda reading: None)
    rig_noise = fitter.noise
    size = fit_window_px(rig)
    out = []
    for j, (dn, origin, spots) in enumerate(frames):
        if len(spots) == 0 or spots.flags[0] & int(Flag.INVALID | Flag.SATURATED):
            out.append(None)
            continue
        uv0 = (float(spots.u[0]), float(spots.v[0]))
        win, o = _window(np.asarray(dn), origin, uv0, size, detector_hw)
        axis = None if readings is None else axis_at({ax: float(r[j]) for ax, r in readings.items()})
        fitter.noise = rig_noise if noise is None else noise[j] if isinstance(noise, (list, tuple)) else noise
        f = fitter.fit(win, o, uv0, axis)
        if not f.ok:
            spots.flags[0] = int(spots.flags[0]) | int(Flag.INVALID | Flag.POOR_FIT)
            out.append(None)
            continue
        spots.u[0], spots.v[0], spots.sigma_u[0], spots.sigma_v[0] = f.u, f.v, f.sigma_u, f.sigma_v
        spots.flags[0] = int(spots.flags[0]) & ~int(Flag.EDGE)
        out.append(0)
    return out


def model_frame_spots(rig: CubeMirrorRig, paths, measure, readings_of=None, progress=None, noise_of=None):
    """The forward-model centroids of sun-sensor frame files (``rigsim centroid --method model``):
    ``measure(img, path)`` gives a frame's moment centroids (brightest first); ``noise_of(img)``: a
    frame's noise model (default the rig's sun-sensor detector's); ``readings_of``: the
    frames' turntable readings {axis: (N,) rad} in ``paths``' order, or None. Each frame keeps only
    a window around its brightest spot in memory. Returns every frame's spots, the brightest
    replaced by its fit (:func:`model_centroids`)."""
    from rigsim.files import read_image

    ss = rig.sun_sensor
    shape = (ss.resolution_px[1], ss.resolution_px[0])
    keep = fit_window_px(rig) + 4
    frames, noises = [], []
    for p in paths:
        img = read_image(p, shape=shape)
        spots = measure(img, p)
        noises.append(None if noise_of is None else noise_of(img))
        if len(spots) and np.isfinite(spots.u[0]) and np.isfinite(spots.v[0]):
            win, o = _window(np.asarray(img), (0, 0), (float(spots.u[0]), float(spots.v[0])), keep, shape)
        else:
            win, o = np.zeros((0, 0)), np.zeros(2, int)
        frames.append((np.array(win, dtype=float), o, spots))
        if progress is not None:
            progress(1)
    model_centroids(rig, frames, readings_of, shape, noise=None if noise_of is None else noises)
    return [sp for _, _, sp in frames]
