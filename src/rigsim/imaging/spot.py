"""One bright spot on a full DN frame (the autocollimator's return): background, detection, window,
thresholded centroid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rigsim.imaging import Background, Flag, NoiseModel, centroid_tcom, detect, estimate_background, extract_rois

THRESHOLD_SIGMA = 3.0
"""Thresholded centre of mass: pixels above background + 3σ count (their excess over it)."""


# ------------------------------------------------------------------------------ frame pipeline
@dataclass
class SpotMeasurement:
    """What the instrument's software makes of one DN frame (no truth)."""

    uv: np.ndarray | None  # spot centroid (px), None when unusable
    flags: int  # rigsim.imaging Flag bits of the centroid (and of its detection)
    problem: str | None  # None when ``uv`` is usable; otherwise why not
    n_detections: int
    peak_dn: float
    background_dn: float
    background_rms_dn: float
    sigma_uv: np.ndarray | None = None  # 1σ of the centroid (px), from the pixel noise

    @property
    def ok(self) -> bool:
        return self.problem is None


def measure_spot(dn: np.ndarray, detector, *, roi_px: int, threshold_sigma: float = THRESHOLD_SIGMA,
                 detect_sigma: float = 5.0) -> SpotMeasurement:
    """Find and centroid the autocollimator's return spot on a full DN frame.

    Background: sigma-clipped median and rms of the frame, the rms floored at the detector's
    read noise and quantisation √((K·R)² + 1/12) DN (a noise-free frame has rms 0). Detection:
    ``detect_sigma`` above it; the brightest peak is the spot (the diffraction cross of a square
    face or the Airy rings may be detected as separate faint sources: they are ignored). Centroid:
    thresholded centre of mass (``centroid_tcom``, background + ``threshold_sigma``·rms,
    subtract mode) over a ``roi_px`` window on the brightest pixel. ``roi_px`` (odd) must hold
    every pixel of the spot above the threshold, diffraction pattern included, or the window cuts
    it asymmetrically and biases the centroid: it depends on the instrument, so it has no default
    (an autocollimator's comes from its geometry,
    :func:`rigsim.optics.autocollimator.centroid_roi_px`). The centroid is refused
    (``problem`` set) if nothing is detected, if any pixel of the window is saturated (ADC
    maximum), or if the window leaves the detector (the spot is at the edge of the measuring
    range)."""
    if int(roi_px) != roi_px or roi_px < 3 or int(roi_px) % 2 == 0:
        raise ValueError(f"roi_px = {roi_px!r}: must be an odd integer >= 3 (a window centred on a pixel)")
    roi_px = int(roi_px)
    a = np.asarray(dn)
    if a.ndim != 2:
        raise ValueError(f"dn must be a 2-D frame, got shape {a.shape}")
    max_dn = float(detector.saturation_dn)  # frame DN (the ADC's top code, MSB-aligned when the camera does)
    floor = math.sqrt(NoiseModel.from_detector(detector).variance(0.0))
    bg = estimate_background(a, saturation=max_dn)
    level = float(bg.level) if np.isfinite(bg.level) else float(np.median(a))
    rms = max(float(bg.rms), floor) if np.isfinite(bg.rms) else floor
    peak_all = float(a.max())

    def out(uv, fl, problem, n=0, sigma=None):
        return SpotMeasurement(uv, int(fl), problem, n, peak_all, level, rms, sigma)

    det = detect(a, threshold_sigma=detect_sigma, saturation=max_dn, background=Background(level, rms, bg.flags))
    if len(det) == 0:
        if peak_all >= max_dn:
            return out(None, Flag.SATURATED | Flag.INVALID, "the frame is saturated (no measurable spot)")
        return out(None, Flag.EMPTY | Flag.INVALID, "no spot on the detector (nothing above the background)")
    i = int(np.argmax(det.peak))
    rois = extract_rois(a.astype(float), det.peak_u[i:i + 1].astype(float), det.peak_v[i:i + 1].astype(float), roi_px)
    c = centroid_tcom(rois.stack[0], threshold=level + threshold_sigma * rms, background=level,
                      saturation=max_dn, origin_uv=rois.origin_uv[0])
    fl = int(c.flags) | int(rois.flags[0]) | int(det.flags[i])
    n = len(det)
    if fl & Flag.SATURATED:
        nsat = int(np.sum(a >= max_dn))
        return out(None, fl, f"the spot is saturated ({nsat} pixels at the ADC maximum {max_dn:g} DN): "
                             "lower the source brightness", n)
    if fl & Flag.EDGE or int(rois.flags[0]) & Flag.EDGE:
        return out(None, fl, f"the spot (at u, v ≈ {det.peak_u[i]}, {det.peak_v[i]}) is at the detector's edge "
                             f"(its {roi_px} px centroid window leaves the detector): edge of the measuring range", n)
    if fl & (Flag.INVALID | Flag.EMPTY) or not np.all(np.isfinite([c.u, c.v])):
        return out(None, fl, "no usable centroid (empty or invalid spot window)", n)
    return out(np.array([c.u, c.v]), fl, None, n, np.array([c.sigma_u, c.sigma_v]))
