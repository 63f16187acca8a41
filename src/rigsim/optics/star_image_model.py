"""The star image the sensor's optics predict at a detector position: the model a forward-model
centroider fits to the pixels (:func:`rigsim.imaging.star_model_fit.fit_star_models`).

Two models, both unit flux and integrated exactly over each pixel, both referenced to the point the
camera model projects (a star at (u, v) is the star whose geometric image point, pinhole plus
Brown distortion, is (u, v)), so a fitted position needs no centroid-shift correction:

* :class:`GaussianStarImage`: the circular Gaussian of the rig's ``[sensor.psf]`` (defocus and
  Airy core), centred on the image point (erf differences per pixel).
* :class:`TracedStarImage`: the traced lens's PSF (:class:`rigsim.optics.star_psf.PSFTable`) at the
  star's field direction (the nominal camera's ray through (u, v)) for a reference star colour,
  placed with its chief ray at (u, v). The renderer draws each ¼-px bin constant within the bin
  (``rigsim.render.star.render_stars_psf``), which makes a pixel's value piecewise linear in the
  star's position, with jumps in its derivative that stall a Gauss–Newton fit and make the Fisher
  information jump. The model smooths each bin by a box of :data:`SMOOTH` bins (⅛ px; the PSF's
  variance grows by 0.0013 px², against 1.7–3.3 px²): the pixel values are then piecewise quadratic
  with continuous derivatives. On noise-free traced stars the fitted position is then 0.001 px rms
  (0.005 px at most) from the exact one; with half that smoothing (0.0005 px rms) a Gauss–Newton
  fit without step control stalls on a few stars in 100.

A model is bound to the stars of a frame (:meth:`bind`: the per-star PSF at each star's start
position), then evaluated at trial positions: :meth:`BoundStarImage.pixels` gives the image and its
derivatives in u and v on each star's window. docs/effects-star.md ("The forward-model centroider")
says what is in the model and what is not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import erf

from rigsim.optics.star_psf import PSFTable, bv_temperature_k, photon_spectrum_weights

__all__ = ["BoundStarImage", "GaussianStarImage", "TracedStarImage", "bind_psf_bins"]

SMOOTH = 0.5
"""Width of the box that smooths each PSF bin, in bins (module docstring)."""
_SQRT2 = math.sqrt(2.0)
_INV_SQRT2PI = 1.0 / math.sqrt(2.0 * math.pi)


class BoundStarImage:
    """A star image model bound to N stars: :meth:`pixels` at trial positions."""

    def pixels(self, u, v, origin_uv, shape_hw):  # pragma: no cover - interface
        """(p, dp/du, dp/dv), each (N, h, w): the unit-flux image of star i at (u[i], v[i]) (frame px) on
        the window whose pixel (0, 0) is at ``origin_uv[i]``."""
        raise NotImplementedError

    def subset(self, idx) -> "BoundStarImage":  # pragma: no cover - interface
        """The model of the stars ``idx`` only."""
        raise NotImplementedError


def _gauss_1d(n: int, c: np.ndarray, s: float):
    """(N, n) pixel fractions of a 1-D Gaussian of centre c (N,) (window px) and their c-derivatives."""
    edges = np.arange(n + 1, dtype=float) - 0.5
    z = (edges[None, :] - c[:, None]) / s
    cdf = 0.5 * erf(z / _SQRT2)
    pdf = _INV_SQRT2PI * np.exp(-0.5 * z * z)
    return np.diff(cdf, axis=1), -np.diff(pdf, axis=1) / s


class _BoundGaussian(BoundStarImage):
    def __init__(self, sigma_px: float, n: int):
        self.sigma_px, self.n = float(sigma_px), int(n)

    def subset(self, idx):
        return _BoundGaussian(self.sigma_px, len(np.arange(self.n)[idx]))

    def pixels(self, u, v, origin_uv, shape_hw):
        h, w = shape_hw
        o = np.asarray(origin_uv, float)
        ex, dex = _gauss_1d(w, np.asarray(u, float) - o[:, 0], self.sigma_px)
        ey, dey = _gauss_1d(h, np.asarray(v, float) - o[:, 1], self.sigma_px)
        p = ey[:, :, None] * ex[:, None, :]
        return p, ey[:, :, None] * dex[:, None, :], dey[:, :, None] * ex[:, None, :]


@dataclass(frozen=True)
class GaussianStarImage:
    """A pixel-integrated circular Gaussian of ``sigma_px``, centred on the star's image point."""

    sigma_px: float

    @property
    def includes(self) -> tuple[str, ...]:
        return (f"circular Gaussian PSF, σ = {self.sigma_px:.3f} px (defocus and Airy core)",
                "exact pixel integration")

    @property
    def support_px(self) -> int:
        """Half-width (px) of the window the model needs around the star."""
        return max(3, math.ceil(4.0 * self.sigma_px))

    def bind(self, uv, bv=None) -> BoundStarImage:
        return _BoundGaussian(self.sigma_px, len(np.atleast_2d(uv)))


def _ramp_integral(z: np.ndarray, h: float) -> np.ndarray:
    """∫ clip(t, 0, h) dt from −∞ to z."""
    return np.where(z <= 0, 0.0, np.where(z <= h, 0.5 * z * z, h * (z - 0.5 * h)))


