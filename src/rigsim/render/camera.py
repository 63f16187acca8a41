"""Numpy camera models that mirror the Mitsuba sensors in :mod:`rigsim.render.plugins`.

Pure numpy (no mitsuba): used to place crop windows, to compute the truth written into frame
sidecars, and by tests. Conventions, fixed project-wide and identical to OpenCV:

* camera frame: x right, y down, z forward (optical axis);
* pixel (0, 0)'s centre is at (u, v) = (0.0, 0.0); +u runs right along a row (columns), +v runs
  down (rows); an image array is indexed ``img[v, u]``; pixel (i, j) covers
  ``[i-0.5, i+0.5) x [j-0.5, j+0.5)``;
* Brown distortion in OpenCV's form and coefficient order ``(k1, k2, p1, p2, k3)``::

      r2 = x^2 + y^2,  radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
      xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
      yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
      u = fx xd + cx,  v = fy yd + cy

  so ``project`` equals ``cv2.projectPoints(X, 0, 0, K, (k1, k2, p1, p2, k3))`` (tested).

The radial map r -> r * radial(r) folds back beyond the first root of
``1 + 3 k1 r2 + 5 k2 r2^2 + 7 k3 r2^3``; directions beyond that radius (``r2_max``) are outside
the model's domain and are reported invalid rather than projected to a wrong place.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from rigsim.optics.camera import brown_distort, brown_jacobian, brown_undistort, radial_r2_max

__all__ = ["PinholeCamera", "TelecentricCamera", "radial_r2_max"]


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole camera with OpenCV intrinsics and Brown distortion (pixels, OpenCV convention)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    r2_max: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("fx", "fy"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"PinholeCamera.{name} = {v!r}: must be a finite number > 0 px")
        for name in ("width", "height"):
            v = getattr(self, name)
            if int(v) != v or v < 1:
                raise ValueError(f"PinholeCamera.{name} = {v!r}: must be an integer >= 1 px")
        for name in ("cx", "cy", "k1", "k2", "k3", "p1", "p2"):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise ValueError(f"PinholeCamera.{name} = {v!r}: must be finite")
        object.__setattr__(self, "r2_max", radial_r2_max(self.k1, self.k2, self.k3))

    @classmethod
    def from_intrinsics(cls, cam) -> "PinholeCamera":
        """From any object with fx, fy, cx, cy, k1, k2, k3, p1, p2, width, height attributes,
        e.g. :class:`rigsim.optics.camera.PinholeBrown` (same convention)."""
        return cls(**{n: getattr(cam, n) for n in ("fx", "fy", "cx", "cy", "width", "height",
                                                   "k1", "k2", "k3", "p1", "p2")})

    # -- OpenCV interop ---------------------------------------------------------------------
    @property
    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        """OpenCV order (k1, k2, p1, p2, k3)."""
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])

    def as_dict(self) -> dict:
        d = asdict(self)
        d.pop("r2_max", None)
        return d

    # -- distortion ---------------------------------------------------------------------------
    def distort(self, x, y):
        """Normalised undistorted (x, y) -> distorted (xd, yd); broadcasts."""
        return brown_distort(x, y, *self.dist_coeffs)

    def distort_jacobian(self, x, y):
        """Entries (a, b, c, d) of d(xd, yd)/d(x, y) = [[a, b], [c, d]]."""
        return brown_jacobian(x, y, *self.dist_coeffs)

    def undistort(self, xd, yd, iterations: int = 20):
        """Distorted normalised -> undistorted normalised (Newton). Returns (x, y, valid)."""
        return brown_undistort(xd, yd, *self.dist_coeffs, self.r2_max, iterations)

    # -- projection ---------------------------------------------------------------------------
    def project(self, p_cam):
        """Points or directions in the camera frame (..., 3) -> pixels (..., 2) and valid mask.

        Invalid: behind the camera (z <= 0) or outside the distortion model's monotonic domain.
        Points outside the detector are still projected (see :meth:`on_detector`).
        """
        p = np.asarray(p_cam, dtype=np.float64)
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = p[..., 0] / z
            y = p[..., 1] / z
        valid = (z > 0) & (x * x + y * y < self.r2_max)
        xd, yd = self.distort(x, y)
        uv = np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)
        return uv, valid

    def backproject(self, uv):
        """Pixels (..., 2) -> unit directions in the camera frame (..., 3) and valid mask."""
        uv = np.asarray(uv, dtype=np.float64)
        xd = (uv[..., 0] - self.cx) / self.fx
        yd = (uv[..., 1] - self.cy) / self.fy
        x, y, valid = self.undistort(xd, yd)
        d = np.stack([x, y, np.ones_like(x)], axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True), valid

    def flux_weight(self, uv):
        """Relative flux per unit detector area for a uniform-radiance scene, 1 on axis.

        ``cos^4(theta) / det(d(xd,yd)/d(x,y))`` -- the importance the ``flux`` response of the
        Mitsuba sensor applies per ray (aperture normal to the optical axis).
        """
        d, valid = self.backproject(uv)
        ct = d[..., 2]
        x, y = d[..., 0] / ct, d[..., 1] / ct
        a, b, c, dd = self.distort_jacobian(x, y)
        return np.where(valid, ct ** 4 / (a * dd - b * c), 0.0)

    def on_detector(self, uv, margin: float = 0.0):
        """True where a pixel position lies on the detector area (pixel edges at -0.5, W-0.5)."""
        uv = np.asarray(uv, dtype=np.float64)
        return ((uv[..., 0] >= -0.5 + margin) & (uv[..., 0] < self.width - 0.5 - margin)
                & (uv[..., 1] >= -0.5 + margin) & (uv[..., 1] < self.height - 0.5 - margin))


@dataclass(frozen=True)
class TelecentricCamera:
    """Object-space telecentric (orthographic) camera: u = x / pixel_size_mm + cx, likewise v."""

    pixel_size_mm: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        if not (math.isfinite(self.pixel_size_mm) and self.pixel_size_mm > 0):
            raise ValueError(f"TelecentricCamera.pixel_size_mm = {self.pixel_size_mm!r}: must be "
                             "a finite number > 0 mm")
        for name in ("width", "height"):
            v = getattr(self, name)
            if int(v) != v or v < 1:
                raise ValueError(f"TelecentricCamera.{name} = {v!r}: must be an integer >= 1 px")

    def as_dict(self) -> dict:
        return asdict(self)

    def project(self, p_cam):
        p = np.asarray(p_cam, dtype=np.float64)
        uv = np.stack([p[..., 0] / self.pixel_size_mm + self.cx,
                       p[..., 1] / self.pixel_size_mm + self.cy], axis=-1)
        return uv, p[..., 2] > 0
