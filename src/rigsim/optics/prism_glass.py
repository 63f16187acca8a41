"""The central prism as real glass: Snell refraction, Fresnel reflection, total internal reflection.

Each facet of the prism is the mirror-coated back face of a glass element whose uncoated entrance
face (towards the camera) deviates from parallel by a residual wedge ε. The laser enters the
entrance face (refraction), is reflected by the coated back face and leaves through the entrance
face again (refraction): the *main* return. The entrance face itself reflects R ≈ 4 % (Fresnel,
uncoated): the *first ghost*; the light reflected back inside by the entrance face on the way out
makes a second pass to the mirror: the *second ghost* ((1−R)²·R). At the reference the coated face is
aligned so that the main return autocollimates (the rig's alignment); the ghosts then leave a few
times ε away from it (computed exactly here by the vector Snell trace).

All directions are unit vectors (…, 3); normals point towards the camera (air side).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "GlassFacet",
    "fresnel_unpolarised",
    "glass_facet",
    "reflect",
    "refract",
    "thin_wedge_deviation",
    "wedge_deviation_exact",
]


def reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    d = np.asarray(d, float)
    return d - 2.0 * np.sum(d * n, axis=-1, keepdims=True) * n


def refract(d: np.ndarray, n: np.ndarray, n1: float, n2: float) -> tuple[np.ndarray, np.ndarray]:
    """Snell refraction of direction ``d`` at a surface of normal ``n`` (either orientation) from
    index n1 into n2: (refracted direction, tir). ``tir`` is True where sin θ_t = (n1/n2)·sin θ_i > 1
    (total internal reflection: the refracted direction is then the reflected one)."""
    d = np.asarray(d, float)
    n = np.asarray(n, float)
    c = np.sum(d * n, axis=-1, keepdims=True)
    m = np.where(c > 0, -n, n)                      # the normal facing the incoming ray
    ci = -np.sum(d * m, axis=-1, keepdims=True)     # cos θ_i > 0
    eta = n1 / n2
    k = 1.0 - eta**2 * (1.0 - ci**2)
    tir = k[..., 0] < 0
    t = eta * d + (eta * ci - np.sqrt(np.maximum(k, 0.0))) * m
    out = np.where(tir[..., None], reflect(d, m), t)
    return out, tir


def fresnel_unpolarised(cos_i, n1: float, n2: float) -> np.ndarray:
    """Reflectance of unpolarised light (mean of s and p) from index n1 onto n2 at incidence cos θ_i; 1 under TIR."""
    ci = np.abs(np.asarray(cos_i, float))
    s2 = (n1 / n2) ** 2 * (1.0 - ci**2)
    ct = np.sqrt(np.maximum(1.0 - s2, 0.0))
    rs = ((n1 * ci - n2 * ct) / (n1 * ci + n2 * ct)) ** 2
    rp = ((n1 * ct - n2 * ci) / (n1 * ct + n2 * ci)) ** 2
    return np.where(s2 >= 1.0, 1.0, 0.5 * (rs + rp))


def thin_wedge_deviation(wedge_rad: float, n: float) -> float:
    """Small-angle deviation of the double pass through a wedge of angle ε behind which a mirror
    faces the ray (normal incidence on the mirror side): 2(n−1)ε."""
    return 2.0 * (n - 1.0) * wedge_rad


def wedge_deviation_exact(incidence_rad: float, wedge_rad: float, n: float) -> float:
    """Closed form (in the plane of incidence) of the angle between the main return and the ideal
    mirror reflection: the ray meets the mirror at ``incidence_rad`` (in air, against the mirror
    normal) and the entrance face is tilted by ``wedge_rad`` against the mirror.

    Entering: θ1 = asin(sin(i − ε)/n) against the face normal, i.e. θ1 + ε against the mirror's;
    reflected: −(θ1 + ε); against the face: −(θ1 + 2ε); leaving: asin(n·sin(−θ1 − 2ε)) against the
    face, i.e. that + ε against the mirror. The ideal mirror returns −i. Angles are measured in the
    plane from the normal towards the face's tilt; the returned deviation is measured the other way
    round (as seen along the returning ray)."""
    th1 = math.asin(math.sin(incidence_rad - wedge_rad) / n)
    out = math.asin(n * math.sin(-th1 - 2.0 * wedge_rad)) + wedge_rad
    return -(out - (-incidence_rad))


class GlassFacet:
    """One facet's glass element: entrance-face normal ``front`` and coated-face normal ``mirror``
    (unit, towards the camera), entrance-face point ``front_point`` and mirror point ``mirror_point``
    (mm), index ``n``."""

    def __init__(self, front, mirror, front_point, mirror_point, n: float):
        self.front = np.asarray(front, float)
        self.mirror = np.asarray(mirror, float)
        self.front_point = np.asarray(front_point, float)
        self.mirror_point = np.asarray(mirror_point, float)
        self.n = float(n)

    def reflectance(self) -> float:
        """Fresnel reflectance of the entrance face at normal incidence, ((n−1)/(n+1))²."""
        return float(((self.n - 1.0) / (self.n + 1.0)) ** 2)

    def paths(self, p: np.ndarray, d: np.ndarray, only: str | None = None) -> dict:
        """The returns of rays (points ``p``, directions ``d``, (…, 3)) arriving from the camera:
        {"main" | "ghost1" | "ghost2": (point on the entrance face where the ray leaves, direction,
        transmitted fraction (…,))}. "tir" (…,): the main return met total internal reflection
        on leaving (it then stays in the glass: fraction 0). ``only="main"``: skip the ghosts."""
        n = self.n
        p = np.asarray(p, float)
        d = np.asarray(d, float)

        def hit(p, d, q, nn):
            t = np.sum((q - p) * nn, axis=-1, keepdims=True) / np.sum(d * nn, axis=-1, keepdims=True)
            return p + t * d

        def cos(d, nn):
            return np.sum(d * nn, axis=-1)

        p1 = hit(p, d, self.front_point, self.front)
        R1 = fresnel_unpolarised(cos(d, self.front), 1.0, n)
        g1 = (p1, reflect(d, self.front), R1)
        d1, _ = refract(d, self.front, 1.0, n)
        p2 = hit(p1, d1, self.mirror_point, self.mirror)
        d2 = reflect(d1, self.mirror)
        p3 = hit(p2, d2, self.front_point, self.front)
        R3 = fresnel_unpolarised(cos(d2, self.front), n, 1.0)
        d3, tir = refract(d2, self.front, n, 1.0)
        main = (p3, d3, np.where(tir, 0.0, (1.0 - R1) * (1.0 - R3)))
        if only == "main":
            return {"main": main, "tir": tir}
        # the light reflected back into the glass at p3: mirror again, then out
        d4 = reflect(d2, self.front)
        p4 = hit(p3, d4, self.mirror_point, self.mirror)
        d5 = reflect(d4, self.mirror)
        p5 = hit(p4, d5, self.front_point, self.front)
        R5 = fresnel_unpolarised(cos(d5, self.front), n, 1.0)
        d6, tir6 = refract(d5, self.front, n, 1.0)
        g2 = (p5, d6, np.where(tir6, 0.0, (1.0 - R1) * R3 * (1.0 - R5)))
        return {"main": main, "ghost1": g1, "ghost2": g2, "tir": tir}


def glass_facet(u_out: np.ndarray, mirror_point: np.ndarray, *, n: float, thickness_mm: float,
                wedge_rad: float, wedge_azimuth_rad: float) -> GlassFacet:
    """The glass element of a facet whose main return autocollimates the beam ``u_out`` (unit, from
    the camera): the entrance face is tilted by ``wedge_rad`` from −u_out about an axis at
    ``wedge_azimuth_rad`` in the plane normal to the beam, ``thickness_mm`` in front of the mirror
    point; the coated face is normal to the refracted beam (so the main return retraces it)."""
    u = np.asarray(u_out, float) / np.linalg.norm(u_out)
    a = np.cross(u, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(u, a)
    axis = math.cos(wedge_azimuth_rad) * a + math.sin(wedge_azimuth_rad) * b
    nf0 = -u
    # Rodrigues: rotate the face normal by ε about the axis (⟂ nf0)
    front = nf0 * math.cos(wedge_rad) + np.cross(axis, nf0) * math.sin(wedge_rad)
    d1, _ = refract(u, front, 1.0, n)
    mirror = -d1
    front_point = np.asarray(mirror_point, float) - thickness_mm * u
    return GlassFacet(front, mirror, front_point, mirror_point, n)
