"""The star sensor's lens as a prescription, traced exactly: spherical surfaces, Schott glasses
(Sellmeier), a real ray trace with Snell's law in vector form, and the paraxial (ynu / ABCD)
trace it is checked against.

Conventions: the optical axis is +z, light travels towards +z, the first vertex is at z = 0.
A surface is its curvature ``c`` (1/mm, + when the centre of curvature lies after the vertex),
the thickness ``t`` (mm) to the next vertex and the medium after it (a glass name or ``"air"``).
The design, its source and the numbers it gives are in docs/effects-star.md ("Traced PSF").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GLASSES", "STAR_LENS", "STAR_LENS_STOP", "StarLens", "Surface", "abbe_number", "refractive_index"]

# Schott catalogue Sellmeier coefficients (B1..B3, C1..C3 in µm²): n² − 1 = Σ Bᵢ λ² / (λ² − Cᵢ)
GLASSES = {
    "N-SK16": ((1.34317774, 0.241144399, 0.994317969), (0.00704687339, 0.0229005, 92.7508526)),
    "F2": ((1.34533359, 0.209073176, 0.937357162), (0.00997743871, 0.0470450767, 111.886764)),
    "SK2": ((1.28189012, 0.257738258, 0.96818604), (0.0072719164, 0.0242823527, 110.377773)),
    "F5": ((1.3104463, 0.19603426, 0.96612977), (0.00958633048, 0.0457627627, 115.011883)),
}


def refractive_index(medium: str, wavelength_nm) -> np.ndarray:
    """n(λ) of a glass (Sellmeier) or of ``"air"`` (taken as 1: the sensor works in vacuum)."""
    lam = np.asarray(wavelength_nm, dtype=float)
    if medium == "air":
        return np.ones_like(lam)
    B, C = GLASSES[medium]
    l2 = (lam * 1e-3) ** 2
    return np.sqrt(1.0 + sum(b * l2 / (l2 - c) for b, c in zip(B, C)))


def abbe_number(medium: str) -> float:
    """V_d = (n_d − 1) / (n_F − n_C) at the d, F, C lines (587.6, 486.1, 656.3 nm)."""
    nd, nF, nC = refractive_index(medium, [587.5618, 486.1327, 656.2725])
    return float((nd - 1.0) / (nF - nC))


@dataclass(frozen=True)
class Surface:
    c: float          # curvature 1/R (1/mm)
    t: float          # thickness to the next vertex (mm); the last one is unused
    medium: str       # medium after the surface


# (chosen) A double-Gauss objective of six elements: SK2 | N-SK16 + F5 | stop | F5 + N-SK16 | N-SK16, two
# cemented doublets. Radius (mm, 0 = plane), thickness to the next vertex (mm), medium after. The form
# is the classical double Gauss; the radii and spacings were re-optimised with this module's trace
# for f = 43.3 mm, f/2.17 over the 20° × 20° field at 450–850 nm (least polychromatic rms spot radius,
# edge thickness ≥ 1 mm glass / 0.2 mm air): docs/effects-star.md. StarLens scales it to the rig's
# focal length (a factor 1.0000 for the default rig).
STAR_LENS = (
    (25.941, 2.388, "SK2"),
    (70.327, 0.173, "air"),
    (16.577, 6.448, "N-SK16"),
    (55.979, 1.473, "F5"),
    (10.374, 9.863, "air"),
    (0.0, 4.461, "air"),          # the aperture stop
    (-14.700, 2.993, "F5"),
    (38.059, 5.865, "N-SK16"),
    (-18.055, 0.460, "air"),
    (44.999, 2.996, "N-SK16"),
    (-68.204, 0.0, "air"),
)
STAR_LENS_STOP = 5  # index of the stop surface


class StarLens:
    """A rotationally symmetric lens: ``surfaces`` (radius mm, thickness mm, medium after) scaled so its
    paraxial focal length at ``ref_nm`` is ``focal_length_mm``; the stop (surface ``stop``) sized for an
    entrance pupil of ``epd_mm``; the detector ``defocus_mm`` from the best focus (least rms spot radius on
    axis) at ``ref_nm``, + away from the lens."""

    def __init__(self, surfaces=STAR_LENS, *, stop: int = STAR_LENS_STOP, focal_length_mm: float = 50.0,
                 epd_mm: float = 10.0, ref_nm: float = 587.5618, defocus_mm: float = 0.0):
        s0 = [Surface(0.0 if r == 0 else 1.0 / r, t, m) for r, t, m in surfaces]
        k = focal_length_mm / _efl(s0, ref_nm)
        self.surfaces = tuple(Surface(s.c / k, s.t * k, s.medium) for s in s0)
        self.stop = int(stop)
        self.ref_nm = float(ref_nm)
        self.epd_mm = float(epd_mm)
        self.z = np.concatenate([[0.0], np.cumsum([s.t for s in self.surfaces[:-1]])])  # vertex positions
        # paraxial pupil: y at the stop is linear in (y, u) at the first surface: y_stop = a·y + b·u
        a = _ynu(self.surfaces, ref_nm, 1.0, 0.0, upto=self.stop)[0]
        b = _ynu(self.surfaces, ref_nm, 0.0, 1.0, upto=self.stop)[0]
        self.entrance_pupil_z = b / a          # where the chief ray (y_stop = 0) crosses the axis, from vertex 1
        self.stop_radius_mm = abs(a) * self.epd_mm / 2.0
        self.focal_length_mm = self.efl(ref_nm)
        self.image_z = self.z[-1] + self.bfl(ref_nm)
        self.best_focus_z = self.image_z + self.best_focus_shift(ref_nm)
        self.image_z = self.best_focus_z + float(defocus_mm)   # the detector plane: defocused from best focus

    # ------------------------------------------------------------------ paraxial
    def efl(self, wavelength_nm: float) -> float:
        """Paraxial effective focal length at a wavelength (the ynu trace of a ray parallel to the axis)."""
        return _efl(self.surfaces, wavelength_nm)

    def bfl(self, wavelength_nm: float) -> float:
        """Paraxial back focal distance from the last vertex."""
        y, u = _ynu(self.surfaces, wavelength_nm, 1.0, 0.0)
        return -y / u

    def paraxial_image_height(self, tan_field: float, wavelength_nm: float) -> float:
        """Height (mm) on the detector plane of the paraxial chief ray (through the centre of the
        entrance pupil at slope ``tan_field``)."""
        u0 = float(tan_field)
        y0 = -self.entrance_pupil_z * u0          # height at vertex 1 of the ray that crosses the axis at z_ep
        y, u = _ynu(self.surfaces, wavelength_nm, y0, u0)
        return y + u * (self.image_z - self.z[-1])

    # ------------------------------------------------------------------ real rays
    def trace_rays(self, directions, pupil_xy, wavelength_nm: float):
        """Real rays from a star at ``directions`` (3,) or (M, 3) (unit, +z towards the lens), entering at
        ``pupil_xy`` (M, 2) mm on the paraxial entrance-pupil plane, traced through every surface.
        Returns the points (M, 3) on the last surface, the unit directions (M, 3) after it, and a mask
        of the rays that pass the stop and every surface (no miss, no total internal reflection)."""
        d = np.array(np.broadcast_to(np.asarray(directions, dtype=float), (len(pupil_xy), 3)))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        p = np.empty_like(d)
        p[:, :2] = np.asarray(pupil_xy, dtype=float)
        p[:, 2] = self.entrance_pupil_z
        p -= d * ((self.entrance_pupil_z + 1.0) / d[:, 2:3])   # start on z = −1 mm, before the lens
        ok = np.ones(len(p), dtype=bool)
        n1 = 1.0
        for i, s in enumerate(self.surfaces):
            n2 = float(refractive_index(s.medium, wavelength_nm))
            q = p - np.array([0.0, 0.0, self.z[i]])
            # the sphere c(x² + y² + z²) − 2z = 0 (vertex at the origin) meets q + s·d at the root of
            # c s² − 2 s B + C = 0 nearest the vertex, written so that c = 0 (a plane) needs no case
            B = d[:, 2] - s.c * np.einsum("ij,ij->i", q, d)
            C = s.c * np.einsum("ij,ij->i", q, q) - 2.0 * q[:, 2]
            disc = B * B - s.c * C
            ok &= disc >= 0
            q = q + (C / (B + np.sqrt(np.maximum(disc, 0.0))))[:, None] * d
            if i == self.stop:
                ok &= q[:, 0] ** 2 + q[:, 1] ** 2 <= self.stop_radius_mm ** 2
            nrm = np.stack([-s.c * q[:, 0], -s.c * q[:, 1], 1.0 - s.c * q[:, 2]], axis=1)  # unit normal
            mu = n1 / n2
            cos_i = np.einsum("ij,ij->i", d, nrm)
            k = 1.0 - mu * mu * (1.0 - cos_i * cos_i)
            ok &= k >= 0
            d = mu * d + (np.sqrt(np.maximum(k, 0.0)) - mu * cos_i)[:, None] * nrm   # Snell's law, vector form
            p = q + np.array([0.0, 0.0, self.z[i]])
            n1 = n2
        return p, d, ok

    def trace(self, directions, pupil_xy, wavelength_nm: float, image_z: float | None = None):
        """As :meth:`trace_rays`, returning the (M, 2) hits (mm, physical image: inverted) on the detector
        plane (or the plane ``image_z``) and the mask."""
        p, d, ok = self.trace_rays(directions, pupil_xy, wavelength_nm)
        t = ((self.image_z if image_z is None else image_z) - p[:, 2]) / d[:, 2]
        return p[:, :2] + t[:, None] * d[:, :2], ok

    def pupil_grid(self, n: int, overfill: float = 1.3) -> np.ndarray:
        """A square grid of points (mm) on the entrance-pupil plane, ``n`` across ``overfill`` × its
        diameter, inside that circle: the stop cuts the real pupil out of it (pupil aberrations and
        oblique fields included)."""
        g = (np.arange(n) + 0.5) / n * 2.0 - 1.0
        X, Y = np.meshgrid(g, g)
        m = X * X + Y * Y <= 1.0
        return np.stack([X[m], Y[m]], axis=1) * (overfill * self.epd_mm / 2.0)

    def best_focus_shift(self, wavelength_nm: float, n: int = 64) -> float:
        """Axial shift (mm) from the paraxial focus to the plane of least rms spot radius on axis (the
        rays are straight lines after the last surface: a linear least-squares problem)."""
        p, d, ok = self.trace_rays([0.0, 0.0, 1.0], self.pupil_grid(n), wavelength_nm)
        z0 = self.z[-1] + self.bfl(wavelength_nm)
        s = d[ok, :2] / d[ok, 2:3]
        h = p[ok, :2] + s * (z0 - p[ok, 2:3])
        return float(-np.sum(h * s) / np.sum(s * s))

    def chief_ray(self, directions, wavelength_nm: float) -> np.ndarray:
        """(M, 2) detector hits of the rays through the centre of the entrance pupil."""
        d = np.atleast_2d(np.asarray(directions, dtype=float))
        hits = [self.trace(di, np.zeros((1, 2)), wavelength_nm)[0][0] for di in d]
        return np.array(hits)


def _ynu(surfaces, wavelength_nm, y, u, upto=None):
    """Paraxial ray (height y, slope u in air) from vertex 1 through the surfaces (refraction at each,
    transfer to the next): returns (y, u) after the last surface (or at surface ``upto``, before it
    refracts). Refraction n'u' = nu − yφ with φ = c(n' − n); transfer y' = y + t·u."""
    n = 1.0
    for i, s in enumerate(surfaces):
        if upto is not None and i == upto:
            return y, u
        n2 = float(refractive_index(s.medium, wavelength_nm))
        u = (n * u - y * s.c * (n2 - n)) / n2
        n = n2
        if i < len(surfaces) - 1:
            y = y + s.t * u
    return y, u


def _efl(surfaces, wavelength_nm) -> float:
    return -1.0 / _ynu(surfaces, wavelength_nm, 1.0, 0.0)[1]
