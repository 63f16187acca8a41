"""What the aiming camera sees of the divergent return on the diaphragm screen, as a closed form: the
collimated pencil's disk (the hole's radius r) blurred by the divergence disk (radius R), i.e. the
two disks' overlap area as a function of the distance to the spot's centre, minus the light that falls
back into the hole. The centroid of what is left is pulled away from the hole: by about (r/R)² of the
offset when R ≫ r, by up to ~90 % when R ≈ r (a short screen distance or a small divergence)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["disk_overlap_area", "visible_return_centre_mm", "hole_pull_gain"]


def disk_overlap_area(rho, a: float, b: float) -> np.ndarray:
    """Area common to two disks of radii ``a`` and ``b`` whose centres are ``rho`` apart."""
    rho = np.asarray(rho, float)
    out = np.where(rho <= abs(a - b), math.pi * min(a, b) ** 2, 0.0)
    m = (rho > abs(a - b)) & (rho < a + b)
    p = rho[m]
    ca = np.clip((p * p + a * a - b * b) / (2 * p * a), -1.0, 1.0)
    cb = np.clip((p * p + b * b - a * a) / (2 * p * b), -1.0, 1.0)
    k = np.sqrt(np.clip((-p + a + b) * (p + a - b) * (p - a + b) * (p + a + b), 0.0, None))
    out[m] = a * a * np.arccos(ca) + b * b * np.arccos(cb) - 0.5 * k
    return out


def visible_return_centre_mm(offset_mm, hole_radius_mm: float, blur_radius_mm: float, level: float = 0.1) -> np.ndarray:
    """Centroid (mm, screen plane, from the hole) of the visible return whose geometric centre is at
    ``offset_mm``, over the part above ``level`` of its peak (the concentricity measurement's threshold).
    Integrated on a grid of r/60."""
    d = np.asarray(offset_mm, float)
    r, R = float(hole_radius_mm), float(blur_radius_mm)
    h = min(r, R) / 60.0
    n = math.ceil((float(np.abs(d).max()) + r + R) / h) + 2
    x = h * np.arange(-n, n + 1)
    X, Y = np.meshgrid(x, x)
    img = disk_overlap_area(np.hypot(X - d[0], Y - d[1]), r, R) * (np.hypot(X, Y) >= r)
    w = img * (img > level * img.max())
    return np.array([(w * X).sum(), (w * Y).sum()]) / w.sum()


def hole_pull_gain(hole_radius_mm: float, blur_radius_mm: float) -> float:
    """Measured / geometric offset near the null (at an offset of r/20)."""
    d = 0.05 * float(hole_radius_mm)
    return float(visible_return_centre_mm([d, 0.0], hole_radius_mm, blur_radius_mm)[0] / d)
