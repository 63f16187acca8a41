"""The sun sensor's forward-model centroider: the spot image the rig's optics predict, fitted to a
frame's pixels by maximum likelihood (``rigsim.imaging.forward_model``), on the nominal rig only.

The model (``rigsim.optics.sun_spot_model``) is built from what the rig file says the instrument is:
the simulator's disk, the nominal camera (design focal length, principal point at the detector's
centre), and the optical effects the rig file declares on the instrument (the pinhole's
diffraction, the thick mask's vignetting, the sun's limb darkening). The simulator's angular
gradient is not modelled: its direction across the disk depends on the pose.
"""

from __future__ import annotations

import math

import numpy as np

from rigsim.imaging import NoiseModel
from rigsim.imaging.forward_model import ModelFit, fit_spot_model
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.sun_spot_model import SunSpotModel
from rigsim.rig.cube_mirror import CubeMirrorRig

__all__ = ["MAX_CHI2_DOF", "SunSpotFitter"]

MAX_CHI2_DOF = 3.0
"""A sweep frame whose fit has χ²/dof above this is left out (the frame does not show the modelled
spot: a second source, a defect, a wrong model)."""


class SunSpotFitter:
    """``fit(dn, origin_uv, uv0)``: the spot's centre (where the camera model projects the sun's
    centre) in a sun-sensor frame or readout window ``dn`` (DN, offset included) whose first pixel
    is ``origin_uv``, from a first estimate ``uv0``. ``camera``: the camera that shapes the spot
    (default the nominal one: design focal length, principal point at the detector's centre, no
    distortion)."""

    def __init__(self, rig: CubeMirrorRig, camera: PinholeBrown | None = None):
        ss = rig.sun_sensor
        w, h = ss.resolution_px
        self.camera = camera if camera is not None else PinholeBrown(ss.fx_px, ss.fx_px, (w - 1) / 2.0, (h - 1) / 2.0,
                                                                     0.0, 0.0, 0.0, 0.0, 0.0, w, h)
        self.full_angle_rad = math.radians(rig.sun_simulator.collimation_full_angle_arcmin / 60.0)
        eff = rig.effects
        self.radiance = eff.disk_radiance(with_gradient=False)
        self.pinhole = eff.thick_pinhole()
        self.psf = eff.pinhole_psf(ss.focal_length_mm)
        self.noise = NoiseModel.from_detector(ss.detector)
        self.saturation_dn = float(ss.detector.saturation_dn)

    def model(self, uv, origin_uv, shape_hw) -> SunSpotModel:
        d = self.camera.unproject(np.asarray(uv, float).reshape(1, 2))[0]
        return SunSpotModel(self.camera, self.full_angle_rad, d, origin_uv, shape_hw, psf=self.psf,
                            radiance=self.radiance, pinhole=self.pinhole)

    def fit(self, dn, origin_uv, uv0) -> ModelFit:
        a = np.asarray(dn, dtype=float)
        mask = a < self.saturation_dn
        uv = np.asarray(uv0, float).reshape(2)
        f = None
        for _ in range(2):  # the shape at the first estimate, then once more where the fit ends if it moved
            m = self.model(uv, origin_uv, a.shape)
            f = fit_spot_model(a, m, self.noise, float(uv[0]), float(uv[1]), mask=mask, effects=m.effects)
            if not f.ok or math.hypot(f.u - uv[0], f.v - uv[1]) < 0.05:
                break
            uv = np.array([f.u, f.v])
        if f.ok and not f.chi2_dof <= MAX_CHI2_DOF:
            f = ModelFit(f.u, f.v, f.flux_dn, f.background_dn, f.cov, f.chi2, f.dof, f.iterations, f.converged,
                         f.effects, f"the spot model does not fit the pixels (χ²/dof {f.chi2_dof:.2f} > {MAX_CHI2_DOF:g})")
        return f
