"""The diaphragm screen's surface as the aiming camera sees it: a granular albedo (a Gaussian random
field fixed on the screen) and room light (an illuminance with a linear gradient), per camera pixel.

Screen coordinates (s, t) are mm from the hole (lab X', Y'); ``uv_to_screen`` maps pixels to them.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ambient_illuminance", "grain_field", "pixel_albedo", "pixel_average_factor"]

_GRAIN_STREAM = 0x5C2EE4


def _gauss_kernel_energy(sigma: float, truncate: float = 4.0) -> float:
    """Σk² of scipy's separable Gaussian filter of ``sigma`` samples (the variance it gives unit white noise)."""
    r = int(truncate * sigma + 0.5)
    x = np.arange(-r, r + 1, dtype=float)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    k /= k.sum()
    return float((k * k).sum()) ** 2


def grain_field(shape: tuple[int, int], step_mm: float, grain_um: float, contrast: float, seed: int) -> np.ndarray:
    """Relative albedo 1 + contrast·z on a grid of ``step_mm``: z is white noise filtered by a Gaussian
    of σ = ``grain_um`` and scaled to unit variance (covariance exp(−r²/4σ²)), drawn from ``seed``."""
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(np.random.SeedSequence([int(seed), _GRAIN_STREAM]))
    sig = 1e-3 * grain_um / step_mm
    z = gaussian_filter(rng.standard_normal(shape, dtype=np.float32), sig, mode="wrap")
    return 1.0 + (contrast / math.sqrt(_gauss_kernel_energy(sig))) * z


def pixel_average_factor(width_mm: float, grain_um: float) -> float:
    """Variance kept when a field of covariance exp(−x²/4σ²) is averaged over a segment of ``width_mm``:
    (2/a²)∫₀ᵃ(a − u)e^{−u²/s²}du with s = 2σ (one axis; a box pixel is the product over its two axes)."""
    a, s = float(width_mm), 2e-3 * float(grain_um)
    integral = a * s * math.sqrt(math.pi) / 2.0 * math.erf(a / s) - 0.5 * s * s * (1.0 - math.exp(-(a / s) ** 2))
    return 2.0 * integral / (a * a)


def pixel_albedo(field: np.ndarray, lo_mm, step_mm: float, uv_to_screen, width: int, height: int,
                 n: int = 4) -> np.ndarray:
    """Mean of ``field`` (grid origin ``lo_mm``, step ``step_mm``; bilinear) over an n × n grid of
    sub-samples inside every camera pixel (``uv_to_screen``: pixels (N, 2) → screen mm (N, 2))."""
    import cv2

    uu, vv = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    acc = np.zeros((height, width))
    f = np.asarray(field, np.float32)
    for a in range(n):
        for b in range(n):
            uv = np.stack([uu + (a + 0.5) / n - 0.5, vv + (b + 0.5) / n - 0.5], axis=-1).reshape(-1, 2)
            p = uv_to_screen(uv)
            mx = ((p[:, 0] - lo_mm[0]) / step_mm).astype(np.float32).reshape(height, width)
            my = ((p[:, 1] - lo_mm[1]) / step_mm).astype(np.float32).reshape(height, width)
            acc += cv2.remap(f, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    return acc / (n * n)


def ambient_illuminance(st, lux: float, gradient_per_100mm: float, direction_deg: float) -> np.ndarray:
    """Room illuminance (lux) at screen points ``st`` (..., 2): lux·(1 + g·(st·ê)/100 mm), never below 0."""
    st = np.asarray(st, float)
    a = math.radians(direction_deg)
    return np.clip(lux * (1.0 + gradient_per_100mm * (st[..., 0] * math.cos(a) + st[..., 1] * math.sin(a)) / 100.0),
                   0.0, None)
