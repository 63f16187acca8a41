"""Single-pixel events (hot pixels, the end of a cosmic-ray track) found by their shape and repaired
before star extraction.

A star is imaged through the optics: its brightest pixel's edge neighbours carry a share of its
light fixed by the PSF (for a Gaussian of σ px centred on a pixel, the ratio centre/neighbour is
``p0/p1`` with p0 = erf(1/(2√2σ)), p1 = (erf(3/(2√2σ)) − p0)/2; off-centre it is smaller). A hot
pixel or a perpendicular particle hit puts its charge in one pixel. A pixel is a single-pixel
event when its excess over the local background (5×5 median) is above ``k_sigma`` times the
pixel noise and above ``margin`` × p0/p1 times its largest edge neighbour's excess (plus the same
noise). It is replaced by the mean of its four edge neighbours. docs/effects.md measures it.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from rigsim.imaging.result import NoiseModel

__all__ = ["psf_peak_ratio", "repair_pixels", "single_pixel_events"]

_CROSS = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], np.uint8)


def psf_peak_ratio(sigma_px: float) -> float:
    """Centre / edge-neighbour signal of a pixel-integrated Gaussian PSF centred on a pixel: the
    largest ratio a star can show."""
    s = math.sqrt(2.0) * float(sigma_px)
    p0 = math.erf(0.5 / s)
    p1 = (math.erf(1.5 / s) - p0) / 2.0
    return p0 / max(p1, 1e-300)


def single_pixel_events(img, noise: NoiseModel, psf_sigma_px: float, *, k_sigma: float = 4.0,
                        margin: float = 1.5) -> np.ndarray:
    """Boolean mask of the pixels of ``img`` (DN) that hold charge no PSF of ``psf_sigma_px`` could
    put there alone (module docstring)."""
    a = np.asarray(img, dtype=np.float32)
    bg = cv2.medianBlur(a, 5)
    e = a - bg
    nb = cv2.dilate(e, _CROSS, borderType=cv2.BORDER_REPLICATE)   # the largest edge neighbour's excess
    sd = np.sqrt(noise.variance(bg.astype(np.float64))).astype(np.float32)
    ratio = np.float32(margin * psf_peak_ratio(psf_sigma_px))
    return (e > k_sigma * sd) & (e > ratio * np.maximum(nb, 0.0) + k_sigma * sd)


def repair_pixels(img, mask: np.ndarray) -> np.ndarray:
    """A copy of ``img`` with the masked pixels replaced by the mean of their four edge neighbours
    (masked neighbours excluded; a pixel with none keeps the 5×5 median), same dtype."""
    a = np.asarray(img)
    if not mask.any():
        return a.copy()
    f = a.astype(np.float32)
    good = (~mask).astype(np.float32)
    k = _CROSS.astype(np.float32)
    s = cv2.filter2D(f * good, -1, k, borderType=cv2.BORDER_REFLECT)
    n = cv2.filter2D(good, -1, k, borderType=cv2.BORDER_REFLECT)
    fill = np.where(n > 0, s / np.maximum(n, 1e-6), cv2.medianBlur(f, 5))
    out = f.copy()
    out[mask] = fill[mask]
    if np.issubdtype(a.dtype, np.integer):
        info = np.iinfo(a.dtype)
        return np.clip(np.rint(out), info.min, info.max).astype(a.dtype)
    return out.astype(a.dtype)


def sequence_fixed_pattern(frames, *, k_sigma: float = 5.0) -> np.ndarray:
    """The detector's defects (hot pixels, and any pixel with a fixed excess over its neighbours)
    from a sequence in which the scene moves: the per-pixel median over the N frames, less that
    median image's own 5×5 median (so a smooth fixed background such as stray light stays in the
    frames), kept where it exceeds ``k_sigma`` times the noise of such a median and zero elsewhere,
    so that the noise of a median of few frames is not subtracted from every pixel. That noise is
    1.2533 σ/√N, σ the frames' pixel noise (1.4826 × the MAD of their excess over their own 5×5
    median). Float32, DN. Each pixel must see sky, not a star, in more than half of the frames."""
    stack = np.stack([np.asarray(f, dtype=np.float32) for f in frames])
    n = stack.shape[0]
    if n < 3:
        raise ValueError(f"a fixed pattern from a sequence needs at least 3 frames, got {n}")
    med = np.median(stack, axis=0)
    # the excess over the median image's own 5×5 median: a defect is local, while a smooth background
    # fixed on the detector (stray light, a vignetted sky) is the extraction's background to estimate
    pattern = med - cv2.medianBlur(med, 5)
    # each frame's pixel noise, from its excess over its own 5×5 median (robust to stars and to gradients)
    sigma = float(np.median([1.4826 * np.median(np.abs(f - cv2.medianBlur(f, 5))) for f in stack]))
    sigma = max(sigma, math.sqrt(1.0 / 12.0))  # at least the quantisation of a DN frame
    pattern[np.abs(pattern) <= k_sigma * 1.2533 * sigma / math.sqrt(n)] = 0.0
    return pattern


def subtract_pattern(dn, pattern: np.ndarray | None) -> np.ndarray:
    """``dn`` less the fixed ``pattern`` (clipped at 0; float32), or ``dn`` itself when None."""
    if pattern is None:
        return dn
    if np.shape(dn) != np.shape(pattern):
        raise ValueError(f"frame {np.shape(dn)} and fixed pattern {np.shape(pattern)} differ in shape")
    return np.maximum(np.asarray(dn, dtype=np.float32) - pattern, 0.0)
