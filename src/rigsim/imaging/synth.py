"""Synthetic spots with known truth, for tests and benchmarks.

* `pixel_fractions` / `gaussian_spots`: pixel-integrated circular Gaussian (exact, with erf).
* `disk_image`: pixel-integrated uniform disk or ellipse (diaphragm hole, reflected spot) by
  supersampling, optionally blurred by a Gaussian optical PSF.
* `add_noise`: Poisson + Gaussian read noise, optional saturation.
* `snr_gaussian` / `flux_for_snr`: the SNR definition used in rigsim's docs and benchmarks.

Pixel convention: pixel (0, 0)'s centre is at (0.0, 0.0); pixel i spans [i - 0.5, i + 0.5].
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import erf

from .result import NoiseModel

__all__ = [
    "pixel_fractions",
    "gaussian_spots",
    "gaussian_frame",
    "disk_image",
    "add_noise",
    "snr_gaussian",
    "flux_for_snr",
    "noise_equivalent_area_px",
]

_SQRT2 = math.sqrt(2.0)


def pixel_fractions(n: int, centre: np.ndarray | float, sigma_px: np.ndarray | float) -> np.ndarray:
    """Fraction of a 1-D Gaussian (mean ``centre``, sd ``sigma_px``) falling in pixels 0..n-1.

    Broadcasts: ``centre`` and ``sigma_px`` of shape S give an array of shape S + (n,).
    """
    c = np.asarray(centre, dtype=float)[..., None]
    s = np.asarray(sigma_px, dtype=float)[..., None]
    edges = np.arange(n + 1, dtype=float) - 0.5
    cdf = 0.5 * erf((edges - c) / (_SQRT2 * s))
    return np.diff(cdf, axis=-1)


def gaussian_spots(
    shape_hw: tuple[int, int],
    u: np.ndarray | float,
    v: np.ndarray | float,
    flux: np.ndarray | float,
    sigma_px: np.ndarray | float,
    background: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Expected pixel values of pixel-integrated circular Gaussian spots.

    ``u, v, flux, sigma_px, background`` broadcast to a common shape S; the result has shape
    S + (h, w). ``flux`` is the total flux over the infinite plane (not just the array).
    """
    h, w = shape_hw
    u, v, flux, sigma_px, background = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (u, v, flux, sigma_px, background))
    )
    ex = pixel_fractions(w, u, sigma_px)  # S + (w,)
    ey = pixel_fractions(h, v, sigma_px)  # S + (h,)
    return flux[..., None, None] * ey[..., :, None] * ex[..., None, :] + background[..., None, None]


def gaussian_frame(
    shape_hw: tuple[int, int],
    u: np.ndarray,
    v: np.ndarray,
    flux: np.ndarray,
    sigma_px: float,
    background: float = 0.0,
    half_width_sigma: float = 8.0,
) -> np.ndarray:
    """A frame holding several pixel-integrated Gaussian spots (expected values, no noise)."""
    h, w = shape_hw
    img = np.full((h, w), float(background))
    r = int(math.ceil(half_width_sigma * sigma_px))
    for uu, vv, ff in zip(np.atleast_1d(u), np.atleast_1d(v), np.atleast_1d(flux)):
        u0, v0 = int(round(uu)) - r, int(round(vv)) - r
        a0, b0 = max(u0, 0), max(v0, 0)
        a1, b1 = min(u0 + 2 * r + 1, w), min(v0 + 2 * r + 1, h)
        if a1 <= a0 or b1 <= b0:
            continue
        patch = gaussian_spots((b1 - b0, a1 - a0), uu - a0, vv - b0, ff, sigma_px)
        img[b0:b1, a0:a1] += patch
    return img


