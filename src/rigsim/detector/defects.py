"""Radiation effects on a detector: hot pixels (fixed, per sensor) and cosmic-ray hits (per frame).

Both are charge that the optics never delivered, so they are modelled in electrons and added to
the signal after the photon shot noise (``apply_detector(..., added_e=...)``):

* **hot pixels** — displacement-damage defects with a dark current far above the mean. Which
  pixels are hot, and each one's dark current, is a property of the sensor: a counter-based hash
  of (``sensor_seed``, pixel index) decides it, so a crop window sees exactly the hot pixels of
  the full frame. Per frame a hot pixel adds Poisson(rate × exposure) electrons.
* **cosmic-ray hits** — charged particles crossing the depleted silicon. Hits per frame are
  Poisson(flux × area × exposure); each enters at a uniform point with an isotropic direction
  (cos θ = √U, the flux through a plane), leaves a straight track whose projection on the
  detector is ``depth · tan θ`` long, and deposits ``charge per µm × depth / cos θ`` electrons
  times a Landau fluctuation (Moyal approximation), spread evenly along the track.

docs/effects.md gives the default values and their sources.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rigsim.detector.pattern import _GOLDEN, _mix64, _seed_key

__all__ = ["CosmicRayHits", "deposit_cosmic_rays", "draw_cosmic_rays", "hot_pixel_electrons", "hot_pixel_rates"]

_HOT_STREAM = 0x4807_5EED  # separates the hot-pixel draw from the PRNU/DSNU stream of the same seed
_U24 = np.float64(1.0 / (1 << 24))


def hot_pixel_rates(sensor_seed: int, detector_width: int, rows: tuple[int, int], cols: tuple[int, int], *,
                    fraction: float, threshold_e_per_s: float, mean_excess_e_per_s: float) -> np.ndarray:
    """Dark current (e⁻/s) added by hot pixels over the window ``rows`` × ``cols`` (half-open
    ranges) of a detector ``detector_width`` pixels wide: 0 for normal pixels; for a hot one
    (probability ``fraction``) ``threshold + Exp(mean_excess)``."""
    r0, r1 = int(rows[0]), int(rows[1])
    c0, c1 = int(cols[0]), int(cols[1])
    idx = (np.arange(r0, r1, dtype=np.uint64)[:, None] * np.uint64(detector_width)
           + np.arange(c0, c1, dtype=np.uint64)[None, :])
    key = _seed_key(int(sensor_seed) ^ (_HOT_STREAM << 20))
    with np.errstate(over="ignore"):
        h = _mix64((idx + key) * _GOLDEN)
    u_hot = (h >> np.uint64(40)).astype(np.float64) * _U24           # top 24 bits
    u_rate = ((h & np.uint64(0xFF_FFFF)).astype(np.float64) + 0.5) * _U24  # bottom 24 bits, in (0, 1)
    rate = np.zeros(idx.shape, dtype=np.float64)
    hot = u_hot < float(fraction)
    rate[hot] = float(threshold_e_per_s) - float(mean_excess_e_per_s) * np.log(u_rate[hot])
    return rate


def hot_pixel_electrons(rates_e_per_s: np.ndarray, exposure_s: float, rng: np.random.Generator | None,
                        noiseless: bool = False) -> np.ndarray:
    """Electrons from the hot pixels in one exposure: Poisson(rate·t) (its mean when ``noiseless``)."""
    mean = np.asarray(rates_e_per_s, dtype=np.float64) * float(exposure_s)
    if noiseless:
        return mean
    out = np.zeros_like(mean)
    hot = mean > 0
    out[hot] = rng.poisson(mean[hot])
    return out


@dataclass(frozen=True)
class CosmicRayHits:
    """The hits of one frame, in detector pixels (u right, v down): entry point, exit point, charge."""

    start_uv: np.ndarray   # (N, 2)
    end_uv: np.ndarray     # (N, 2)
    charge_e: np.ndarray   # (N,)

    def __len__(self) -> int:
        return int(self.charge_e.size)

    def as_dict(self) -> dict:
        return {"n": len(self), "start_uv_px": self.start_uv.round(3).tolist(),
                "end_uv_px": self.end_uv.round(3).tolist(), "charge_e": self.charge_e.round(1).tolist()}


def draw_cosmic_rays(rng: np.random.Generator, shape_hw: tuple[int, int], *, pixel_pitch_um: float,
                     exposure_s: float, flux_per_cm2_s: float, depth_um: float, charge_e_per_um: float,
                     landau_width: float) -> CosmicRayHits:
    """The cosmic-ray hits of one exposure on a detector of ``shape_hw`` (rows, cols).

    ``landau_width``: the Moyal scale relative to the most probable deposit (0 for none)."""
    H, W = int(shape_hw[0]), int(shape_hw[1])
    area_cm2 = H * W * (pixel_pitch_um * 1e-4) ** 2
    n = int(rng.poisson(float(flux_per_cm2_s) * area_cm2 * float(exposure_s)))
    start = np.column_stack([rng.uniform(-0.5, W - 0.5, n), rng.uniform(-0.5, H - 0.5, n)])
    cos_t = np.sqrt(rng.uniform(0.0, 1.0, n))
    cos_t = np.maximum(cos_t, 1e-4)  # a grazing track is cut where it would cross 10⁴ depths
    phi = rng.uniform(0.0, 2.0 * math.pi, n)
    tan_t = np.sqrt(1.0 - cos_t**2) / cos_t
    length_px = float(depth_um) * tan_t / float(pixel_pitch_um)
    end = start + length_px[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    fluct = 1.0 + float(landau_width) * _moyal(rng, n) if landau_width > 0 else np.ones(n)
    charge = float(charge_e_per_um) * float(depth_um) / cos_t * np.maximum(fluct, 0.0)
    return CosmicRayHits(start, end, charge)


def _moyal(rng: np.random.Generator, n: int) -> np.ndarray:
    """Standard Moyal variates (mode 0), by inversion: x = −2 ln(√2 · erfc⁻¹(U))."""
    from scipy.special import erfcinv

    u = rng.uniform(1e-12, 1.0, n)
    return -2.0 * np.log(math.sqrt(2.0) * erfcinv(u))


def deposit_cosmic_rays(hits: CosmicRayHits, rows: tuple[int, int], cols: tuple[int, int],
                        steps_per_px: int = 8) -> np.ndarray:
    """Electrons of ``hits`` in the window ``rows`` × ``cols`` (half-open, detector pixels): each
    track's charge spread evenly over points every 1/``steps_per_px`` px along it, each point
    into the pixel that holds it."""
    r0, r1 = int(rows[0]), int(rows[1])
    c0, c1 = int(cols[0]), int(cols[1])
    img = np.zeros((r1 - r0, c1 - c0), dtype=np.float64)
    for a, b, q in zip(hits.start_uv, hits.end_uv, hits.charge_e):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) * steps_per_px))
        t = (np.arange(n) + 0.5) / n
        u = np.floor(a[0] + t * (b[0] - a[0]) + 0.5).astype(np.int64)
        v = np.floor(a[1] + t * (b[1] - a[1]) + 0.5).astype(np.int64)
        ok = (u >= c0) & (u < c1) & (v >= r0) & (v < r1)
        np.add.at(img, (v[ok] - r0, u[ok] - c0), float(q) / n)
    return img
