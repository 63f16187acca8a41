"""The detector's cover glass: a plane-parallel window of thickness t and index n between the
pinhole and the detector, parallel to the detector.

A ray at angle θ from the detector's normal crosses it at θ′ (sin θ = n sin θ′). Part of it is
reflected at the inner surface, then at the outer one, and leaves the glass parallel to the
direct ray, displaced outwards (away from the pinhole's foot) by 2 t tan θ′ in the detector plane:
the ghost. Unpolarised light, each polarisation on its own (Fresnel):

    direct  = (T_s² + T_p²) / 2,          ghost = (T_s² R_s² + T_p² R_p²) / 2,

relative to no glass (T = 1 − R; an internal reflection has the external one's reflectance). An
AR coating is a reflectance R per surface for both polarisations and every angle. Higher orders
(R⁴, at 4 t tan θ′) are left out.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["CoverGlass", "fresnel_rs_rp", "glass_spots"]


def fresnel_rs_rp(theta, n: float) -> tuple[np.ndarray, np.ndarray]:
    """Reflectances (R_s, R_p) of an air/glass surface of index ``n`` at incidence ``theta`` (rad)."""
    c = np.cos(np.asarray(theta, dtype=np.float64))
    s2 = 1.0 - c * c
    ct = np.sqrt(1.0 - s2 / (n * n))
    rs = (c - n * ct) / (c + n * ct)
    rp = (n * c - ct) / (n * c + ct)
    return rs * rs, rp * rp


@dataclass(frozen=True)
class CoverGlass:
    thickness_mm: float
    refractive_index: float
    focal_length_mm: float  # pinhole to detector: what converts millimetres on the detector to pixels
    coating_reflectance: float | None = None

    def __post_init__(self):
        if not (self.thickness_mm > 0 and self.refractive_index >= 1.0 and self.focal_length_mm > 0):
            raise ValueError(f"cover glass {self!r}: thickness and focal length must be > 0, index >= 1")

    def reflectances(self, theta) -> tuple[np.ndarray, np.ndarray]:
        if self.coating_reflectance is not None:
            r = np.full_like(np.asarray(theta, dtype=np.float64), float(self.coating_reflectance))
            return r, r
        return fresnel_rs_rp(theta, self.refractive_index)

    def direct(self, theta) -> np.ndarray:
        """The direct spot's transmittance (relative to no glass)."""
        rs, rp = self.reflectances(theta)
        return ((1 - rs) ** 2 + (1 - rp) ** 2) / 2.0

    def ghost(self, theta) -> np.ndarray:
        """The ghost's share of the light (relative to no glass)."""
        rs, rp = self.reflectances(theta)
        return ((1 - rs) ** 2 * rs ** 2 + (1 - rp) ** 2 * rp ** 2) / 2.0

    def ghost_ratio(self, theta) -> np.ndarray:
        """Ghost over direct spot."""
        return self.ghost(theta) / self.direct(theta)

    def offset_mm(self, theta) -> np.ndarray:
        """The ghost's displacement in the detector plane, away from the pinhole's foot: 2 t tan θ′."""
        s = np.sin(np.asarray(theta, dtype=np.float64))
        return 2.0 * self.thickness_mm * s / np.sqrt(self.refractive_index ** 2 - s * s)

    def offset_px(self, d, fx: float, fy: float) -> np.ndarray:
        """(…, 2) pixel displacement of the ghost for camera-frame ray directions ``d`` (…, 3)."""
        d = np.asarray(d, dtype=np.float64)
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        k = 2.0 * self.thickness_mm / self.focal_length_mm / np.sqrt(self.refractive_index ** 2 - d[..., 0] ** 2 - d[..., 1] ** 2)
        return np.stack([fx * k * d[..., 0], fy * k * d[..., 1]], axis=-1)

    def as_dict(self) -> dict:
        return asdict(self)

    @property
    def normal_ghost_ratio(self) -> float:
        """Ghost over direct spot at normal incidence: R² (R = ((n − 1)/(n + 1))² bare)."""
        return float(self.ghost_ratio(0.0))

    @staticmethod
    def theta(d) -> np.ndarray:
        """Angle (rad) of camera-frame directions ``d`` from the optical axis (the detector's normal)."""
        d = np.asarray(d, dtype=np.float64)
        return np.arccos(np.clip(d[..., 2] / np.linalg.norm(d, axis=-1), -1.0, 1.0))




def glass_spots(camera, glass: CoverGlass, sun_dir, full_angle_rad: float, n: int = 200_000) -> dict:
    """The direct spot and the ghost of a uniform disk through the glass, by quadrature (``flux``
    response, the weight per solid angle cos θ of :func:`rigsim.optics.sun_disk.spot_truth`):
    each one's flux relative to the disk without glass, its centroid (u, v), and the centroid of
    both together. The ghost's points are the direct ones moved by :meth:`CoverGlass.offset_px`."""
    from rigsim.optics.sun_disk import disk_directions

    d = disk_directions(sun_dir, full_angle_rad, n)
    uv, ok = camera.project_valid(d)
    if not ok.all():
        return {"valid": False}
    th = CoverGlass.theta(d)
    w = d[:, 2]
    wd, wg = w * glass.direct(th), w * glass.ghost(th)
    g_uv = uv + glass.offset_px(d, camera.fx, camera.fy)
    direct_c = (wd[:, None] * uv).sum(0) / wd.sum()
    ghost_c = (wg[:, None] * g_uv).sum(0) / wg.sum()
    both = (direct_c * wd.sum() + ghost_c * wg.sum()) / (wd.sum() + wg.sum())
    return {"valid": True, "direct_flux": float(wd.sum() / w.sum()), "ghost_flux": float(wg.sum() / w.sum()),
            "direct_uv": direct_c.tolist(), "ghost_uv": ghost_c.tolist(), "both_uv": both.tolist(),
            "plain_uv": ((w[:, None] * uv).sum(0) / w.sum()).tolist()}
