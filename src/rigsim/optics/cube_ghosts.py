"""Ghost reflections of a glass cube prism with bare faces, as an exact ray trace (numpy).

A pencil reflected by the measured face (Fresnel reflectance R) makes the spot; the part that
enters the glass, is reflected by the opposite face and leaves through the measured face makes the
first ghost, and so on (k internal reflections). Planes are given as (point, outward unit normal).
"""

from __future__ import annotations

import numpy as np

__all__ = ["fresnel_unpolarised", "ghost_ray", "normal_reflectance", "refract", "slab_reflectance"]


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def fresnel_unpolarised(cos_i: float, n1: float, n2: float) -> float:
    """Reflectance of unpolarised light at incidence cosine ``cos_i`` (> 0) from index n1 into n2
    (1 under total internal reflection)."""
    cos_i = abs(float(cos_i))
    sin_t2 = (n1 / n2) ** 2 * max(0.0, 1.0 - cos_i * cos_i)
    if sin_t2 >= 1.0:
        return 1.0
    cos_t = np.sqrt(1.0 - sin_t2)
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t)
    return float(0.5 * (rs * rs + rp * rp))


def normal_reflectance(n: float) -> float:
    """Fresnel reflectance at normal incidence, ((n − 1)/(n + 1))²."""
    return ((n - 1.0) / (n + 1.0)) ** 2


def slab_reflectance(R: float, internal_reflections: int) -> float:
    """Power reflected by a parallel slab with both faces of reflectance R, counting the direct
    reflection and ``internal_reflections`` internal ones: R + (1−R)²·R·Σ_{j<k} R^{2j}."""
    return R + (1.0 - R) ** 2 * R * sum(R ** (2 * j) for j in range(int(internal_reflections)))


def refract(d, n, eta: float) -> np.ndarray | None:
    """Direction of ``d`` refracted at a surface of unit normal ``n`` (either side), index ratio
    eta = n_from / n_to; None under total internal reflection."""
    d, n = _unit(d), _unit(n)
    c = -float(d @ n)
    if c < 0:
        n, c = -n, -c
    k = 1.0 - eta * eta * (1.0 - c * c)
    if k < 0:
        return None
    return _unit(eta * d + (eta * c - np.sqrt(k)) * n)


def _hit(o, d, p0, n):
    s = float((np.asarray(p0, float) - o) @ n) / float(d @ n)
    return o + s * d


def ghost_ray(origin, direction, front: tuple, back: tuple, n_glass: float, order: int = 1):
    """The ``order``-th ghost of the ray (origin, direction) on a glass block bounded by the planes
    ``front`` (the face the ray meets) and ``back``; order 0 is the direct reflection.
    Returns (exit point on the front face, exit direction, power fraction of the incident ray)."""
    o, d = np.asarray(origin, float), _unit(direction)
    pf, nf = np.asarray(front[0], float), _unit(front[1])
    pb, nb = np.asarray(back[0], float), _unit(back[1])
    p = _hit(o, d, pf, nf)
    R0 = fresnel_unpolarised(d @ nf, 1.0, n_glass)
    if order == 0:
        return p, _unit(d - 2.0 * (d @ nf) * nf), R0
    power = 1.0 - R0
    d = refract(d, nf, 1.0 / n_glass)
    for j in range(order):
        p = _hit(p, d, pb, nb)
        power *= fresnel_unpolarised(d @ nb, n_glass, 1.0)
        d = _unit(d - 2.0 * (d @ nb) * nb)
        p = _hit(p, d, pf, nf)
        Rf = fresnel_unpolarised(d @ nf, n_glass, 1.0)
        if j < order - 1:
            power *= Rf
            d = _unit(d - 2.0 * (d @ nf) * nf)
    power *= 1.0 - Rf
    d = refract(d, nf, n_glass)
    return p, d, power
