"""The star sensor's PSF from its traced lens: a table of PSFs over a grid of field directions and
wavelengths, and each star's PSF as the spectrum-weighted sum over wavelengths, interpolated in field.

Each table entry is the geometric spot of a regular grid of rays over the entrance pupil (the stop
cuts the real pupil out of it), deposited bilinearly on a grid of ``1/oversample`` px bins and
blurred by the Airy core's Gaussian (σ = 0.42 λ N). Positions are pixel offsets in the rig's image
(u right, v down: the physical image is inverted) from the chief ray at the reference wavelength,
so a PSF's first moment is its shift from the geometric image point: coma, oblique defocus and
lateral colour. docs/effects-star.md ("Traced PSF") gives the model and its numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter

__all__ = ["PSFTable", "bv_temperature_k", "photon_spectrum_weights", "field_tangents", "psf_table", "ray_offsets"]

_HC_OVER_K_UM_K = 14387.7688  # h c / k in µm·K (second radiation constant, CODATA 2018)


def bv_temperature_k(bv) -> np.ndarray:
    """Effective temperature (K) of a star of colour B−V (Ballesteros 2012, EPL 97, 34008, eq. 14: a
    blackbody fitted to the Johnson B and V bands); B−V is clipped to −0.4 … 2.0."""
    x = 0.92 * np.clip(np.asarray(bv, dtype=float), -0.4, 2.0)
    return 4600.0 * (1.0 / (x + 1.7) + 1.0 / (x + 0.62))


def photon_spectrum_weights(temperature_k, wavelengths_nm) -> np.ndarray:
    """(N, L) share of a blackbody's photons (QE flat across the band) at each of the evenly spaced
    wavelengths (trapezoid rule over the band); rows sum to 1. Photons per unit wavelength ∝
    λ⁻⁴ / (exp(hc/λkT) − 1)."""
    lam_um = np.asarray(wavelengths_nm, dtype=float) * 1e-3
    T = np.atleast_1d(np.asarray(temperature_k, dtype=float))[:, None]
    n = lam_um[None, :] ** -4 / np.expm1(_HC_OVER_K_UM_K / (lam_um[None, :] * T))
    trap = np.ones(lam_um.size)
    if lam_um.size > 1:
        trap[[0, -1]] = 0.5
    w = n * trap[None, :]
    return w / w.sum(axis=1, keepdims=True)


@dataclass(frozen=True)
class PSFTable:
    """``psf[i, j, l]``: the PSF (bins × bins, sums to 1) at field node (tan_x[i], tan_y[j]) and
    wavelength l; ``centroid[i, j, l]`` its first moment (px, u and v); bin k's centre lies at
    ``(k + ½)/oversample − radius_px`` px from the chief ray at the reference wavelength."""

    tan_x: np.ndarray
    tan_y: np.ndarray
    wavelengths_nm: np.ndarray
    oversample: int
    radius_px: int
    psf: np.ndarray        # (nx, ny, L, n, n) rows v, columns u
    centroid: np.ndarray   # (nx, ny, L, 2)

    def _field_weights(self, tx, ty):
        """Bilinear weights of the four nodes around each direction (clamped to the grid)."""
        def axis(g, t):
            t = np.clip(t, g[0], g[-1])
            i = np.clip(np.searchsorted(g, t) - 1, 0, g.size - 2)
            a = (t - g[i]) / (g[i + 1] - g[i])
            return i, a
        i, a = axis(self.tan_x, np.asarray(tx, float))
        j, b = axis(self.tan_y, np.asarray(ty, float))
        idx = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)]
        w = np.stack([(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b], axis=1)
        return idx, w

    def star_psfs(self, dirs_cam, spectral_weights):
        """Each star's PSF (N, n, n) and its centroid shift (N, 2) px: the spectrum-weighted sum over
        wavelengths (``spectral_weights`` (N, L)), interpolated bilinearly in field between the nodes."""
        d = np.asarray(dirs_cam, dtype=float)
        idx, w = self._field_weights(d[:, 0] / d[:, 2], d[:, 1] / d[:, 2])
        sw = np.asarray(spectral_weights, dtype=float)
        n = self.psf.shape[-1]
        out = np.zeros((d.shape[0], n, n))
        cen = np.zeros((d.shape[0], 2))
        for c, (i, j) in enumerate(idx):
            wl = w[:, c, None] * sw                                   # (N, L)
            out += np.einsum("nl,nlab->nab", wl, self.psf[i, j])
            cen += np.einsum("nl,nlk->nk", wl, self.centroid[i, j])
        return out, cen


def field_tangents(camera, resolution_px, widen: float = 1.02) -> np.ndarray:
    """(tan_x, tan_y) half-extents of the field that ``camera`` images on a detector of
    ``resolution_px`` (W, H), through its corners, ``widen`` × wider (the PSFs' off-detector wings)."""
    W, H = resolution_px
    d = camera.unproject(np.array([[-0.5, -0.5], [W - 0.5, -0.5], [-0.5, H - 0.5], [W - 0.5, H - 0.5]]))
    return np.abs(d[:, :2] / d[:, 2:3]).max(axis=0) * widen


def ray_offsets(lens, tan_x, tan_y, wavelengths_nm, *, pixel_pitch_um: float, pupil_rays: int = 48) -> np.ndarray:
    """(nx, ny, L) object array: at each field direction (tan_x[i], tan_y[j]) and wavelength, the
    (n, 2) detector offsets (px, u and v of the rig's image) of the rays of ``lens`` (a
    :class:`rigsim.optics.star_lens.StarLens`, ``pupil_rays`` across the pupil) from the chief
    ray at the lens's reference wavelength."""
    tx, ty = np.asarray(tan_x, dtype=float), np.asarray(tan_y, dtype=float)
    lams = np.asarray(wavelengths_nm, dtype=float)
    pupil = lens.pupil_grid(int(pupil_rays))
    pitch_mm = pixel_pitch_um * 1e-3
    offs = np.empty((tx.size, ty.size, lams.size), dtype=object)
    for i, x in enumerate(tx):
        for j, y in enumerate(ty):
            d = np.array([x, y, 1.0])
            chief = lens.trace(d, np.zeros((1, 2)), lens.ref_nm)[0][0]
            for k, lam in enumerate(lams):
                h, ok = lens.trace(d, pupil, lam)
                offs[i, j, k] = -(h[ok] - chief) / pitch_mm   # px in the rig's image (the lens inverts it)
    return offs


def psf_table(lens, *, tan_max_x: float, tan_max_y: float, wavelengths_nm, pixel_pitch_um: float,
              nodes: int = 9, pupil_rays: int = 48, oversample: int = 4) -> PSFTable:
    """Trace ``lens`` (a :class:`rigsim.optics.star_lens.StarLens`) at ``nodes`` × ``nodes`` field
    directions spanning ±``tan_max`` and at each wavelength: the :class:`PSFTable`."""
    tx = np.linspace(-tan_max_x, tan_max_x, nodes)
    ty = np.linspace(-tan_max_y, tan_max_y, nodes)
    lams = np.asarray(wavelengths_nm, dtype=float)
    f_number = lens.focal_length_mm / lens.epd_mm
    offs = ray_offsets(lens, tx, ty, lams, pixel_pitch_um=pixel_pitch_um, pupil_rays=pupil_rays)
    rmax = max(float(np.abs(o).max()) for o in offs.flat)
    sig_max = 0.42 * lams.max() * 1e-3 * f_number / pixel_pitch_um
    R = math.ceil(rmax + 4.0 * sig_max + 0.5)
    os_ = int(oversample)
    n = 2 * R * os_
    psf = np.zeros((nodes, nodes, lams.size, n, n))
    cen = np.zeros((nodes, nodes, lams.size, 2))
    for i in range(nodes):
        for j in range(nodes):
            for lam_i, lam in enumerate(lams):
                o = offs[i, j, lam_i]
                g = (o + R) * os_ - 0.5                  # continuous bin coordinate (bin k's centre at k)
                k0 = np.floor(g).astype(np.int64)
                f = g - k0
                img = np.zeros(n * n)
                for du, dv, wt in ((0, 0, (1 - f[:, 0]) * (1 - f[:, 1])), (1, 0, f[:, 0] * (1 - f[:, 1])),
                                   (0, 1, (1 - f[:, 0]) * f[:, 1]), (1, 1, f[:, 0] * f[:, 1])):
                    img += np.bincount((k0[:, 1] + dv) * n + k0[:, 0] + du, weights=wt, minlength=n * n)
                img = img.reshape(n, n)
                sig = 0.42 * lam * 1e-3 * f_number / pixel_pitch_um * os_
                img = gaussian_filter(img, sig, mode="constant", truncate=4.0)
                img /= img.sum()
                c = (np.arange(n) + 0.5) / os_ - R
                psf[i, j, lam_i] = img
                cen[i, j, lam_i] = (img.sum(axis=0) @ c, img.sum(axis=1) @ c)
    return PSFTable(tx, ty, lams, os_, R, psf, cen)
