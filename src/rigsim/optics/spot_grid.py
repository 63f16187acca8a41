"""A spot model tabulated on a fine grid: the unit-flux pixel image P sampled every ``step`` px of
offset, interpolated by a cubic spline to any sub-pixel offset on a window's pixels. The forward
models of the sun-sensor and autocollimator spots are built this way (docs/forward-model.md)."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates, spline_filter

__all__ = ["GridSpotModel", "pixel_sums"]


def pixel_sums(img: np.ndarray, m: int) -> np.ndarray:
    """Sums of every m × m block of cells of ``img`` (one pixel's light when a cell is 1/m px), at every
    cell offset: ``out[j, i]`` = ``img[j:j+m, i:i+m].sum()``, its centre (m − 1)/2 cells past (i, j)."""
    c = np.cumsum(np.pad(img, ((1, 0), (1, 0))), axis=0).cumsum(axis=1)
    return c[m:, m:] - c[:-m, m:] - c[m:, :-m] + c[:-m, :-m]


class GridSpotModel:
    """``model(u, v)``: the window's pixel image for a spot whose reference point is at (u, v).
    Subclasses build P and call :meth:`_tabulate`."""

    def _tabulate(self, P: np.ndarray, first_px: float, step_px: float, origin_uv, shape_hw, effects) -> None:
        """``P[j, i]``: the pixel image at offset (``first_px`` + i·step, ``first_px`` + j·step) of the
        pixel's centre from the reference point; the window's first pixel at ``origin_uv``."""
        self.origin = np.asarray(origin_uv, dtype=float).reshape(2)
        self.shape = (int(shape_hw[0]), int(shape_hw[1]))
        self._first = float(first_px)
        self._step = float(step_px)
        self._coef = spline_filter(P, order=3, mode="constant")
        self.effects = tuple(effects)
        v, u = np.indices(self.shape)
        self._u = u.ravel() + self.origin[0]
        self._v = v.ravel() + self.origin[1]

    def __call__(self, u: float, v: float) -> np.ndarray:
        iu = (self._u - u - self._first) / self._step
        iv = (self._v - v - self._first) / self._step
        out = map_coordinates(self._coef, [iv, iu], order=3, mode="constant", cval=0.0, prefilter=False)
        return out.reshape(self.shape)
