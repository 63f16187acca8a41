"""Star-field frames: truth → expected photons (analytic or Mitsuba) → detector DN.

Rendering only: nothing here extracts, identifies or estimates. A :class:`StarFrame` carries
the 16-bit frame and the truth it was rendered from (which the estimators never read).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rigsim.detector import apply_detector
from rigsim.star.analytic import render_stars
from rigsim.star.field import StarField, StarSky

__all__ = ["StarFrame", "render_frame", "render_sequence", "frame_seed"]


@dataclass
class StarFrame:
    index: int
    time_s: float
    dn: np.ndarray                 # uint16 (H, W), img[v, u]
    truth: StarField
    seed: int
    renderer: str
    detector_meta: dict
    saturated: np.ndarray
    photons: np.ndarray | None = None
    settings: dict = field(default_factory=dict)


def frame_seed(seed: int, k: int) -> int:
    """Detector-noise seed of frame k of a run with ``seed`` (independent streams per frame)."""
    return int(np.random.SeedSequence([int(seed), 0x57A4, int(k)]).generate_state(1, np.uint32)[0])


def render_frame(sky: StarSky, R_cam_from_icrs, *, seed: int, index: int = 0, time_s: float = 0.0,
                 omega_cam_rad_s=None, substeps: int = 1, renderer: str = "analytic",
                 noiseless: bool = False, keep_photons: bool = False, mitsuba=None) -> StarFrame:
    """One frame. ``renderer``: 'analytic' (default) or 'mitsuba' (pass a
    :class:`rigsim.star.render_mitsuba.MitsubaStarRenderer` as ``mitsuba``)."""
    s = sky.rig.sensor
    sigma = s.psf_sigma_px
    margin = -math.ceil(5.0 * sigma)  # stars just off the detector still put their wings on it
    truth = sky.field(R_cam_from_icrs, omega_cam_rad_s=omega_cam_rad_s, substeps=substeps, margin_px=margin)
    if renderer == "analytic":
        photons = render_stars(truth.uv_substeps, truth.photons, truth.shape_hw, sigma,
                               background=truth.background_photons_per_px)
        settings = {"renderer": "analytic", "psf": "pixel-integrated gaussian", "sigma_px": sigma,
                    "substeps": int(substeps)}
    elif renderer == "mitsuba":
        if mitsuba is None:
            raise ValueError("renderer='mitsuba' needs a MitsubaStarRenderer (mitsuba=...)")
        photons = mitsuba.render(truth, seed=seed)
        settings = {"renderer": "mitsuba", **mitsuba.settings()}
    else:
        raise ValueError(f"renderer = {renderer!r}: allowed 'analytic' or 'mitsuba'")
    det = apply_detector(photons, s.detector, seed=seed, noiseless=noiseless)
    return StarFrame(index=int(index), time_s=float(time_s), dn=det.dn, truth=truth, seed=int(seed),
                     renderer=renderer, detector_meta=det.meta, saturated=det.saturated,
                     photons=photons if keep_photons else None, settings=settings)


def render_sequence(sky: StarSky, seq, *, seed: int, renderer: str = "analytic", noiseless: bool = False,
                    keep_photons: bool = False, mitsuba=None, substeps: int | None = None, progress=None):
    """Render every frame of an :class:`rigsim.star.attitude.AttitudeSequence` (a generator)."""
    K = sky.rig.sequence.smear_substeps if substeps is None else int(substeps)
    for k in range(len(seq)):
        fr = render_frame(sky, seq.R_cam_from_icrs[k], seed=frame_seed(seed, k), index=k,
                          time_s=float(seq.times_s[k]), omega_cam_rad_s=seq.omega_cam_rad_s[k], substeps=K,
                          renderer=renderer, noiseless=noiseless, keep_photons=keep_photons, mitsuba=mitsuba)
        if progress is not None:
            progress.update(1)
        yield fr