def disk_image(
    shape_hw: tuple[int, int],
    u: float,
    v: float,
    radius_px: float,
    inside: float = 1.0,
    outside: float = 0.0,
    *,
    semi_minor_px: float | None = None,
    angle_rad: float = 0.0,
    blur_sigma_px: float = 0.0,
    supersample: int = 16,
) -> np.ndarray:
    """Pixel-integrated uniform disk (or ellipse) centred at (u, v).

    ``radius_px`` is the radius (the semi-major axis for an ellipse, ``semi_minor_px`` the
    semi-minor axis, ``angle_rad`` the angle of the major axis from +u towards +v). The
    indicator is averaged over ``supersample``^2 points per pixel, then optionally blurred by a
    Gaussian PSF of ``blur_sigma_px`` (applied on the supersampled grid).
    """
    h, w = shape_hw
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample must be >= 1, got {supersample!r}")
    b = radius_px if semi_minor_px is None else float(semi_minor_px)
    a = float(radius_px)
    # sub-sample coordinates: pixel i covers [i - 0.5, i + 0.5)
    su = (np.arange(w * s) + 0.5) / s - 0.5
    sv = (np.arange(h * s) + 0.5) / s - 0.5
    du = su[None, :] - u
    dv = sv[:, None] - v
    ca, sa = math.cos(angle_rad), math.sin(angle_rad)
    x = du * ca + dv * sa
    y = -du * sa + dv * ca
    ind = ((x / a) ** 2 + (y / b) ** 2 <= 1.0).astype(float)
    if blur_sigma_px > 0:
        from scipy.ndimage import gaussian_filter

        ind = gaussian_filter(ind, blur_sigma_px * s, mode="constant", cval=0.0, truncate=5.0)
    frac = ind.reshape(h, s, w, s).mean(axis=(1, 3))
    return outside + (inside - outside) * frac


def add_noise(
    expected_dn: np.ndarray,
    noise: NoiseModel,
    rng: np.random.Generator,
    *,
    saturation_dn: float | None = None,
) -> np.ndarray:
    """Poisson electrons + Gaussian read noise, returned in DN (float, not quantised).

    electrons ~ Poisson((expected_dn - offset_dn) / K) + Normal(0, read_noise_e);
    DN = K * electrons + offset_dn (K = ``noise.gain_dn_per_e``; ``extra_variance_dn2`` is added
    as Gaussian noise). ``rng`` must be a numpy Generator (explicit seeding is mandatory in
    rigsim). Values above ``saturation_dn`` are clipped to it.
    """
    if not isinstance(rng, np.random.Generator):
        raise TypeError("rng must be a numpy.random.Generator, e.g. np.random.default_rng(seed)")
    k = noise.gain_dn_per_e
    lam = np.maximum(np.asarray(expected_dn, dtype=float) - noise.offset_dn, 0.0) / k
    e = rng.poisson(lam).astype(float)
    if noise.read_noise_e > 0:
        e += rng.normal(0.0, noise.read_noise_e, size=e.shape)
    dn = e * k + noise.offset_dn
    if noise.extra_variance_dn2 > 0:
        dn += rng.normal(0.0, np.sqrt(noise.extra_variance_dn2), size=dn.shape)
    if saturation_dn is not None:
        dn = np.minimum(dn, saturation_dn)
    return dn


def noise_equivalent_area_px(sigma_px: float) -> float:
    """Noise-equivalent area 4*pi*sigma^2 of a circular Gaussian PSF (px^2)."""
    return 4.0 * math.pi * sigma_px**2


def snr_gaussian(flux_e, background_e, read_noise_e, sigma_px):
    """rigsim's SNR definition for a Gaussian spot (all in electrons):

        SNR = F / sqrt(F + A_eff * (B + R^2)),   A_eff = 4 * pi * sigma^2

    F is the total flux, B the background per pixel, R the read noise per pixel; A_eff is the
    noise-equivalent area of the PSF, so this is the SNR of optimal (PSF-weighted) photometry.
    """
    a = noise_equivalent_area_px(sigma_px)
    f = np.asarray(flux_e, dtype=float)
    return f / np.sqrt(f + a * (background_e + read_noise_e**2))


def flux_for_snr(snr, background_e, read_noise_e, sigma_px):
    """Total flux (e-) that gives ``snr`` under `snr_gaussian`'s definition."""
    s2 = np.asarray(snr, dtype=float) ** 2
    k = noise_equivalent_area_px(sigma_px) * (background_e + read_noise_e**2)
    return 0.5 * (s2 + np.sqrt(s2 * s2 + 4.0 * s2 * k))
