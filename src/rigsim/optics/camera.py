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
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        xd = x * radial + 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x)
        yd = y * radial + self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y
        return np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)

    def project(self, dirs: np.ndarray) -> np.ndarray:
        """Directions (…, 3) in the camera frame → pixels (…, 2). NaN where s_z ≤ 0."""
        dirs = np.asarray(dirs, dtype=float)
        z = dirs[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = dirs[..., :2] / z[..., None]
        uv = self.normalized_to_pixel(xy)
        uv[z <= 0] = np.nan
        return uv

    def pixel_to_normalized(self, uv: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Invert the distortion (fixed-point iteration, like cv2.undistortPoints)."""
        uv = np.asarray(uv, dtype=float)
        xd = np.stack([(uv[..., 0] - self.cx) / self.fx, (uv[..., 1] - self.cy) / self.fy], -1)
        xy = xd.copy()
        for _ in range(iterations):
            x, y = xy[..., 0], xy[..., 1]
            r2 = x * x + y * y
            radial = 1 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
            dx = 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x)
            dy = self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y
            xy = np.stack([(xd[..., 0] - dx) / radial, (xd[..., 1] - dy) / radial], -1)
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
