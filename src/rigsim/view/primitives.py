"""Small pyvista mesh makers (millimetres) used by the scene builders.

Polylines keep their float64 points as given (``polyline``), so a drawn beam is the analytic
trace itself; everything else is display geometry.
"""

from __future__ import annotations

import math

import numpy as np
import pyvista as pv

__all__ = ["polyline", "tube", "segments", "circle_points", "ring", "arrow", "box", "cylinder", "disk",
           "annulus", "frustum_lines", "quad", "ruled", "from_trimesh", "transform", "perp_basis", "unit"]


def unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def perp_basis(n) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors e1, e2 with (e1, e2, n) right-handed orthonormal."""
    n = unit(n)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = unit(np.cross(a, n))
    return e1, np.cross(n, e1)


def polyline(points) -> pv.PolyData:
    """One open polyline through ``points`` (n, 3), float64 kept."""
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64))
    n = len(pts)
    lines = np.concatenate([[n], np.arange(n)]).astype(np.int64)
    return pv.PolyData(pts, lines=lines)


def segments(starts, ends) -> pv.PolyData:
    """Independent line segments (float64)."""
    a = np.asarray(starts, float).reshape(-1, 3)
    b = np.asarray(ends, float).reshape(-1, 3)
    pts = np.empty((2 * len(a), 3))
    pts[0::2], pts[1::2] = a, b
    k = np.arange(len(a))
    lines = np.column_stack([np.full(len(a), 2), 2 * k, 2 * k + 1]).ravel()
    return pv.PolyData(pts, lines=lines)


def tube(points, radius: float, n_sides: int = 24) -> pv.PolyData:
    return polyline(points).tube(radius=radius, n_sides=n_sides, capping=True)


def circle_points(centre, e1, e2, radius: float, n: int = 128) -> np.ndarray:
    t = np.linspace(0.0, 2.0 * math.pi, n + 1)
    return (np.asarray(centre, float) + radius * (np.cos(t)[:, None] * np.asarray(e1, float)
                                                  + np.sin(t)[:, None] * np.asarray(e2, float)))


def ring(centre, e1, e2, radius: float, thickness: float, n: int = 160) -> pv.PolyData:
    """A torus-like ring (a tube along a circle) in the plane spanned by e1, e2."""
    return polyline(circle_points(centre, e1, e2, radius, n)).tube(radius=0.5 * thickness, n_sides=16)


def arrow(start, direction, length: float, shaft_radius: float | None = None, tip_length: float | None = None,
          tip_radius: float | None = None) -> pv.PolyData:
    """An arrow of total ``length`` mm (absolute sizes, not relative to the length)."""
    sr = 0.025 * length if shaft_radius is None else shaft_radius
    tl = 0.22 * length if tip_length is None else tip_length
    tr = 2.4 * sr if tip_radius is None else tip_radius
    return pv.Arrow(start=np.asarray(start, float), direction=unit(direction), scale=float(length),
                    tip_length=tl / length, tip_radius=tr / length, shaft_radius=sr / length,
                    tip_resolution=24, shaft_resolution=24)


def box(centre, R, size) -> pv.PolyData:
    """A box of edge lengths ``size`` (along the columns of R) centred at ``centre``."""
    b = pv.Box(bounds=(-size[0] / 2, size[0] / 2, -size[1] / 2, size[1] / 2, -size[2] / 2, size[2] / 2))
    return transform(b, R, centre)


def cylinder(p0, p1, radius: float, resolution: int = 64, capping: bool = True) -> pv.PolyData:
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    return pv.Cylinder(center=0.5 * (p0 + p1), direction=unit(d), radius=radius, height=float(np.linalg.norm(d)),
                       resolution=resolution, capping=capping).triangulate()


def disk(centre, normal, radius: float, n: int = 96) -> pv.PolyData:
    """A filled disk (triangle fan) facing ``normal``."""
    e1, e2 = perp_basis(normal)
    rim = circle_points(centre, e1, e2, radius, n)[:-1]
    pts = np.vstack([np.asarray(centre, float)[None], rim])
    k = np.arange(n)
    faces = np.column_stack([np.full(n, 3), np.zeros(n, int), 1 + k, 1 + (k + 1) % n]).ravel()
    return pv.PolyData(pts, faces=faces)


def annulus(centre, normal, r_in: float, r_out: float, n: int = 128) -> pv.PolyData:
    e1, e2 = perp_basis(normal)
    a = circle_points(centre, e1, e2, r_in, n)[:-1]
    b = circle_points(centre, e1, e2, r_out, n)[:-1]
    pts = np.vstack([a, b])
    k = np.arange(n)
    k1 = (k + 1) % n
    f1 = np.column_stack([np.full(n, 3), k, n + k, n + k1])
    f2 = np.column_stack([np.full(n, 3), k, n + k1, k1])
    return pv.PolyData(pts, faces=np.vstack([f1, f2]).ravel())


def quad(centre, e1, e2, half1: float, half2: float) -> pv.PolyData:
    c = np.asarray(centre, float)
    e1, e2 = np.asarray(e1, float), np.asarray(e2, float)
    pts = np.array([c - half1 * e1 - half2 * e2, c + half1 * e1 - half2 * e2, c + half1 * e1 + half2 * e2,
                    c - half1 * e1 + half2 * e2])
    return pv.PolyData(pts, faces=np.array([4, 0, 1, 2, 3]))


def frustum_lines(apex, corners) -> pv.PolyData:
    """Edges of a pyramid: apex → each corner, and the corner loop."""
    apex = np.asarray(apex, float)
    c = np.asarray(corners, float)
    n = len(c)
    pts = np.vstack([apex[None], c])
    lines = []
    for k in range(n):
        lines += [2, 0, 1 + k]
        lines += [2, 1 + k, 1 + (k + 1) % n]
    return pv.PolyData(pts, lines=np.array(lines))


def ruled(loop_a, loop_b) -> pv.PolyData:
    """The surface between two closed loops of the same number of points (quads)."""
    a = np.asarray(loop_a, float)
    b = np.asarray(loop_b, float)
    n = len(a)
    k = np.arange(n)
    k1 = (k + 1) % n
    faces = np.column_stack([np.full(n, 4), k, k1, n + k1, n + k]).ravel()
    return pv.PolyData(np.vstack([a, b]), faces=faces)


def from_trimesh(m) -> pv.PolyData:
    v = np.asarray(m.vertices, float)
    f = np.asarray(m.faces, np.int64)
    return pv.PolyData(v, faces=np.column_stack([np.full(len(f), 3), f]).ravel())


def transform(mesh: pv.PolyData, R, t) -> pv.PolyData:
    M = np.eye(4)
    M[:3, :3] = np.asarray(R, float)
    M[:3, 3] = np.asarray(t, float)
    return mesh.transform(M, inplace=False)
