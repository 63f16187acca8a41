"""Star extraction and centroiding on a DN frame, through :mod:`rigsim.imaging` (no truth used).

Any user's frame works: pass a 2-D array and a :class:`rigsim.detector.DetectorConfig` (for the
noise model) and the PSF σ. Returns :class:`Observations`: positions in px (OpenCV convention),
per-axis 1σ from the centroider (Cramér–Rao-attaining Gaussian fit by default), flux (DN) and
flags; ``usable`` excludes INVALID, SATURATED, EDGE and BLENDED spots (their σ is not to be
trusted for calibration).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rigsim.imaging import Flag, NoiseModel, find_spots

__all__ = ["BAD_FLAGS", "Observations", "extract_stars"]

BAD_FLAGS = int(Flag.INVALID | Flag.SATURATED | Flag.EDGE | Flag.BLENDED | Flag.NAN)


@dataclass(frozen=True)
class Observations:
    uv: np.ndarray        # (M, 2) px
    sigma_uv: np.ndarray  # (M, 2) px, 1σ per axis
    flux: np.ndarray      # (M,) DN above background
    flags: np.ndarray     # (M,) rigsim.imaging.Flag bits

    def __len__(self) -> int:
        return int(self.uv.shape[0])

    @property
    def usable(self) -> np.ndarray:
        return ((self.flags & BAD_FLAGS) == 0) & np.all(np.isfinite(self.uv), axis=1) & np.all(self.sigma_uv > 0, axis=1)

    def subset(self, idx) -> Observations:
        return Observations(self.uv[idx], self.sigma_uv[idx], self.flux[idx], self.flags[idx])


def extract_stars(dn: np.ndarray, detector, sigma_px: float, *, method: str = "gauss",
                  threshold_sigma: float = 5.0, saturation: float | None = None,
                  repair_single_pixels: bool = False) -> Observations:
    """Detect and centroid every star of a frame (``find_spots`` with the detector's noise model).

    ``saturation`` defaults to the ADC's top code. For the Gaussian fit σ starts at ``sigma_px``
    and is fitted (smeared spots are slightly wider than the static PSF). ``repair_single_pixels``:
    first replace the pixels no PSF could have lit alone (hot pixels, particle hits:
    :func:`rigsim.imaging.cosmetics.single_pixel_events`) by their neighbours' mean.
    """
    noise = NoiseModel.from_detector(detector)
    if repair_single_pixels:
        from rigsim.imaging.cosmetics import repair_pixels, single_pixel_events

        dn = repair_pixels(dn, single_pixel_events(dn, noise, sigma_px))
    sat = float(2 ** detector.adc_bits - 1) if saturation is None else float(saturation)
    kw = {}
    if method == "gauss":
        kw["fit_sigma"] = True
    res, _det = find_spots(np.asarray(dn), method=method, sigma_px=float(sigma_px), noise=noise,
                           threshold_sigma=threshold_sigma, saturation=sat, **kw)
    uv = np.stack([res.u, res.v], axis=1) if len(res) else np.zeros((0, 2))
    sig = np.stack([res.sigma_u, res.sigma_v], axis=1) if len(res) else np.zeros((0, 2))
    return Observations(uv.astype(float), sig.astype(float), np.asarray(res.flux, float), np.asarray(res.flags, np.int64))
