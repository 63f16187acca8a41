"""The star image's centroid shift from the chief ray over the field: the bilinear map a ground
calibration delivers (:class:`CentroidMap`), and the traced lens's first-moment shift
(:func:`ray_centroids`).

The first moment of a traced PSF (:func:`rigsim.optics.star_psf.psf_table`) is the mean of its rays'
detector offsets: depositing a ray bilinearly and blurring by a symmetric Gaussian keep it. A
centroid fitted with a Gaussian does not follow the first moment of a lopsided spot, so the ground
map is measured with the pipeline's own centroiding (rigsim.procedures.star.ground_map).
docs/effects-star.md ("A ground calibration of the centroid shift") gives the numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rigsim.optics.star_psf import ray_offsets

__all__ = ["CentroidMap", "ray_centroids"]


def ray_centroids(lens, tan_x, tan_y, wavelengths_nm, *, pixel_pitch_um: float, pupil_rays: int = 48) -> np.ndarray:
    """(nx, ny, L, 2) mean detector offset (px, u and v of the rig's image) of the rays of ``lens`` (a
    :class:`rigsim.optics.star_lens.StarLens`) from the chief ray at its reference wavelength, at each
    field direction (tan_x[i], tan_y[j]) and wavelength: the first moment of
    :func:`rigsim.optics.star_psf.psf_table`'s PSFs with the same pupil grid."""
    offs = ray_offsets(lens, tan_x, tan_y, wavelengths_nm, pixel_pitch_um=pixel_pitch_um, pupil_rays=pupil_rays)
    return np.array([o.mean(axis=0) for o in offs.flat]).reshape(offs.shape + (2,))


@dataclass(frozen=True)
class CentroidMap:
    """``shift[i, j]``: the centroid shift (px, u and v) at field direction (tan_x[i], tan_y[j]);
    bilinear between the nodes, clamped at the grid's edge."""

    tan_x: np.ndarray
    tan_y: np.ndarray
    shift: np.ndarray   # (nx, ny, 2)

    def at(self, tan_x, tan_y) -> np.ndarray:
        """(N, 2) shift at the directions (tan_x, tan_y) (each (N,))."""
        def axis(g, t):
            t = np.clip(np.asarray(t, dtype=float), g[0], g[-1])
            i = np.clip(np.searchsorted(g, t) - 1, 0, g.size - 2)
            return i, (t - g[i]) / (g[i + 1] - g[i])

        i, a = axis(self.tan_x, tan_x)
        j, b = axis(self.tan_y, tan_y)
        a, b = a[:, None], b[:, None]
        s = self.shift
        return ((1 - a) * (1 - b) * s[i, j] + a * (1 - b) * s[i + 1, j] + (1 - a) * b * s[i, j + 1]
                + a * b * s[i + 1, j + 1])