def _overlap(c: np.ndarray, first_px: np.ndarray, m: int, centres: np.ndarray, os_: int, smooth: float):
    """(N, m, n) share of each 1/os-px bin in each of m pixels, and its derivative in the star's position
    c (N,): bin j is a box of width h = 1/os centred on c + centres[j], smoothed by a second box of
    width ``smooth`` · h, pixel k spans [first_px + k − ½, first_px + k + ½]. The share is piecewise
    quadratic in c with a continuous derivative (the bare box's is piecewise linear with jumps)."""
    h = 1.0 / os_
    w = float(smooth) * h
    pix = first_px[:, None, None] + np.arange(m)[None, :, None]
    x0 = c[:, None, None] + centres[None, None, :] - 0.5 * h          # the bin's left edge
    share = np.zeros((len(c), m, centres.size))
    dshare = np.zeros_like(share)
    for edge, sign in ((pix + 0.5, 1.0), (pix - 0.5, -1.0)):
        y = edge - x0
        share += sign * (_ramp_integral(y + 0.5 * w, h) - _ramp_integral(y - 0.5 * w, h)) / w
        dshare -= sign * (np.clip(y + 0.5 * w, 0.0, h) - np.clip(y - 0.5 * w, 0.0, h)) / w
    return share * os_, dshare * os_


class _BoundTable(BoundStarImage):
    def __init__(self, bins: np.ndarray, radius_px: int, oversample: int, smooth: float = SMOOTH):
        self.bins, self.R, self.os, self.smooth = bins, int(radius_px), int(oversample), float(smooth)
        self.centres = (np.arange(bins.shape[-1]) + 0.5) / self.os - self.R

    def subset(self, idx):
        return _BoundTable(self.bins[idx], self.R, self.os, self.smooth)

    def pixels(self, u, v, origin_uv, shape_hw):
        h, w = shape_hw
        o = np.asarray(origin_uv, float)
        Au, dAu = _overlap(np.asarray(u, float), o[:, 0], w, self.centres, self.os, self.smooth)
        Av, dAv = _overlap(np.asarray(v, float), o[:, 1], h, self.centres, self.os, self.smooth)
        PAu = self.bins @ np.swapaxes(Au, 1, 2)                                      # (N, n, w)
        p = Av @ PAu
        return p, Av @ (self.bins @ np.swapaxes(dAu, 1, 2)), dAv @ PAu


@dataclass(frozen=True)
class TracedStarImage:
    """The traced lens's PSF at the star's field direction through ``camera`` (the nominal camera), for
    a blackbody star of colour ``reference_bv``, with its chief ray at the star's image point."""

    table: PSFTable
    camera: object
    reference_bv: float = 0.65

    @property
    def includes(self) -> tuple[str, ...]:
        t = self.table
        return (f"traced lens PSF ({t.psf.shape[0]}×{t.psf.shape[1]} field nodes, bilinear in field; "
                f"{t.wavelengths_nm.size} wavelengths {t.wavelengths_nm[0]:.0f}–{t.wavelengths_nm[-1]:.0f} nm)",
                f"star colour: a blackbody of B−V {self.reference_bv:g} for every star",
                "field direction: the nominal camera's ray through the star's start position",
                f"exact pixel integration of 1/{t.oversample}-px bins (each smoothed by a {SMOOTH:g}-bin box); "
                "no motion smear")

    @property
    def support_px(self) -> int:
        """Half-width (px) of the window the model needs around the star: the PSF's 99.9 % energy radius
        over the table, plus a pixel."""
        t = self.table
        n = t.psf.shape[-1]
        c = (np.arange(n) + 0.5) / t.oversample - t.radius_px
        r = np.hypot(c[None, :], c[:, None]).ravel()
        order = np.argsort(r)
        flat = t.psf.reshape(-1, n * n)[:, order]
        cum = np.cumsum(flat, axis=1)
        r99 = r[order][np.argmax(cum >= 0.999, axis=1)].max()
        return min(int(t.radius_px), math.ceil(float(r99)) + 1)

    def spectral_weights(self, bv=None) -> np.ndarray:
        """(N, L) or (1, L): the photons per wavelength of stars of colour ``bv`` (default the reference)."""
        bv = self.reference_bv if bv is None else np.where(np.isfinite(bv), bv, self.reference_bv)
        return photon_spectrum_weights(bv_temperature_k(np.atleast_1d(bv)), self.table.wavelengths_nm)

    def bind(self, uv, bv=None) -> BoundStarImage:
        """The model of stars near ``uv`` (N, 2) px, of colours ``bv`` (N,) (default: the reference colour)."""
        uv = np.atleast_2d(np.asarray(uv, float))
        d = self.camera.unproject(uv)
        w = np.broadcast_to(self.spectral_weights(bv), (len(uv), self.table.wavelengths_nm.size))
        bins, _shift = self.table.star_psfs(d, w)
        return _BoundTable(bins, self.table.radius_px, self.table.oversample)


def bind_psf_bins(bins, radius_px: int, oversample: int) -> BoundStarImage:
    """A star image model of given PSF bins ((N, n, n), a :class:`PSFTable`'s layout: e.g. the PSFs the
    renderer drew), one per star."""
    return _BoundTable(np.asarray(bins, dtype=float), radius_px, oversample)
