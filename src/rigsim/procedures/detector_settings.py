"""What the centroid stage needs to know about a camera (its detector's noise, saturation and frame
size), from a rig or from options; shared by every family's file commands."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from rigsim.errors import CliError
from rigsim.imaging import NoiseModel, estimate_background
from rigsim.imaging.frame_spots import default_threshold_dn

__all__ = ["CAMERAS", "DetectorSettings", "detector_settings", "frame_background"]

CAMERAS = {"sun-sensor": "sun_sensor", "aiming-camera": "aiming_camera", "autocollimator": "autocollimator",
           "star-sensor": "sensor"}
"""``--camera`` of a rig: the rig attribute that holds its detector (cube-mirror rigs: the first three;
star rigs: ``star-sensor``; boresight rigs: the one shared detector)."""


def frame_background(img: np.ndarray) -> tuple[float, float]:
    """The frame's background level and noise (DN): the sigma-clipped median and rms of its pixels
    (:func:`rigsim.imaging.estimate_background`; spots and lit areas are clipped away)."""
    b = estimate_background(np.asarray(img, float))
    return float(b.level), float(b.rms)


@dataclass(frozen=True)
class DetectorSettings:
    """What the centroid stage needs to know about a camera: noise model, saturation, frame size."""

    noise: NoiseModel
    saturation_dn: float | None
    shape: tuple[int, int] | None  # (rows, cols), checked against every frame; None: any size
    estimate_background: bool = False  # offset and noise from each frame (frame_background) instead of ``noise``

    def describe(self) -> str:
        n = self.noise
        sat = f"saturation {self.saturation_dn:g} DN" if self.saturation_dn is not None else "no saturation level"
        if self.estimate_background:
            return f"offset and noise measured per frame (clipped median, rms), gain {n.gain_dn_per_e:g} DN/e-, {sat}"
        return f"offset {n.offset_dn:g} DN, gain {n.gain_dn_per_e:g} DN/e-, read noise {n.read_noise_e:g} e-, {sat}"

    def mismatch(self, img: np.ndarray, threshold_dn: float | None = None) -> str | None:
        """When the frame's own background (:func:`frame_background`) does not fit the detector model, a sentence saying how (None when it fits, and always with
        ``estimate_background``): a background more than half the detection threshold above the
        offset (the threshold counts from the offset: the background itself would be detected), or
        below the offset by more than 5σ, or a spread more than 1.5× the model's at that level."""
        if self.estimate_background:
            return None
        med, sd = frame_background(img)
        n = self.noise
        thr = default_threshold_dn(n) if threshold_dn is None else float(threshold_dn)
        sd_dark = float(np.sqrt(n.variance(n.offset_dn)))
        sd_at = float(np.sqrt(n.variance(max(med, n.offset_dn))))
        said = f"background {med:.1f} DN with {sd:.2f} DN rms noise"
        if med - n.offset_dn > 0.5 * thr:
            return (f"{said}, {med - n.offset_dn:.1f} DN above the detector's offset ({n.offset_dn:g} DN); "
                    f"spots are pixels more than {thr:.3g} DN above the offset")
        if med < n.offset_dn - 5.0 * sd_dark - 1.0:
            return f"{said}, below the detector's offset ({n.offset_dn:g} DN)"
        if sd > 1.5 * sd_at + 0.5:
            return f"{said}; the detector model expects {sd_at:.2f} DN there (threshold {thr:.3g} DN)"
        return None

    def noise_for(self, img: np.ndarray) -> NoiseModel:
        """The noise model of one frame (measured on it when ``estimate_background``)."""
        if not self.estimate_background:
            return self.noise
        med, sd = frame_background(img)
        g = self.noise.gain_dn_per_e
        return replace(self.noise, read_noise_e=sd / g, offset_dn=med)


def detector_settings(rig=None, camera: str | None = None, *, offset_dn=None, gain_dn_per_e=None, read_noise_e=None,
                      saturation_dn=None) -> DetectorSettings:
    """The detector of ``rig``'s ``camera`` (one of :data:`CAMERAS`; default the rig's main camera),
    each value overridden by the keyword when given. Without a rig the keywords alone (gain 1 by
    default); with neither a rig nor an offset, each frame's offset and noise are measured on it
    (:func:`frame_background`)."""
    det, shape = None, None
    if rig is not None:
        if hasattr(rig, "cameras"):  # boresight: one detector for every ROI
            det = rig.detector
        else:
            attr = CAMERAS.get(camera or ("star-sensor" if hasattr(rig, "sensor") else "sun-sensor"))
            part = getattr(rig, attr, None) if attr else None
            if part is None or not hasattr(part, "detector"):
                have = [k for k, a in CAMERAS.items() if getattr(rig, a, None) is not None]
                raise CliError(f"--camera = {camera!r}: this rig ({rig.name}) has {', '.join(have)}")
            det = part.detector
            shape = tuple(part.resolution_px[::-1])
    base = NoiseModel.from_detector(det) if det is not None else NoiseModel(1.0, 0.0, 0.0, 1.0 / 12.0)  # in frame DN
    noise = replace(base, **{k: float(v) for k, v in (("gain_dn_per_e", gain_dn_per_e), ("read_noise_e", read_noise_e),
                                                      ("offset_dn", offset_dn)) if v is not None})
    sat = float(saturation_dn) if saturation_dn is not None else (float(det.saturation_dn) if det is not None else None)
    return DetectorSettings(noise, sat, shape, estimate_background=det is None and offset_dn is None)
