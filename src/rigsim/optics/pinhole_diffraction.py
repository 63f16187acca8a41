"""The sun sensor's pinhole diffracts: its point-spread function on the detector.

A point of the sun at field angle θ lights the pinhole with a plane wave. Seen along the chief ray
the opening is the pinhole projected (an ellipse, D·cos θ along the field direction, D across)
or, in a thick mask, the projected overlap of its entrance and exit circles. Its field is
propagated over L = f / cos θ to the plane across the chief ray, by Fresnel (the aperture times
exp(iπρ²/λL), Fourier transformed) or, for comparison, by Fraunhofer (no chirp), and mapped onto
the detector (stretched by 1/cos θ along the field direction). The intensity, band-weighted over
the sun simulator's spectrum times the detector's response, is the PSF; convolved with the
geometric image through a point pinhole (the ideal frame) it is the image through the real
pinhole. docs/effects-sun.md gives the model, its accuracy and the values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["DEFAULT_BAND_NM", "PinholePSF", "band_weights", "silicon_qe"]

DEFAULT_BAND_NM = (450.0, 550.0, 650.0, 750.0, 850.0)
"""Wavelengths (nm) at which the PSF is summed (chosen: the silicon detector's band in 100 nm steps)."""

_QE_NM = np.array([400.0, 450.0, 500.0, 550.0, 600.0, 650.0, 700.0, 750.0, 800.0, 850.0, 900.0, 950.0, 1000.0])
_QE = np.array([0.30, 0.42, 0.52, 0.58, 0.60, 0.58, 0.52, 0.45, 0.37, 0.28, 0.19, 0.11, 0.04])
"""(chosen) A generic front-illuminated silicon CMOS quantum efficiency (peak 0.6 near 600 nm, the
shape of typical datasheet curves); docs/effects-sun.md."""

_HC_OVER_K_NM_K = 1.438777e7  # h c / k_B in nm·K (CODATA 2018)


def silicon_qe(wavelength_nm) -> np.ndarray:
    """The chosen silicon quantum efficiency at ``wavelength_nm`` (linear between the table's points)."""
    return np.interp(np.asarray(wavelength_nm, dtype=np.float64), _QE_NM, _QE)


def band_weights(wavelengths_nm, temperature_k: float = 5800.0) -> np.ndarray:
    """Relative detected photons at each wavelength: a blackbody's photon spectral radiance
    (∝ λ⁻⁴ / (exp(hc/λkT) − 1)) times :func:`silicon_qe`; normalised to sum 1."""
    lam = np.asarray(wavelengths_nm, dtype=np.float64).reshape(-1)
    w = lam**-4 / np.expm1(_HC_OVER_K_NM_K / (lam * temperature_k)) * silicon_qe(lam)
    return w / w.sum()


@dataclass(frozen=True)
class PinholePSF:
    """The diffraction PSF of a pinhole of ``diameter_mm`` in a mask ``thickness_mm`` thick, its
    detector ``focal_length_mm`` away; summed over ``wavelengths_nm`` with ``weights``.
    ``propagation``: "fresnel" (the default of the rig) or "fraunhofer"; ``samples``: aperture
    cells across its diameter."""

    diameter_mm: float
    thickness_mm: float
    focal_length_mm: float
    wavelengths_nm: tuple = DEFAULT_BAND_NM
    weights: tuple | None = None
    propagation: str = "fresnel"
    samples: int = 48

    def __post_init__(self):
        if self.propagation not in ("fresnel", "fraunhofer"):
            raise ValueError(f"propagation = {self.propagation!r}: must be 'fresnel' or 'fraunhofer'")
        if self.weights is None:
            object.__setattr__(self, "weights", tuple(band_weights(self.wavelengths_nm).tolist()))
        if len(self.weights) != len(self.wavelengths_nm):
            raise ValueError("weights: one per wavelength")

    def fresnel_number(self, wavelength_nm: float = 550.0) -> float:
        """N = (D/2)² / (λ f) on axis."""
        return (self.diameter_mm / 2.0) ** 2 / (wavelength_nm * 1e-6 * self.focal_length_mm)

    def aperture(self, theta: float, samples: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """The opening seen along the chief ray at field angle ``theta``: cell centres (p along the
        field direction, q across; mm, in the plane across the chief ray), each cell's open fraction
        (4×4 sub-samples), and the cell area (mm²). The overlap of the entrance and exit circles is
        centred on the chief ray (the mask's mid-plane is the pinhole of the camera model)."""
        R = self.diameter_mm / 2.0
        d = self.thickness_mm * math.tan(theta)
        if d >= 2.0 * R:
            raise ValueError(f"the mask ({self.thickness_mm} mm) closes the pinhole at {math.degrees(theta):.2f}°")
        hp = R - d / 2.0  # the overlap's half width along the field direction (mask plane)
        n = int(self.samples if samples is None else samples)
        dp, dq = 2.0 * hp / n, 2.0 * R / n
        sub = (np.arange(4) + 0.5) / 4.0 - 0.5
        c = (np.arange(n) + 0.5) - n / 2.0
        P = (c[:, None] + sub[None, :]).reshape(-1) * dp  # sub-sample positions
        Q = (c[:, None] + sub[None, :]).reshape(-1) * dq
        inside = ((P[:, None] + d / 2) ** 2 + Q[None, :] ** 2 <= R * R) & ((P[:, None] - d / 2) ** 2 + Q[None, :] ** 2 <= R * R)
        frac = inside.reshape(n, 4, n, 4).mean(axis=(1, 3))
        pc, qc = np.meshgrid(c * dp, c * dq, indexing="ij")
        keep = frac > 0
        cos = math.cos(theta)
        return pc[keep] * cos, qc[keep], frac[keep], dp * cos * dq

    def kernel(self, sun_dir_cam, fx: float, fy: float, half_px: float, step_px: float = 1.0) -> np.ndarray:
        """The PSF on the detector at pixel offsets (du, dv) = step·(i, j), |i|, |j| ≤ half/step, from
        the chief ray's point, times the sample's area (step² px²): ``K[j, i]`` (rows along v). It
        sums to 1 over the whole plane (Parseval, to the aperture's sampling); less over this window."""
        s = np.asarray(sun_dir_cam, dtype=np.float64).reshape(3)
        s = s / np.linalg.norm(s)
        theta = math.acos(min(1.0, s[2]))
        rho = math.hypot(s[0], s[1])
        ex, ey = (s[0] / rho, s[1] / rho) if rho > 1e-12 else (1.0, 0.0)
        cos = math.cos(theta)
        f = self.focal_length_mm
        L = f / cos
        # the sampled opening's pattern repeats every λL/cell: at least 4× the half width (no alias)
        cell = min(self.wavelengths_nm) * 1e-6 * L / (4.0 * half_px * max(f / fx, f / fy))
        p, q, a, dA = self.aperture(theta, max(int(self.samples), math.ceil(self.diameter_mm / cell)))
        m = round(half_px / step_px)
        off = np.arange(-m, m + 1) * step_px
        # detector offset (a, b) mm → plane across the chief ray: (ξ cos θ, η), ξ along ê, η across
        cu = (p * cos * ex - q * ey) * (f / fx)  # phase = du·cu + dv·cv (per λL)
        cv = (p * cos * ey + q * ex) * (f / fy)
        area = (f / fx) * (f / fy) * step_px**2  # mm² of one sample on the detector
        out = np.zeros((2 * m + 1, 2 * m + 1))
        for lam_nm, w in zip(self.wavelengths_nm, self.weights):
            lam = lam_nm * 1e-6
            amp = a.astype(np.complex128)
            if self.propagation == "fresnel":
                amp = amp * np.exp(1j * math.pi * (p * p + q * q) / (lam * L))
            k = -2j * math.pi / (lam * L)
            Eu = np.exp(k * cu[:, None] * off[None, :])  # (J, M)
            Ev = np.exp(k * cv[:, None] * off[None, :])
            U = (Ev * amp[:, None]).T @ Eu * dA  # (v, u)
            # intensity per mm² across the chief ray over the energy through the opening (its open
            # area: Parseval); on the detector × cos θ
            out += w * (np.abs(U) ** 2) / (lam * L) ** 2 / (np.sum(a) * dA) * cos * area
        return out

    def as_dict(self) -> dict:
        return {"diameter_mm": self.diameter_mm, "thickness_mm": self.thickness_mm,
                "focal_length_mm": self.focal_length_mm, "wavelengths_nm": list(self.wavelengths_nm),
                "weights": list(self.weights), "propagation": self.propagation, "samples": self.samples}


def kernel_moments(K: np.ndarray, step_px: float = 1.0) -> dict:
    """Sum, centroid (px) and covariance (px²) of a kernel of :meth:`PinholePSF.kernel`."""
    m = (K.shape[0] - 1) // 2
    off = np.arange(-m, m + 1) * step_px
    tot = K.sum()
    cu = (K.sum(axis=0) @ off) / tot
    cv = (K.sum(axis=1) @ off) / tot
    U, V = np.meshgrid(off - cu, off - cv)
    cov = np.array([[np.sum(K * U * U), np.sum(K * U * V)], [np.sum(K * U * V), np.sum(K * V * V)]]) / tot
    return {"sum": float(tot), "centroid_px": [float(cu), float(cv)], "cov_px2": cov.tolist(),
            "rms_radius_px": float(math.sqrt(np.trace(cov)))}
