"""Forward-model fits of the cube-mirror rigs' image spots other than the sun sensor's
(``method="model"`` of the file stages; docs/forward-model-spots.md):

* :func:`fit_autocollimator_spot` — seed 001's autocollimator return
  (:class:`rigsim.optics.autocollimator_spot_model.AutocollimatorSpotModel`: the exact trace of the
  nominal instrument off the nominal mirror tilted to the spot's first reading, with the return
  pupil's diffraction);
* :func:`fit_screen_spot` — seed 000's divergent spot on the diaphragm screen as the aiming camera
  sees it (:class:`rigsim.optics.screen_spot_model.ScreenSpotModel`: the pencil's disk blurred by the
  divergence's disk, less the light lost into the hole, through the nominal homography).

Both start from the current centroider's result and use the rig file's nominal description only
(no truth), the detector's noise model and :func:`rigsim.imaging.forward_model.fit_spot_model`.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from rigsim.errors import InputError
from rigsim.imaging import NoiseModel
from rigsim.imaging.forward_model import ModelFit, fit_spot_model
from rigsim.imaging.spot import SpotMeasurement, measure_spot
from rigsim.rig.cube_mirror import CubeMirrorRig

__all__ = ["CHI2_LIMIT", "fit_autocollimator_spot", "fit_screen_spot", "screen_spot_radii_mm"]

CHI2_LIMIT = 3.0
"""A fit whose χ²/dof exceeds this is refused: the frame's spot is not the model's (an effect the
model leaves out, a wrong target, a defect)."""


# ------------------------------------------------------------------------------ autocollimator
def fit_autocollimator_spot(rig: CubeMirrorRig, dn: np.ndarray, mirror: tuple[str, float], *, optics,
                            roi_px: int, n_rays: int = 400_000,
                            construction: str = "optics") -> tuple[SpotMeasurement, ModelFit | None]:
    """The autocollimator's return spot on a full DN frame of the mirror ``mirror`` = (outline
    ``"square"`` or ``"disk"``, size mm: the frame's target in
    :func:`~rigsim.procedures.cube_mirror.null_files.autocollimator_targets`) by forward-model
    fitting: detection and first estimate by :func:`measure_spot` on the ``roi_px`` window (its
    refusals), then the model of that mirror as the rig describes it (centred, at the instrument's
    distance) tilted to the first estimate's reading (``optics``: the nominal instrument), fitted on
    the same window. Returns the measurement (``uv``: the spot's ray centroid, what the calibration
    reads; ``sigma_uv`` from the fit) and the fit (None when the first estimate was refused).
    ``construction``: ``"optics"`` (the instrument's image) or ``"renderer"`` (the image as rigsim's
    renderer draws it, diffraction applied after pixel binning: for rigsim's own frames;
    :class:`AutocollimatorSpotModel`)."""
    from rigsim.optics.autocollimator import diffraction_half_px, peak_over_noise, retilt
    from rigsim.optics.autocollimator_spot_model import AutocollimatorSpotModel

    eff = getattr(rig, "effects", None)
    if eff is not None and getattr(getattr(eff, "reticle", None), "enabled", False):
        raise InputError("the autocollimator projects a reticle pattern ([effects.reticle]): the spot model is a "
                         "point reticle's; use the reticle's line fits")
    det = rig.autocollimator.detector
    W = int(roi_px)
    sm = measure_spot(dn, det, roi_px=W)
    if not sm.ok:
        return sm, None
    shape, size = mirror
    m0 = optics.centred_mirror(shape, size)
    # the diffraction pattern out to the background noise at the instrument's brightness setting
    half_k = diffraction_half_px(optics.spot_extent(m0, k_sigma=1.0, peak_over_noise=peak_over_noise(det, 0.5)))
    tilted = retilt(m0, optics.reading(sm.uv))
    a = np.asarray(dn, float)
    o = np.floor(sm.uv + 0.5).astype(int) - W // 2
    if o[0] < 0 or o[1] < 0 or o[0] + W > a.shape[1] or o[1] + W > a.shape[0]:
        return replace(sm, uv=None, problem="the spot's fit window leaves the detector"), None
    roi = a[o[1]:o[1] + W, o[0]:o[0] + W]
    model = AutocollimatorSpotModel(optics, tilted, o, (W, W), diffraction_half_px=half_k, n_rays=n_rays,
                                    construction=construction)
    f = fit_spot_model(roi, model, NoiseModel.from_detector(det), *sm.uv, mask=roi < float(det.saturation_dn),
                       effects=model.effects)
    if not f.ok:
        return replace(sm, uv=None, problem=f"the spot model's fit failed: {f.problem}"), f
    if f.chi2_dof > CHI2_LIMIT:
        return replace(sm, uv=None, problem=f"the spot is not the model's (χ²/dof = {f.chi2_dof:.2f} > {CHI2_LIMIT:g}): "
                                            "an effect the model leaves out, or the wrong target"), f
    return replace(sm, uv=np.array([f.u, f.v]), sigma_uv=np.array([f.sigma_u, f.sigma_v])), f


# ------------------------------------------------------------------------------ aiming camera
def screen_spot_radii_mm(rig: CubeMirrorRig) -> tuple[float, float]:
    """(pencil radius, divergence blur radius) of the returned spot on the screen, mm, from the nominal
    rig: the hole's radius, and (hole → face → screen path) × tan(α/2) with α the sun simulator's
    collimation angle."""
    a = 0.5 * rig.diaphragm_screen.hole_diameter_mm
    alpha = math.radians(rig.sun_simulator.collimation_full_angle_arcmin / 60.0)
    return a, 2.0 * rig.diaphragm_screen.distance_to_cube_mm * math.tan(0.5 * alpha)


def fit_screen_spot(rig: CubeMirrorRig, hole_dn: np.ndarray, spot_dn: np.ndarray, *, hole_mm=None,
                    start_mm=None, hole_margin_px: float = 2.0) -> tuple[dict, ModelFit | None]:
    """The returned spot's centre on the screen (mm) by forward-model fitting of the spot frame.
    ``hole_mm``, ``start_mm``: the hole's centre and the spot's first estimate on the screen (default:
    :func:`rigsim.imaging.screen.hole_spot_offset`'s). The model (pencil disk ⊗ divergence disk, the
    light lost into the hole) is fitted on the window holding the whole spot, without the hole's
    pixels and ``hole_margin_px`` around them (its glow is in the frame, not in the model) and
    without saturated pixels. Returns ({"spot_mm", "sigma_mm", "chi2_dof", "problem"}, fit)."""
    from rigsim.imaging.screen import hole_spot_offset, plane_to_uv
    from rigsim.optics.aiming import nominal_screen_homography
    from rigsim.optics.screen_spot_model import ScreenSpotModel

    ac = rig.aiming_camera
    if rig.procedure.method != "diaphragm" or ac is None:
        raise InputError(f"rig {rig.name!r} has no diaphragm screen and aiming camera (seed 000's method)")
    H = nominal_screen_homography(ac)
    det = ac.detector
    if hole_mm is None or start_mm is None:
        m = hole_spot_offset(hole_dn, spot_dn, H, object_pixel_mm=ac.object_pixel_mm,
                             offset_dn=det.offset_dn * det.code_step_dn, background=ac.hole_background)
        hole_mm = m["hole_mm"] if hole_mm is None else hole_mm
        start_mm = m["spot_mm"] if start_mm is None else start_mm
    out = {"spot_mm": np.full(2, np.nan), "sigma_mm": np.full(2, np.nan), "chi2_dof": math.nan, "problem": None}
    if not (np.all(np.isfinite(hole_mm)) and np.all(np.isfinite(start_mm))):
        out["problem"] = "no hole or no spot found (first estimate)"
        return out, None
    a, R = screen_spot_radii_mm(rig)
    d = np.asarray(spot_dn, float)
    Hh, Ww = d.shape
    ang = np.linspace(0.0, 2 * math.pi, 256, endpoint=False)
    rim = plane_to_uv(H, np.asarray(start_mm) + (a + R) * np.stack([np.cos(ang), np.sin(ang)], 1))
    u0, v0 = (max(0, int(math.floor(x)) - 4) for x in rim.min(axis=0))
    u1, v1 = (int(math.ceil(x)) + 5 for x in rim.max(axis=0))
    u1, v1 = min(u1, Ww), min(v1, Hh)
    if u1 - u0 < 8 or v1 - v0 < 8:
        out["problem"] = "the spot is off the aiming camera's frame"
        return out, None
    model = ScreenSpotModel(H, (u0, v0), (v1 - v0, u1 - u0), a, R, hole_centre_st=hole_mm, hole_radius_mm=a)
    roi = d[v0:v1, u0:u1]
    near_hole = model.hole_coverage > 0
    if hole_margin_px > 0 and near_hole.any():
        from scipy.ndimage import binary_dilation

        near_hole = binary_dilation(near_hole, iterations=int(math.ceil(hole_margin_px)))
    mask = ~near_hole & (roi < float(det.saturation_dn))
    uv0 = plane_to_uv(H, np.asarray(start_mm, float))
    f = fit_spot_model(roi, model, NoiseModel.from_detector(det), *uv0, mask=mask, effects=model.effects)
    out["chi2_dof"] = f.chi2_dof
    if not f.ok:
        out["problem"] = f"the spot model's fit failed: {f.problem}"
        return out, f
    J = model._jac(f.u, f.v)
    out["spot_mm"] = model.centre_st(f.u, f.v)
    out["sigma_mm"] = np.sqrt(np.diag(J @ f.cov[:2, :2] @ J.T))
    if f.chi2_dof > CHI2_LIMIT:
        out["problem"] = (f"the spot is not the model's (χ²/dof = {f.chi2_dof:.2f} > {CHI2_LIMIT:g}): an effect the model "
                          "leaves out (screen grain, room light, a ghost)")
    return out, f
