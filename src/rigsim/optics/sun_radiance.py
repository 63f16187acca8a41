"""The radiance across the sun simulator's disk: limb darkening and a linear gradient.

A position on the disk is (r, φ): r ∈ [0, 1] the distance from the disk's centre over its radius
(r = tan ρ / tan(a/2) for a ray at angle ρ from the disk's centre, the disk seen under the full
angle a), φ the azimuth from the gradient's direction. The radiance relative to the disk's mean is

    L(r, φ) = D(r) · (1 + g r cos φ),   D(r) = (1 − u(1 − μ)) / (1 − u/3),   μ = √(1 − r²),

D the linear limb-darkening law normalised to a mean of 1 over the disk's area (the mean of μ over
a disk is 2/3), g the gradient's half-range: (max − min)/(max + min) = g on a uniform disk. Both
factors keep the disk's flux. :meth:`DiskRadiance.texture` gives the exact mean of L over the cells
of an (r, φ) grid (what a nearest-filtered texture on Mitsuba's ``disk``, uv = (r, φ/2π), draws).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["DiskRadiance"]


def _i_r(r, u):
    """∫₀ʳ (1 − u + u√(1 − x²)) x dx."""
    return (1.0 - u) * r * r / 2.0 + u * (1.0 - (1.0 - r * r) ** 1.5) / 3.0


def _i_r2(r, u):
    """∫₀ʳ (1 − u + u√(1 − x²)) x² dx."""
    s = np.sqrt(np.maximum(0.0, 1.0 - r * r))
    return (1.0 - u) * r ** 3 / 3.0 + u * (r * (2.0 * r * r - 1.0) * s + np.arcsin(np.minimum(r, 1.0))) / 8.0


@dataclass(frozen=True)
class DiskRadiance:
    """Radiance across the disk, relative to its mean: limb darkening ``u``, gradient ``g``."""

    u: float = 0.0
    g: float = 0.0

    def __post_init__(self):
        if not (0.0 <= self.u <= 1.0):
            raise ValueError(f"u = {self.u!r}: must be in [0, 1]")
        if not (0.0 <= self.g <= 1.0):
            raise ValueError(f"g = {self.g!r}: must be in [0, 1]")

    @property
    def uniform(self) -> bool:
        return self.u == 0.0 and self.g == 0.0

    def limb(self, r) -> np.ndarray:
        """D(r): the limb-darkening factor (mean 1 over the disk)."""
        r = np.asarray(r, dtype=np.float64)
        mu = np.sqrt(np.maximum(0.0, 1.0 - r * r))
        return (1.0 - self.u * (1.0 - mu)) / (1.0 - self.u / 3.0)

    def __call__(self, r, cos_az) -> np.ndarray:
        """L(r, φ) with cos φ = ``cos_az``."""
        return self.limb(r) * (1.0 + self.g * np.asarray(r) * np.asarray(cos_az))

    def texture(self, nr: int = 1024, nphi: int | None = None) -> np.ndarray:
        """(nphi, nr) exact cell means of L over r ∈ [i/nr, (i+1)/nr], φ ∈ [2πj/nphi, 2π(j+1)/nphi]
        (row j, column i). ``nphi``: 1 without a gradient, else 256."""
        nphi = (1 if self.g == 0.0 else 256) if nphi is None else int(nphi)
        r = np.linspace(0.0, 1.0, int(nr) + 1)
        norm = 1.0 - self.u / 3.0
        a = np.diff(_i_r(r, self.u)) / norm  # ∫ D r dr over each ring
        b = np.diff(_i_r2(r, self.u)) / norm  # ∫ D r² dr
        phi = np.linspace(0.0, 2.0 * math.pi, nphi + 1)
        dphi = np.diff(phi)
        dsin = np.diff(np.sin(phi))
        area = np.diff(r * r / 2.0)[None, :] * dphi[:, None]
        out = (a[None, :] * dphi[:, None] + self.g * b[None, :] * dsin[:, None]) / area
        return out


def gradient_across(beam, direction_deg: float) -> np.ndarray:
    """A simulator's gradient direction across its ``beam`` (unit, any frame): ``direction_deg`` from
    the frame's axis most nearly across the beam, towards beam × that axis."""
    d = np.asarray(beam, dtype=np.float64).reshape(3)
    d = d / np.linalg.norm(d)
    a = np.eye(3)[int(np.argmin(np.abs(d)))]
    a = a - (a @ d) * d
    a /= np.linalg.norm(a)
    t = math.radians(direction_deg)
    return math.cos(t) * a + math.sin(t) * np.cross(d, a)
