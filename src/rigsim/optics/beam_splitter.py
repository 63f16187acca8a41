"""A plane-parallel glass plate beam splitter at an angle in a beam: closed forms and an exact trace.

Pure numpy (docs/effects-autocollimator.md, ``beam_splitter``: the derivations and sources).
The plate's first surface S1 has the outward unit normal ``n1``; the second surface S2 lies
``thickness`` behind it (along −n1), outward normal −n1. Reflectances are unpolarised (the mean of
s and p at each surface, as Mitsuba's monochromatic ``dielectric`` uses). A surface with a given
reflectance R at the design angle θ0 follows the Fresnel angle dependence scaled to it:
R(θ) = R·F(θ)/F(θ0), T(θ) = (1 − R)·(1 − F(θ))/(1 − F(θ0)) — exactly what a Mitsuba
``dielectric`` with ``specular_reflectance`` = R/F(θ0) and ``specular_transmittance`` =
(1 − R)/(1 − F(θ0)) renders.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "BeamSplitter",
    "PlatePlacement",
    "focus_shift_sagittal",
    "focus_shift_tangential",
    "fresnel_unpolarised",
    "ghost_ratio",
    "ghost_separation",
    "lateral_shift",
    "refracted_angle",
    "surface_weights",
    "trace_plate",
]


def fresnel_unpolarised(cos_i, n_rel: float):
    """Unpolarised Fresnel reflectance of a surface from a medium into one ``n_rel`` times denser
    (n_rel = n2/n1) at incidence cosines ``cos_i``; total internal reflection gives 1."""
    ci = np.abs(np.asarray(cos_i, float))
    s2 = (1.0 - ci * ci) / (n_rel * n_rel)
    ok = s2 < 1.0
    ct = np.sqrt(np.maximum(1.0 - s2, 0.0))
    rs = (ci - n_rel * ct) / (ci + n_rel * ct)
    rp = (n_rel * ci - ct) / (n_rel * ci + ct)
    return np.where(ok, 0.5 * (rs * rs + rp * rp), 1.0)


def refracted_angle(n: float, theta_rad: float) -> float:
    """θ' in the glass: sin θ = n sin θ'."""
    return math.asin(math.sin(theta_rad) / n)


def lateral_shift(t: float, n: float, theta_rad: float) -> float:
    """Perpendicular displacement of a ray crossing the plate at incidence θ:
    d = t·sin θ·(1 − cos θ/√(n² − sin²θ))."""
    s = math.sin(theta_rad)
    return t * s * (1.0 - math.cos(theta_rad) / math.sqrt(n * n - s * s))


def ghost_separation(t: float, n: float, theta_rad: float) -> float:
    """Perpendicular distance between a beam and its copy that made two more internal reflections
    (or between the beams reflected at S1 and at S2): 2·t·tan θ'·cos θ."""
    return 2.0 * t * math.tan(refracted_angle(n, theta_rad)) * math.cos(theta_rad)


def focus_shift_sagittal(t: float, n: float, theta_rad: float) -> float:
    """Shift of the sagittal focus of a converging beam along its axial ray: d/tan θ
    (→ t(1 − 1/n) at normal incidence)."""
    if theta_rad == 0.0:
        return t * (1.0 - 1.0 / n)
    return lateral_shift(t, n, theta_rad) / math.tan(theta_rad)


def focus_shift_tangential(t: float, n: float, theta_rad: float) -> float:
    """Shift of the tangential focus along the axial ray: dd/dθ =
    t·[cos θ − cos 2θ/√(n² − sin²θ) − sin²θ cos²θ/(n² − sin²θ)^{3/2}]."""
    s, c = math.sin(theta_rad), math.cos(theta_rad)
    q = n * n - s * s
    return t * (c - (c * c - s * s) / math.sqrt(q) - s * s * c * c / q ** 1.5)


def ghost_ratio(R1: float, R2: float) -> float:
    """Brightness of the beam splitter's ghost on the detector over the main spot's, for the fold
    (the reticle reflected by S1, the return transmitted by S1 and S2). Two ghost paths land on
    the same spot: the reticle's light reflected by S2 instead of S1 (T1·R2·T1 instead of R1) and
    the return reflected twice inside (R2·R1 more): ratio = R2·(T1²/R1 + R1), with T1 = 1 − R1
    (a lossless coat) and the reflectances at the plate's angle."""
    T1 = 1.0 - R1
    return R2 * (T1 * T1 / R1 + R1)


def surface_weights(cos_i, n: float, R0: float | None, F0: float):
    """(R(θ), T(θ)) of a surface (n: glass / air) with reflectance ``R0`` at the design angle,
    whose bare Fresnel reflectance there is ``F0``; ``R0=None``: bare glass (R = F)."""
    F = fresnel_unpolarised(cos_i, n)
    if R0 is None:
        return F, 1.0 - F
    return R0 * F / F0, (1.0 - R0) * (1.0 - F) / (1.0 - F0)


@dataclass(frozen=True)
class PlatePlacement:
    """A plate in space: S1 passes through ``point`` with outward normal ``normal`` (unit)."""

    point: np.ndarray
    normal: np.ndarray
    thickness: float
    n: float


def _plane_hit(P, d, point, normal):
    den = d @ normal
    t = ((point - P) @ normal) / den
    return P + t[:, None] * d


