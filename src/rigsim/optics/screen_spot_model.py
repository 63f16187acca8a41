"""The diaphragm screen's returned spot as the aiming camera sees it, as a forward model: the
collimated pencil's disk (the hole's, radius a) blurred on the screen by the sun simulator's
divergence (a uniform disk of radius R = path·tan(α/2)), less the light that falls back into the
hole, seen through the screen → pixel homography.

Each point of the hole sends a uniform cone to the cube face and back: on the screen the pencil's
disk is convolved with a uniform disk. For R > a the irradiance at distance d from the spot's
centre is the overlap of two disks (radii a and R, centres d apart) over πR²: a plateau of
(a/R)²·E₀ out to R − a, falling to zero at R + a. A Lambertian screen seen by the camera gives each
pixel the radiance at the screen point its centre sees (the profile changes over ~170 pixels:
the pixel's own integral changes it by < 1e-5). The model is normalised to a plateau of 1: the
fitted "flux" is the plateau's DN. Its reference point is the spot's centre on the screen, given
by the pixel (u, v) it projects to.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ScreenSpotModel", "disk_overlap", "disk_overlap_slope"]


def disk_overlap(d: np.ndarray, a: float, R: float) -> np.ndarray:
    """Area common to two disks of radii ``a`` and ``R`` whose centres are ``d`` apart."""
    d = np.asarray(d, float)
    lo, hi = abs(R - a), R + a
    dd = np.clip(d, lo + 1e-15, hi)
    c1 = np.clip((dd * dd + a * a - R * R) / (2 * dd * a), -1.0, 1.0)
    c2 = np.clip((dd * dd + R * R - a * a) / (2 * dd * R), -1.0, 1.0)
    k = np.sqrt(np.clip((-dd + a + R) * (dd + a - R) * (dd - a + R) * (dd + a + R), 0.0, None))
    lens = a * a * np.arccos(c1) + R * R * np.arccos(c2) - 0.5 * k
    return np.where(d <= lo, math.pi * min(a, R) ** 2, np.where(d >= hi, 0.0, lens))


def disk_overlap_slope(d: np.ndarray, a: float, R: float) -> np.ndarray:
    """d(overlap)/dd: minus the length of the common chord (zero where one disk holds the other or
    they are apart)."""
    d = np.asarray(d, float)
    lo, hi = abs(R - a), R + a
    dd = np.clip(d, lo + 1e-15, hi)
    k = np.sqrt(np.clip((-dd + a + R) * (dd + a - R) * (dd - a + R) * (dd + a + R), 0.0, None))
    return np.where((d <= lo) | (d >= hi), 0.0, -k / dd)


def _apply(H: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    return (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w, (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w


class ScreenSpotModel:
    """``model(u, v)``: the pixel image (plateau 1), on the window of ``shape_hw`` pixels whose first
    pixel is at ``origin_uv``, of the returned spot whose centre on the screen projects to (u, v).
    ``H``: screen (s, t mm) → pixel homography; ``pencil_radius_mm``: a (the hole's radius);
    ``blur_radius_mm``: R (the divergence's disk on the screen); ``hole_centre_st`` with
    ``hole_radius_mm``: the light that falls back into the hole is lost (each pixel × the fraction of
    it outside the hole, ``ss``² sub-samples on the hole's rim); None: no hole. Has ``gradient``."""

    def __init__(self, H, origin_uv, shape_hw, pencil_radius_mm: float, blur_radius_mm: float, *,
                 hole_centre_st=None, hole_radius_mm: float | None = None, ss: int = 8):
        self.H = np.asarray(H, float)
        self.Hi = np.linalg.inv(self.H)
        self.origin = np.asarray(origin_uv, float).reshape(2)
        self.shape = (int(shape_hw[0]), int(shape_hw[1]))
        self.a, self.R = float(pencil_radius_mm), float(blur_radius_mm)
        if not (self.a > 0 and self.R > 0):
            raise ValueError("pencil and blur radii must be > 0")
        v, u = np.indices(self.shape)
        self.s, self.t = _apply(self.Hi, u + self.origin[0], v + self.origin[1])
        self.keep = np.ones(self.shape)
        effects = ["pencil disk ⊗ divergence disk on the screen", "nominal screen homography"]
        if hole_centre_st is not None and hole_radius_mm is not None:
            hc = np.asarray(hole_centre_st, float)
            r = float(hole_radius_mm)
            dist = np.hypot(self.s - hc[0], self.t - hc[1])
            J = np.abs(np.linalg.det(self._jac(*_apply(self.H, hc[0:1], hc[1:2]))))
            px = 2.0 * math.sqrt(J)  # a pixel's diagonal on the screen, generous
            cov = (dist < r).astype(float)
            rim = np.abs(dist - r) < px
            if rim.any():
                off = (np.arange(ss) + 0.5) / ss - 0.5
                ou, ov = np.meshgrid(off, off)
                vv, uu = np.nonzero(rim)
                su, sv = (uu[:, None] + self.origin[0] + ou.ravel()[None, :],
                          vv[:, None] + self.origin[1] + ov.ravel()[None, :])
                ss_, tt_ = _apply(self.Hi, su, sv)
                cov[rim] = np.mean(np.hypot(ss_ - hc[0], tt_ - hc[1]) < r, axis=1)
            self.keep = 1.0 - cov
            self.hole_coverage = cov
            effects.append("light lost into the hole")
        self.effects = tuple(effects)
        self._norm = 1.0 / (math.pi * min(self.a, self.R) ** 2)

    def _jac(self, u, v, h: float = 0.5) -> np.ndarray:
        """d(s, t)/d(u, v) at the pixel (u, v) (central differences of the exact map)."""
        u, v = float(np.ravel(u)[0]), float(np.ravel(v)[0])
        s1, t1 = _apply(self.Hi, np.array([u + h, u - h, u, u]), np.array([v, v, v + h, v - h]))
        return np.array([[(s1[0] - s1[1]) / (2 * h), (s1[2] - s1[3]) / (2 * h)],
                         [(t1[0] - t1[1]) / (2 * h), (t1[2] - t1[3]) / (2 * h)]])

    def centre_st(self, u: float, v: float) -> np.ndarray:
        s, t = _apply(self.Hi, np.array([float(u)]), np.array([float(v)]))
        return np.array([s[0], t[0]])

    def __call__(self, u: float, v: float) -> np.ndarray:
        c = self.centre_st(u, v)
        d = np.hypot(self.s - c[0], self.t - c[1])
        return disk_overlap(d, self.a, self.R) * self._norm * self.keep

    def gradient(self, u: float, v: float):
        c = self.centre_st(u, v)
        ds, dt = self.s - c[0], self.t - c[1]
        d = np.hypot(ds, dt)
        p = disk_overlap(d, self.a, self.R) * self._norm * self.keep
        g = -disk_overlap_slope(d, self.a, self.R) * self._norm * self.keep / np.maximum(d, 1e-12)  # dp/dc = g·(st − c)
        gs, gt = g * ds, g * dt
        J = self._jac(u, v)
        return p, gs * J[0, 0] + gt * J[1, 0], gs * J[0, 1] + gt * J[1, 1]
