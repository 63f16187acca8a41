"""The boresight camera's laser spots by forward-model fitting (``method="model"``): the image of the
transceiver's core on the CMOS (:class:`rigsim.optics.laser_spot_model.LaserSpotModel`, from the
nominal rig: the core's radius or the Gaussian beam's, the camera's pitch) fitted to each ROI by
maximum likelihood under the detector's noise model (:func:`rigsim.imaging.forward_model.fit_spot_model`),
starting from the thresholded centroid. No truth: the rig file's description only.

What the model leaves out: the prism glass's two ghosts (``[effects.prism_glass]``: fractions of
a percent of the light, a few pixels away; a fit of the main spot alone is biased towards them by
less than their share), the objective's Seidel aberrations (``[effects.objective_aberrations]``:
coma moves the centroid, astigmatism stretches the spot), the detector's fixed patterns (PRNU,
DSNU: a brightness, not a shape). docs/forward-model-spots.md has the measured errors.
"""

from __future__ import annotations

import math

import numpy as np

from rigsim.imaging import Flag, NoiseModel
from rigsim.imaging.forward_model import ModelFit, fit_spot_model
from rigsim.imaging.rois import RoiCentroids, centroid_rois
from rigsim.optics.gaussian_beam import beam_radius_mm
from rigsim.optics.laser_spot_model import LaserSpotModel
from rigsim.rig.boresight import BoresightRig

__all__ = ["CHI2_LIMIT", "laser_spot_shape", "model_centroid_rois", "roi_centroids"]

CHI2_LIMIT = 3.0
"""A fit whose χ²/dof exceeds this is flagged POOR_FIT (the spot is not the model's: a ghost, an
aberrated or defocused spot, a defect)."""


def laser_spot_shape(rig: BoresightRig, camera: int = 0) -> tuple[float, str]:
    """(radius px, profile) of the laser spot on camera ``camera``'s CMOS from the nominal rig: the
    core's disk (``laser.core_radius_um``), or with ``[effects.gaussian_beam]`` the beam's 1/e²
    radius w(z) in the plane conjugate to the CMOS; magnification 1 (the loop images the core at −1)."""
    cam = rig.cameras[camera]
    pitch = cam.pixel_pitch_um * 1e-3
    b = rig.effects.gaussian_beam
    if b.enabled:
        return beam_radius_mm(b.waist_radius_um * 1e-3, b.wavelength_nm, b.m_squared, b.waist_offset_mm) / pitch, \
            "gaussian"
    return rig.laser.core_radius_um * 1e-3 / pitch, "disk"


def model_centroid_rois(rois, origins_uv, radius_px: float, profile: str, noise: NoiseModel, *,
                        saturation_dn: float | None = None) -> tuple[RoiCentroids, list[ModelFit | None]]:
    """Forward-model centroids of a stack of ROIs (n, h, w) whose pixel (0, 0) is detector pixel
    ``origins_uv[k]``; each fit starts at the ROI's thresholded centroid. Saturated pixels
    (≥ ``saturation_dn``, default the array type's maximum) do not count. Returns the centroids
    (σ from the fit's Fisher information; flags INVALID when the start or the fit fails,
    POOR_FIT above :data:`CHI2_LIMIT`) and the fits."""
    stack = np.asarray(rois)
    if stack.ndim == 2:
        stack = stack[None]
    org = np.asarray(origins_uv, float).reshape(-1, 2)
    start = centroid_rois(stack, org, method="tcom", noise=noise)
    if saturation_dn is None:
        saturation_dn = np.iinfo(stack.dtype).max if np.issubdtype(stack.dtype, np.integer) else math.inf
    n = len(stack)
    uv, sig = np.full((n, 2), np.nan), np.full((n, 2), np.nan)
    flags, valid, fits = np.array(start.flags, dtype=np.int64), np.zeros(n, bool), []
    for k in range(n):
        if not start.valid[k]:
            fits.append(None)
            continue
        model = LaserSpotModel(radius_px, org[k], stack[k].shape, profile=profile)
        d = stack[k].astype(float)
        f = fit_spot_model(d, model, noise, *start.uv[k], mask=d < saturation_dn, effects=model.effects)
        fits.append(f)
        if not f.ok:
            flags[k] |= int(Flag.INVALID | Flag.NOT_CONVERGED)
            continue
        uv[k] = f.u, f.v
        sig[k] = f.sigma_u, f.sigma_v
        valid[k] = True
        if f.chi2_dof > CHI2_LIMIT:
            flags[k] |= int(Flag.POOR_FIT)
    return RoiCentroids(uv, sig, flags, valid), fits


def roi_centroids(rig: BoresightRig, rois, origins_uv, *, method: str, noise: NoiseModel,
                  camera: int = 0) -> RoiCentroids:
    """:func:`rigsim.imaging.rois.centroid_rois` for any of its methods, and ``method="model"``:
    :func:`model_centroid_rois` with the spot of camera ``camera`` (:func:`laser_spot_shape`)."""
    if method != "model":
        return centroid_rois(rois, origins_uv, method=method, noise=noise)
    radius_px, profile = laser_spot_shape(rig, camera)
    return model_centroid_rois(rois, origins_uv, radius_px, profile, noise,
                               saturation_dn=float(rig.detector.saturation_dn))[0]
