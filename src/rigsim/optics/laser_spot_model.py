"""The boresight camera's laser spot as a forward model: the image of the transceiver's emitting core
(a uniform disk, or the Gaussian beam's irradiance) on the CMOS, pixel-integrated in closed form, as
a function of where the core's centre is imaged.

The laser loop (emitter in the focal plane, ideal lens, flat facet, the same lens, the focal plane)
images the core at magnification −1 whatever the facet's distance and tilt (paraxial unfolded
trace: lens f, 2D of air, lens f, f of air sends a ray (h, 0) to −h); a focal-length change Δf
changes it by O(Δf/f) (1e-6 at the rig's ±4 µm). So the spot is the core's own disk, radius
``core_radius_mm``, centred where the core's centre is imaged: exact pixel integrals, no grid.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

__all__ = ["disk_pixel_fractions", "disk_pixel_gradient", "gaussian_pixel_fractions", "LaserSpotModel"]


def _quadrant_area(a: np.ndarray, b: np.ndarray, R: float) -> np.ndarray:
    """Signed area of the disk (radius R, centre 0) within the rectangle between (0, 0) and (a, b)."""
    sa, sb = np.sign(a), np.sign(b)
    x = np.minimum(np.abs(a), R)
    y = np.minimum(np.abs(b), R)
    inside = x * x + y * y <= R * R
    xc = np.sqrt(np.maximum(R * R - y * y, 0.0))  # where the circle's height equals y
    xc = np.minimum(xc, x)

    def S(X):  # ∫_0^X sqrt(R² − t²) dt
        return 0.5 * (X * np.sqrt(np.maximum(R * R - X * X, 0.0)) + R * R * np.arcsin(np.clip(X / R, -1.0, 1.0)))

    out = np.where(inside, x * y, y * xc + S(x) - S(xc))
    return sa * sb * out


def disk_pixel_fractions(du: np.ndarray, dv: np.ndarray, radius_px: float) -> np.ndarray:
    """Fraction of a uniform disk (radius ``radius_px``) that falls in the unit pixels centred
    (du, dv) px from its centre: the exact area of the pixel ∩ disk over πR²."""
    R = float(radius_px)
    x0, x1, y0, y1 = du - 0.5, du + 0.5, dv - 0.5, dv + 0.5
    A = (_quadrant_area(x1, y1, R) - _quadrant_area(x0, y1, R) - _quadrant_area(x1, y0, R)
         + _quadrant_area(x0, y0, R))
    return A / (math.pi * R * R)


def _chord_part(x: np.ndarray, y: np.ndarray, R: float) -> np.ndarray:
    """d/dx of :func:`_quadrant_area`: the signed length of the disk's chord at abscissa x between 0 and y."""
    s = np.sqrt(np.maximum(R * R - x * x, 0.0))
    return np.sign(y) * np.minimum(np.abs(y), s)


def disk_pixel_gradient(du: np.ndarray, dv: np.ndarray, radius_px: float) -> tuple[np.ndarray, np.ndarray]:
    """d/du and d/dv (of the disk's centre) of :func:`disk_pixel_fractions`: exact, from the chords
    along the pixel's edges."""
    R = float(radius_px)
    x0, x1, y0, y1 = du - 0.5, du + 0.5, dv - 0.5, dv + 0.5
    gx = _chord_part(x1, y1, R) - _chord_part(x0, y1, R) - _chord_part(x1, y0, R) + _chord_part(x0, y0, R)
    gy = _chord_part(y1, x1, R) - _chord_part(y0, x1, R) - _chord_part(y1, x0, R) + _chord_part(y0, x0, R)
    k = 1.0 / (math.pi * R * R)
    return -gx * k, -gy * k


def gaussian_pixel_fractions(du: np.ndarray, dv: np.ndarray, radius_px: float) -> np.ndarray:
    """Fraction of a Gaussian irradiance exp(−2r²/w²) (w = ``radius_px``, σ = w/2 per axis) in the
    unit pixels centred (du, dv) px from its centre (separable: erf differences). The beam's cut at
    3w drops 1.5e-8 of it: ignored."""
    s = 0.5 * float(radius_px)
    return ((ndtr((du + 0.5) / s) - ndtr((du - 0.5) / s)) * (ndtr((dv + 0.5) / s) - ndtr((dv - 0.5) / s)))


class LaserSpotModel:
    """``model(u, v)``: the unit-flux pixel image, on the window of ``shape_hw`` pixels whose first
    pixel is at ``origin_uv``, of the core's image centred at (u, v): a uniform disk of
    ``radius_px`` (``profile="disk"``) or a Gaussian beam of 1/e² radius ``radius_px``
    (``profile="gaussian"``)."""

    def __init__(self, radius_px: float, origin_uv, shape_hw, *, profile: str = "disk"):
        if profile not in ("disk", "gaussian"):
            raise ValueError(f"profile = {profile!r}: 'disk' or 'gaussian'")
        if not (math.isfinite(radius_px) and radius_px > 0):
            raise ValueError(f"radius_px = {radius_px!r}: must be finite and > 0")
        self.radius_px = float(radius_px)
        self.profile = profile
        self.origin = np.asarray(origin_uv, dtype=float).reshape(2)
        self.shape = (int(shape_hw[0]), int(shape_hw[1]))
        v, u = np.indices(self.shape)
        self._u = u + self.origin[0]
        self._v = v + self.origin[1]
        self._f = disk_pixel_fractions if profile == "disk" else gaussian_pixel_fractions
        self.effects = ("core image: uniform disk, magnification −1, exact pixel integral",) if profile == "disk" \
            else ("core image: Gaussian beam irradiance, exact pixel integral",)

    def __call__(self, u: float, v: float) -> np.ndarray:
        return self._f(self._u - u, self._v - v, self.radius_px)

    def gradient(self, u: float, v: float):
        """(image, d/du, d/dv): exact for the disk, central differences (1e-4 px) for the Gaussian."""
        p = self(u, v)
        if self.profile == "disk":
            gu, gv = disk_pixel_gradient(self._u - u, self._v - v, self.radius_px)
            return p, gu, gv
        h = 1e-4
        return p, (self(u + h, v) - self(u - h, v)) / (2 * h), (self(u, v + h) - self(u, v - h)) / (2 * h)
