"""The sun sensor's spot as a forward model: the image of the sun's disk through the sensor's
pinhole, pixel-integrated, as a function of where the disk's centre projects.

The continuous image is built on a grid of ``step_px`` cells around the centre's projection from
the disk's quadrature (each point projected through the nominal camera, weighted per solid angle,
by the disk's radiance and the thick pinhole's throughput when the rig has them), convolved with
the pinhole's diffraction PSF when the rig has it, and summed over one pixel. Its value at any
sub-pixel offset comes from a cubic spline over that grid. The shape is computed once, at the
spot's first estimate: over the fraction of a pixel a fit moves, it does not change.
"""

from __future__ import annotations

import math

import numpy as np

from rigsim.optics.camera import PinholeBrown
from rigsim.optics.spot_grid import GridSpotModel, pixel_sums
from rigsim.optics.sun_disk import disk_image_points

__all__ = ["SunSpotModel"]


class SunSpotModel(GridSpotModel):
    """``model(u, v)``: the unit-flux pixel image, on the window of ``shape_hw`` pixels whose first
    pixel is at ``origin_uv``, of the sun's disk (``full_angle_rad``) whose centre projects to (u, v);
    ``sun_dir`` is the direction (camera frame) the shape is computed at. ``psf``: a
    :class:`rigsim.optics.pinhole_diffraction.PinholePSF` (None: a point pinhole); ``radiance``: a
    non-uniform disk (:class:`rigsim.optics.sun_radiance.DiskRadiance`; its gradient's axis
    ``radiance_axis``); ``pinhole``: a :class:`rigsim.optics.pinhole.ThickPinhole`'s vignetting.
    ``effects`` lists which of these the model holds. ``step_px``: the grid (default 1/32 px for a
    point pinhole, 1/4 px with the PSF; docs/forward-model.md gives the errors of coarser grids).
    ``psf_margin_px``: the PSF reaches this far beyond the window's half width."""

    def __init__(self, camera: PinholeBrown, full_angle_rad: float, sun_dir, origin_uv, shape_hw, *, psf=None,
                 radiance=None, radiance_axis=None, pinhole=None, response: str = "flux", step_px: float | None = None,
                 points: int = 60_000, psf_margin_px: float = 1.0):
        if step_px is None:  # a sharp disk's edges need 1/32 px; the diffracted image is smooth at 1/4 px
            step_px = 0.03125 if psf is None else 0.25
        m = round(1.0 / step_px)
        if m < 1 or abs(m * step_px - 1.0) > 1e-9:
            raise ValueError(f"step_px = {step_px!r}: must be 1/m for an integer m >= 1")
        self.origin = np.asarray(origin_uv, dtype=float).reshape(2)
        self.shape = (int(shape_hw[0]), int(shape_hw[1]))
        rad = radiance if radiance is not None and not getattr(radiance, "uniform", False) else None
        pts = disk_image_points(camera, sun_dir, full_angle_rad, n=points, response=response, radiance=rad,
                                radiance_axis=radiance_axis,
                                direction_weight=None if pinhole is None else pinhole.direction_weight)
        if not pts["valid"]:
            raise ValueError("the sun's disk leaves the camera model at this direction: no spot model")
        off = pts["uv"] - pts["center_uv"]
        w = pts["weight"] / pts["weight"].sum()
        extent = float(np.max(np.abs(off))) + 2.0
        half_psf = 0.0
        if psf is not None:
            # the PSF out to a readout window's half width around the spot: the fit's window is 2 px
            # narrower than the sensor's readout window, whose light the renderer (and a real window)
            # keeps to ± its half width; a kernel cut at the fit window's half width biases the
            # streaked spots past 60° by 0.01–0.06 px (docs/forward-model.md)
            half_psf = max(self.shape) / 2.0 + psf_margin_px
        half = math.ceil(extent + half_psf + 1.0)
        n = 2 * half * m + 1  # cells of step s centred on k·s, k = -half·m … half·m
        idx = np.floor(off / step_px + 0.5).astype(np.int64) + half * m
        img = np.bincount(idx[:, 1] * n + idx[:, 0], weights=w, minlength=n * n).reshape(n, n)  # [v, u]
        effects = ["disk"]
        if rad is not None:
            effects.append("disk radiance")
        if pinhole is not None:
            effects.append("vignetting")
        if psf is not None:
            from scipy.signal import fftconvolve

            K = psf.kernel(sun_dir, camera.fx, camera.fy, half_psf, step_px)
            img = fftconvolve(img, K, mode="same")
            effects.append("pinhole diffraction")
        # one pixel's sum: m cells; for even m the sums sit on the cell boundaries (offset s/2)
        P = pixel_sums(img, m)
        # P[j, i] is the pixel whose lower-left cell is j, i: its centre at offset (i + (m-1)/2 - half·m)·s
        self._tabulate(P, ((m - 1) / 2.0 - half * m) * step_px, step_px, origin_uv, shape_hw, effects)
