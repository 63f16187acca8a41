"""A pinhole of diameter D in a mask of thickness t: the thick mask vignettes oblique light.

A ray at angle θ from the mask's normal passes the pinhole when it passes both the entrance and
the exit circle; seen along the ray the two circles are offset by c = t tan θ, so the open area
is their overlap, relative to the thin pinhole's

    V(θ) = (2/π) (acos k − k √(1 − k²)),   k = t tan θ / D   (0 for k ≥ 1).

The thin pinhole's own cos⁴ θ fall-off (projected aperture, distance and obliquity on the
detector) is already the ideal frame's flux response; V multiplies it. The aperture's size
itself (its geometric blur, D/pitch px, and Fresnel/Airy diffraction) is not modelled: the rig's
sensor images through a point.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["ThickPinhole"]


@dataclass(frozen=True)
class ThickPinhole:
    diameter_mm: float
    thickness_mm: float

    def __post_init__(self):
        if not (self.diameter_mm > 0 and self.thickness_mm >= 0):
            raise ValueError(f"pinhole {self!r}: diameter must be > 0, thickness >= 0")

    @property
    def ratio(self) -> float:
        """t / D."""
        return self.thickness_mm / self.diameter_mm

    def throughput_tan(self, tan_theta) -> np.ndarray:
        """V as a function of tan θ."""
        k = np.minimum(self.ratio * np.abs(np.asarray(tan_theta, dtype=np.float64)), 1.0)
        return (2.0 / math.pi) * (np.arccos(k) - k * np.sqrt(1.0 - k * k))

    def throughput(self, theta) -> np.ndarray:
        return self.throughput_tan(np.tan(np.asarray(theta, dtype=np.float64)))

    def direction_weight(self, d) -> np.ndarray:
        """V for directions ``d`` given as rows (3, n) (x, y, z in the camera frame)."""
        d = np.asarray(d, dtype=np.float64)
        return self.throughput_tan(np.hypot(d[0], d[1]) / d[2])

    def dlnv_dtheta(self, theta: float) -> float:
        """d ln V / dθ (closed form): −(4/π) k′ √(1 − k²) / V with k′ = (t/D) sec² θ."""
        k = self.ratio * math.tan(theta)
        if k >= 1.0:
            return float("nan")
        v = (2.0 / math.pi) * (math.acos(k) - k * math.sqrt(1.0 - k * k))
        return -(4.0 / math.pi) * self.ratio / math.cos(theta) ** 2 * math.sqrt(1.0 - k * k) / v

    def as_dict(self) -> dict:
        return asdict(self)
