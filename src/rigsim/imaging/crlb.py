"""Cramér–Rao lower bound (CRLB) on spot position.

Noise model (all in electrons): pixel k has expected value mu_k = F * p_k(u, v) + B and variance
V_k = mu_k + R^2 (Poisson signal and background, Gaussian read noise R). The Fisher information
is the usual Gaussian-approximation form

    I_ab = sum_k (d mu_k / d theta_a)(d mu_k / d theta_b) / V_k,

which is exact for a "shifted Poisson" pixel (d + R^2 ~ Poisson(mu + R^2)) and is what the
weighted least-squares fits in `centroid` attain. The bound on any unbiased estimator is
Cov >= I^-1. Which parameters are unknown matters: by default u, v, flux and background are
all estimated from the same ROI (that is what the rigsim Gaussian fit does), optionally also the
PSF width. ``unknowns=("u", "v")`` gives the (lower) bound for known flux and background.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy.special import erf

__all__ = ["CRLB", "crlb_gaussian", "crlb_psf", "fisher_information"]

_SQRT2 = math.sqrt(2.0)
_INV_SQRT2PI = 1.0 / math.sqrt(2.0 * math.pi)
_ALLOWED = ("u", "v", "flux", "background", "sigma")


@dataclass(frozen=True)
class CRLB:
    """Bound on the standard deviation of unbiased estimates (px for u, v)."""

    sigma_u: np.ndarray
    sigma_v: np.ndarray
    cov: np.ndarray  # (..., P, P) inverse Fisher information
    unknowns: tuple[str, ...]

    @property
    def sigma_rms(self) -> np.ndarray:
        """Per-axis RMS bound sqrt((sigma_u^2 + sigma_v^2) / 2)."""
        return np.sqrt(0.5 * (self.sigma_u**2 + self.sigma_v**2))

    def sigma(self, name: str) -> np.ndarray:
        i = self.unknowns.index(name)
        return np.sqrt(self.cov[..., i, i])


def _check_unknowns(unknowns: Sequence[str]) -> tuple[str, ...]:
    u = tuple(unknowns)
    bad = [x for x in u if x not in _ALLOWED]
    if bad or "u" not in u or "v" not in u or len(set(u)) != len(u):
        raise ValueError(f"unknowns must contain 'u' and 'v' and only names from {_ALLOWED}, got {u!r}")
    return u


def _check_noise(flux_e, background_e, read_noise_e):
    for name, val in (("flux_e", flux_e), ("background_e", background_e), ("read_noise_e", read_noise_e)):
        a = np.asarray(val, dtype=float)
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            raise ValueError(f"{name} must be finite and >= 0, got {val!r}")
    if np.any(np.asarray(flux_e) <= 0):
        raise ValueError(f"flux_e must be > 0, got {flux_e!r}")


def fisher_information(derivs: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """Fisher matrix from model derivatives ``derivs`` (..., P, K) and pixel variances (..., K)."""
    wd = derivs / variance[..., None, :]
    return np.einsum("...pk,...qk->...pq", wd, derivs)


def _pix_1d(n: int, c: np.ndarray, s: np.ndarray):
    """Pixel fractions of a 1-D Gaussian and their derivatives w.r.t. centre and sigma."""
    edges = np.arange(n + 1, dtype=float) - 0.5
    z = (edges - c[..., None]) / s[..., None]
    cdf = 0.5 * erf(z / _SQRT2)
    pdf = _INV_SQRT2PI * np.exp(-0.5 * z * z)
    e = np.diff(cdf, axis=-1)
    de_dc = -np.diff(pdf, axis=-1) / s[..., None]
    de_ds = -np.diff(pdf * z, axis=-1) / s[..., None]
    return e, de_dc, de_ds


def crlb_gaussian(
    flux_e,
    background_e,
    read_noise_e,
    sigma_px,
    *,
    du=0.0,
    dv=0.0,
    roi_px: int = 9,
    unknowns: Sequence[str] = ("u", "v", "flux", "background"),
) -> CRLB:
    """CRLB for a pixel-integrated circular Gaussian spot in a ``roi_px`` x ``roi_px`` ROI.

    The spot sits at offset (``du``, ``dv``) px from the centre of the ROI's central pixel
    (the sub-pixel phase). All arguments broadcast together. Units: electrons, px.
    """
    unknowns = _check_unknowns(unknowns)
    _check_noise(flux_e, background_e, read_noise_e)
    if roi_px < 3:
        raise ValueError(f"roi_px must be >= 3, got {roi_px!r}")
    f, b, r, s, du, dv = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (flux_e, background_e, read_noise_e, sigma_px, du, dv))
    )
    if np.any(s <= 0):
        raise ValueError(f"sigma_px must be > 0, got {sigma_px!r}")
    c = roi_px // 2
    ex, dex, sex = _pix_1d(roi_px, c + du, s)
    ey, dey, sey = _pix_1d(roi_px, c + dv, s)
    F = f[..., None, None]
    outer = ey[..., :, None] * ex[..., None, :]
    mu = F * outer + b[..., None, None]
    var = mu + (r**2)[..., None, None]
    d = {
        "u": F * ey[..., :, None] * dex[..., None, :],
        "v": F * dey[..., :, None] * ex[..., None, :],
        "flux": outer,
        "background": np.ones_like(outer),
        "sigma": F * (sey[..., :, None] * ex[..., None, :] + ey[..., :, None] * sex[..., None, :]),
    }
    k = roi_px * roi_px
    derivs = np.stack([d[n].reshape(d[n].shape[:-2] + (k,)) for n in unknowns], axis=-2)
    fisher = fisher_information(derivs, var.reshape(var.shape[:-2] + (k,)))
    cov = np.linalg.inv(fisher)
    iu, iv = unknowns.index("u"), unknowns.index("v")
    return CRLB(np.sqrt(cov[..., iu, iu]), np.sqrt(cov[..., iv, iv]), cov, unknowns)


def crlb_psf(
    psf: Callable[[tuple[int, int], float, float], np.ndarray],
    flux_e: float,
    background_e: float,
    read_noise_e: float,
    u: float,
    v: float,
    shape_hw: tuple[int, int],
    *,
    unknowns: Sequence[str] = ("u", "v", "flux", "background"),
    step_px: float = 1e-4,
) -> CRLB:
    """CRLB for any PSF given as ``psf(shape_hw, u, v) -> (h, w)`` pixel-integrated fractions.

    Position derivatives are taken by central differences (step ``step_px``). ``sigma`` is not
    available as an unknown here (the PSF is a black box).
    """
    unknowns = _check_unknowns(unknowns)
    if "sigma" in unknowns:
        raise ValueError("crlb_psf cannot treat 'sigma' as unknown; use crlb_gaussian")
    _check_noise(flux_e, background_e, read_noise_e)
    p = np.asarray(psf(shape_hw, u, v), dtype=float)
    if p.shape != tuple(shape_hw) or not np.all(np.isfinite(p)):
        raise ValueError(f"psf must return a finite array of shape {tuple(shape_hw)}, got {p.shape}")
    h = step_px
    d = {
        "u": flux_e * (psf(shape_hw, u + h, v) - psf(shape_hw, u - h, v)) / (2 * h),
        "v": flux_e * (psf(shape_hw, u, v + h) - psf(shape_hw, u, v - h)) / (2 * h),
        "flux": p,
        "background": np.ones_like(p),
    }
    var = flux_e * p + background_e + read_noise_e**2
    derivs = np.stack([d[n].ravel() for n in unknowns])
    fisher = fisher_information(derivs, var.ravel())
    cov = np.linalg.inv(fisher)
    iu, iv = unknowns.index("u"), unknowns.index("v")
    return CRLB(np.sqrt(cov[iu, iu]), np.sqrt(cov[iv, iv]), cov, unknowns)
