"""Pinhole camera with Brown–Conrady distortion, in OpenCV's convention.

Camera frame: x right (+u), y down (+v), z forward (boresight). Pixel (0, 0)'s centre is
at (u, v) = (0, 0); arrays are indexed ``img[v, u]``. For a unit direction s (pointing from
the camera towards the object, e.g. towards the sun):

    x' = s_x/s_z, y' = s_y/s_z, r² = x'² + y'²
    x'' = x'(1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x'y' + p2 (r² + 2x'²)
    y'' = y'(1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2y'²) + 2 p2 x'y'
    u = fx x'' + cx,  v = fy y'' + cy

which is exactly ``cv2.projectPoints`` with distCoeffs (k1, k2, p1, p2, k3) (tested).
A real sun sensor forms an inverted image behind its pinhole; describing it by this
virtual (upright) image only fixes the sign convention of the sensor frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def brown_distort(x, y, k1, k2, p1, p2, k3):
    """Normalised undistorted (x, y) → distorted (xd, yd), OpenCV's Brown model; broadcasts."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


def brown_jacobian(x, y, k1, k2, p1, p2, k3):
    """Entries (a, b, c, d) of ∂(xd, yd)/∂(x, y) = [[a, b], [c, d]]."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dr = 2.0 * k1 + r2 * (4.0 * k2 + 6.0 * k3 * r2)  # 2·d(rad)/d(r²)
    a = rad + dr * x * x + 2.0 * p1 * y + 6.0 * p2 * x
    b = dr * x * y + 2.0 * p1 * x + 2.0 * p2 * y
    d = rad + dr * y * y + 6.0 * p1 * y + 2.0 * p2 * x
    return a, b, b, d


def brown_undistort(xd, yd, k1, k2, p1, p2, k3, r2_max=np.inf, iterations: int = 20):
    """Distorted → undistorted normalised coordinates (Newton). Returns (x, y, valid)."""
    xd = np.asarray(xd, dtype=np.float64)
    yd = np.asarray(yd, dtype=np.float64)
    c = (k1, k2, p1, p2, k3)
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        fxd, fyd = brown_distort(x, y, *c)
        ex, ey = fxd - xd, fyd - yd
        a, b, cc, d = brown_jacobian(x, y, *c)
        det = a * d - b * cc
        with np.errstate(divide="ignore", invalid="ignore"):
            x = x - (d * ex - b * ey) / det
            y = y - (-cc * ex + a * ey) / det
    fxd, fyd = brown_distort(x, y, *c)
    a, b, cc, d = brown_jacobian(x, y, *c)
    valid = (np.hypot(fxd - xd, fyd - yd) < 1e-9) & (x * x + y * y < r2_max) & (a * d - b * cc > 0)
    return x, y, valid


def radial_r2_max(k1: float, k2: float, k3: float, cap: float = 1e6) -> float:
    """Largest r² (normalised, undistorted) below which r·radial(r) is strictly increasing.

    d/dr [r(1 + k1 r² + k2 r⁴ + k3 r⁶)] = 1 + 3k1 s + 5k2 s² + 7k3 s³ with s = r²; beyond its
    first positive root the radial map folds back and a projection would land in a wrong place.
    """
    coeffs = [7.0 * k3, 5.0 * k2, 3.0 * k1, 1.0]
    while coeffs and coeffs[0] == 0.0:
        coeffs.pop(0)
    if len(coeffs) <= 1:
        return cap
    roots = np.roots(coeffs)
    pos = [r.real for r in roots if abs(r.imag) < 1e-12 * max(1.0, abs(r.real)) and r.real > 0]
    return float(min(min(pos), cap)) if pos else cap


@dataclass(frozen=True)
class PinholeBrown:
    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    width: int = 1024
    height: int = 1024

    @classmethod
    def from_params(cls, p: np.ndarray, width: int, height: int) -> "PinholeBrown":
        """From ``[fx, fy, cx, cy, k1, k2, p1, p2, k3]`` (trailing terms optional)."""
        names = ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"]
        return cls(**{n: float(v) for n, v in zip(names, p)}, width=width, height=height)

    @classmethod
    def from_sun_sensor(cls, s) -> "PinholeBrown":
        d = s.distortion
        return cls(s.fx_px, s.fy_px, *s.principal_point_px, d.k1, d.k2, d.p1, d.p2, d.k3, *s.resolution_px)

    def params(self) -> np.ndarray:
        return np.array([self.fx, self.fy, self.cx, self.cy, self.k1, self.k2, self.p1, self.p2, self.k3])

    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def dist_coeffs(self) -> np.ndarray:
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])

    def normalized_to_pixel(self, xy: np.ndarray) -> np.ndarray:
        xd, yd = brown_distort(xy[..., 0], xy[..., 1], *self.dist_coeffs())
        return np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)

    def project(self, dirs: np.ndarray) -> np.ndarray:
        """Directions (…, 3) in the camera frame → pixels (…, 2).

        NaN where s_z ≤ 0 or beyond the distortion model's monotonic domain (``radial_r2_max``),
        where the Brown polynomial folds back and the pixel would be wrong.
        """
        dirs = np.asarray(dirs, dtype=float)
        z = dirs[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = dirs[..., :2] / z[..., None]
        uv = self.normalized_to_pixel(xy)
        r2 = np.sum(xy * xy, axis=-1)
        uv[(z <= 0) | ~(r2 < radial_r2_max(self.k1, self.k2, self.k3))] = np.nan
        return uv

    def pixel_to_normalized(self, uv: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Invert the distortion (Newton); NaN where it has no valid inverse."""
        uv = np.asarray(uv, dtype=float)
        x, y, ok = brown_undistort((uv[..., 0] - self.cx) / self.fx, (uv[..., 1] - self.cy) / self.fy,
                                   *self.dist_coeffs(), radial_r2_max(self.k1, self.k2, self.k3), iterations)
        xy = np.stack([x, y], -1)
        xy[~ok] = np.nan
        return xy

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        xy = self.pixel_to_normalized(uv)
        v = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    def on_detector(self, uv: np.ndarray, margin_px: float = 0.0) -> np.ndarray:
        """True where the pixel position lies at least ``margin_px`` inside the detector."""
        u, v = uv[..., 0], uv[..., 1]
        ok = np.isfinite(u) & np.isfinite(v)
        return ok & (u >= -0.5 + margin_px) & (u <= self.width - 0.5 - margin_px) & (v >= -0.5 + margin_px) & (v <= self.height - 0.5 - margin_px)
