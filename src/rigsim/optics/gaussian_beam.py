"""Gaussian laser beams (embedded-Gaussian / M² model, ISO 11146): radius, Rayleigh range, moments.

A beam of waist radius w0 (1/e² irradiance radius), beam-quality factor M² and wavelength λ has
the Rayleigh range z_R = π w0² / (M² λ) and the radius w(z) = w0·sqrt(1 + (z/z_R)²) at a distance z
from its waist. Its irradiance is I(r) ∝ exp(−2 r²/w²): each transverse coordinate has the second
central moment σ² = w²/4 (ISO 11146's second-moment diameter is 4σ = 2w).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["beam_radius_mm", "gaussian_irradiance", "rayleigh_range_mm", "sample_gaussian_disk", "second_moment_mm2"]


def rayleigh_range_mm(waist_mm: float, wavelength_nm: float, m_squared: float = 1.0) -> float:
    """z_R = π w0² / (M² λ), mm."""
    return math.pi * waist_mm**2 / (m_squared * wavelength_nm * 1e-6)


def beam_radius_mm(waist_mm: float, wavelength_nm: float, m_squared: float, z_mm: float) -> float:
    """w(z) = w0·sqrt(1 + (z/z_R)²), the 1/e² irradiance radius at z from the waist, mm."""
    zr = rayleigh_range_mm(waist_mm, wavelength_nm, m_squared)
    return waist_mm * math.sqrt(1.0 + (z_mm / zr) ** 2)


def second_moment_mm2(radius_mm: float, truncation: float = math.inf) -> float:
    """Second central moment per transverse axis of I ∝ exp(−2r²/w²) (w = ``radius_mm``), cut at
    r = ``truncation``·w: w²/4 without the cut; with it, σ² = (w²/4)·(1 − (1 + a) e^(−a)) / (1 − e^(−a)),
    a = 2·truncation²."""
    s2 = radius_mm**2 / 4.0
    if not math.isfinite(truncation):
        return s2
    a = 2.0 * truncation**2
    return s2 * (1.0 - (1.0 + a) * math.exp(-a)) / (1.0 - math.exp(-a))


def gaussian_irradiance(n: int, truncation: float) -> np.ndarray:
    """An n×n bitmap of exp(−2r²/w²) on the square [−truncation·w, truncation·w]² (pixel centres),
    zero beyond r = truncation·w; the peak is 1."""
    x = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    r2 = (x[None, :] ** 2 + x[:, None] ** 2) * truncation**2
    img = np.exp(-2.0 * r2)
    img[r2 > truncation**2] = 0.0
    return img


def sample_gaussian_disk(rng: np.random.Generator, n: int, radius_mm: float, truncation: float) -> tuple[np.ndarray, np.ndarray]:
    """n points (x, y) distributed as exp(−2r²/w²) and cut at r = truncation·w (exact inverse CDF of r)."""
    a = 2.0 * truncation**2
    u = rng.random(n)
    r = radius_mm * np.sqrt(-0.5 * np.log1p(-u * (1.0 - math.exp(-a))))
    t = 2.0 * np.pi * rng.random(n)
    return r * np.cos(t), r * np.sin(t)
