"""Frames → centroids → (Δf, α, β, γ): the processing chain a real rig runs, on any ROIs.

Imaging (:mod:`rigsim.imaging`) and estimation (:mod:`rigsim.boresight.estimation`) stay separate:
:func:`centroid_rois` takes uint16/float ROIs and their origins and knows nothing of the rig;
:class:`CameraProcessor` holds one camera's nominal geometry and reference spots and turns a
pair of ROIs (M1, M2) into an estimate. Bring your own frames or centroids.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rigsim.imaging import NoiseModel, centroid_tcom
from rigsim.imaging.centroid import centroid as centroid_any

from .estimation import BoresightEstimate, estimate
from .geometry import CameraGeometry

__all__ = ["centroid_rois", "CameraProcessor", "SpotMeasurement"]


@dataclass
class SpotMeasurement:
    uv: np.ndarray          # (n, 2) rigsim pixels
    sigma_uv: np.ndarray    # (n, 2) propagated 1-sigma
    flags: np.ndarray       # (n,) rigsim.imaging.Flag bits
    valid: np.ndarray       # (n,) bool


def centroid_rois(rois, origins_uv, *, method: str = "tcom", noise: NoiseModel | None = None,
                  **kw) -> SpotMeasurement:
    """Centroid a stack of ROIs (n, h, w) whose pixel (0, 0) is detector pixel ``origins_uv[k]``.

    ``method="tcom"`` is seed 003's thresholded centre of mass (threshold: background + 3σ of the
    ROI's outer ring); any method of :func:`rigsim.imaging.centroid` may be named."""
    stack = np.asarray(rois)
    if stack.ndim == 2:
        stack = stack[None]
    if stack.ndim != 3:
        raise ValueError(f"rois must be (n, h, w) or (h, w), got shape {stack.shape}")
    org = np.asarray(origins_uv, dtype=float).reshape(-1, 2)
    if len(org) != len(stack):
        raise ValueError(f"origins_uv has {len(org)} rows for {len(stack)} ROIs")
    if method == "tcom":
        res = centroid_tcom(stack, noise=noise, origin_uv=org, **kw)
    else:
        res = centroid_any(stack, method=method, noise=noise, origin_uv=org, **kw)
    uv = np.column_stack([res.u, res.v])
    sig = np.column_stack([res.sigma_u, res.sigma_v])
    return SpotMeasurement(uv, sig, np.asarray(res.flags), np.asarray(res.valid))


class CameraProcessor:
    """One camera's real-time chain: two ROIs (M1, M2) → centroids → estimate.

    ``reference_uv`` (2, 2): the reference spots A1, B1 (measured at the reference state, e.g. the
    mean of many frames); default the design's."""

    def __init__(self, geom: CameraGeometry, reference_uv=None, *, method: str = "dvad",
                 reading: str = "consistent", centroider: str = "tcom", noise: NoiseModel | None = None):
        self.geom = geom
        self.reference_uv = np.asarray(geom.reference_uv if reference_uv is None else reference_uv, float)
        self.method = method
        self.reading = reading
        self.centroider = centroider
        self.noise = noise

    def spots(self, roi_m1, roi_m2, origin_m1, origin_m2) -> SpotMeasurement:
        return centroid_rois(np.stack([roi_m1, roi_m2]), [origin_m1, origin_m2], method=self.centroider,
                             noise=self.noise)

    def process(self, roi_m1, roi_m2, origin_m1, origin_m2) -> BoresightEstimate:
        """(Δf, α, β, γ) from one pair of ROIs. Raises ValueError if a spot is not measurable."""
        m = self.spots(roi_m1, roi_m2, origin_m1, origin_m2)
        if not m.valid.all():
            from rigsim.imaging import Flag

            bad = [f"M{k + 1}: {Flag(int(f)).name}" for k, f in enumerate(m.flags) if not m.valid[k]]
            raise ValueError("no usable laser spot in " + ", ".join(bad))
        return estimate(self.geom, self.reference_uv, m.uv.reshape(2, 2), self.method, self.reading)

    def process_uv(self, meas_uv) -> BoresightEstimate:
        """From spot positions (…, 2, 2) a user measured with their own centroider."""
        return estimate(self.geom, self.reference_uv, meas_uv, self.method, self.reading)