def _refract(d, nh, eta):
    """Snell at unit normals ``nh`` facing the incident side; eta = n_i / n_t."""
    ci = -(d @ nh)
    k = 1.0 - eta * eta * (1.0 - ci * ci)
    ok = k > 0.0
    return eta * d + (eta * ci - np.sqrt(np.maximum(k, 0.0)))[:, None] * nh[None, :], ci, ok


def trace_plate(P, d, plate: PlatePlacement, path: str = "transmit"):
    """Exact trace (Snell at two planes) of rays ``P`` + s·``d`` (unit rows) arriving at S1 from
    outside. ``path``: ``"transmit"`` (S1 in, S2 out), ``"ghost"`` (S1 in, S2 reflect, S1
    reflect, S2 out), ``"reflect_s1"`` (off S1), ``"reflect_s2"`` (S1 in, S2 reflect, S1 out).
    Returns (exit point, exit direction, incidence cosine at S1 from outside, ok)."""
    P = np.atleast_2d(np.asarray(P, float))
    d = np.atleast_2d(np.asarray(d, float))
    n1 = np.asarray(plate.normal, float)
    p1 = np.asarray(plate.point, float)
    p2 = p1 - plate.thickness * n1
    H = _plane_hit(P, d, p1, n1)
    ci = -(d @ n1)
    if path == "reflect_s1":
        return H, d + 2.0 * ci[:, None] * n1[None, :], ci, ci > 0
    g, _, ok = _refract(d, n1, 1.0 / plate.n)
    H = _plane_hit(H, g, p2, n1)
    if path in ("ghost", "reflect_s2"):
        g = g - 2.0 * (g @ n1)[:, None] * n1[None, :]   # off S2, from inside
        H = _plane_hit(H, g, p1, n1)
        if path == "reflect_s2":
            out, _, ok2 = _refract(g, -n1, plate.n)
            return H, out, ci, ok & ok2 & (ci > 0)
        g = g - 2.0 * (g @ n1)[:, None] * n1[None, :]   # off S1, from inside
        H = _plane_hit(H, g, p2, n1)
    out, _, ok2 = _refract(g, n1, plate.n)
    return H, out, ci, ok & ok2 & (ci > 0)


@dataclass(frozen=True)
class BeamSplitter:
    """The autocollimator's plate beam splitter (docs/effects-autocollimator.md): S1 (the
    reticle's side, facing the objective) crosses the axis at ``z_mm`` (A frame), tilted by
    ``tilt_deg`` about y_A (its normal (sin θ, 0, cos θ)); the reticle reaches the objective by
    reflection off S1, the return reaches the detector through S1 and S2. ``r1``/``r2``: the
    surfaces' reflectances at θ (None: bare glass)."""

    thickness_mm: float = 2.0
    n: float = 1.5168
    tilt_deg: float = 45.0
    r1: float | None = 0.5
    r2: float | None = None
    z_mm: float = -45.0

    @property
    def theta(self) -> float:
        return math.radians(self.tilt_deg)

    @property
    def normal(self) -> np.ndarray:
        return np.array([math.sin(self.theta), 0.0, math.cos(self.theta)])

    @property
    def placement(self) -> PlatePlacement:
        return PlatePlacement(np.array([0.0, 0.0, self.z_mm]), self.normal, self.thickness_mm, self.n)

    @property
    def fresnel_at_tilt(self) -> float:
        return float(fresnel_unpolarised(math.cos(self.theta), self.n))

    @property
    def R1(self) -> float:
        return self.fresnel_at_tilt if self.r1 is None else float(self.r1)

    @property
    def R2(self) -> float:
        return self.fresnel_at_tilt if self.r2 is None else float(self.r2)

    def weights(self, cos_i, surface: int):
        """(R, T) of S1 or S2 at incidence cosines ``cos_i`` (in air)."""
        return surface_weights(cos_i, self.n, self.r1 if surface == 1 else self.r2, self.fresnel_at_tilt)

    @property
    def lateral_shift_mm(self) -> float:
        return lateral_shift(self.thickness_mm, self.n, self.theta)

    @property
    def focus_shift_mm(self) -> float:
        """Axial move of the detector: midway between the sagittal and tangential foci (the
        circle of least confusion of the astigmatic focus)."""
        return 0.5 * (focus_shift_sagittal(self.thickness_mm, self.n, self.theta)
                      + focus_shift_tangential(self.thickness_mm, self.n, self.theta))

    @property
    def ghost_separation_mm(self) -> float:
        return ghost_separation(self.thickness_mm, self.n, self.theta)

    @property
    def ghost_ratio(self) -> float:
        return ghost_ratio(self.R1, self.R2)

    def as_dict(self) -> dict:
        return {"thickness_mm": self.thickness_mm, "glass_index": self.n, "tilt_deg": self.tilt_deg,
                "first_surface_reflectance": self.R1, "second_surface_reflectance": self.R2,
                "s1_on_axis_z_mm": self.z_mm, "lateral_shift_mm": self.lateral_shift_mm,
                "detector_focus_shift_mm": self.focus_shift_mm, "ghost_separation_mm": self.ghost_separation_mm,
                "ghost_ratio": self.ghost_ratio}
