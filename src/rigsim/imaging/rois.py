"""Centroids of a stack of regions of interest cut from one detector frame (one row per ROI, rigsim
pixels).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rigsim.imaging import NoiseModel, centroid_tcom
from rigsim.imaging.centroid import centroid as centroid_any

MAD_TO_SD = 1.482602218505602


@dataclass
class RoiCentroids:
    uv: np.ndarray          # (n, 2) rigsim pixels
    sigma_uv: np.ndarray    # (n, 2) propagated 1-sigma
    flags: np.ndarray       # (n,) rigsim.imaging.Flag bits
    valid: np.ndarray       # (n,) bool


def centroid_rois(rois, origins_uv, *, method: str = "tcom", noise: NoiseModel | None = None,
                  **kw) -> RoiCentroids:
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
    return RoiCentroids(uv, sig, np.asarray(res.flags), np.asarray(res.valid))


def tcom_fast(rois, origins_uv, *, noise: NoiseModel | None = None, threshold_sigma: float = 3.0):
    """Lean thresholded centre of mass for the real-time path: the definition of
    :func:`rigsim.imaging.centroid_tcom` (``mode="subtract"``: background = median of the ROI's
    outer ring, threshold T = background + 3σ with σ from ``noise`` or 1.4826·MAD of the ring,
    weights I − T above T) without its flag machinery (~0.75 ms per call). Returns (uv (n, 2),
    ok (n,)); ``ok`` is False where a pixel is saturated, non-finite or nothing passes the
    threshold — use :func:`centroid_rois` there for the flags. Equal to centroid_tcom to 1e-12 px
    on clean ROIs (tested)."""
    a = np.asarray(rois)
    if a.ndim == 2:
        a = a[None]
    sat = np.iinfo(a.dtype).max if np.issubdtype(a.dtype, np.integer) else np.inf
    d = a.astype(float)
    n, h, w = d.shape
    ring = np.concatenate([d[:, 0, :], d[:, -1, :], d[:, 1:-1, 0], d[:, 1:-1, -1]], axis=1)
    bg = np.median(ring, axis=1)
    if noise is not None:
        sd = np.sqrt(noise.variance(bg))
    else:
        sd = MAD_TO_SD * np.median(np.abs(ring - bg[:, None]), axis=1)
    wgt = d - (bg + threshold_sigma * sd)[:, None, None]
    np.maximum(wgt, 0.0, out=wgt)
    W = wgt.sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        u = (wgt.sum(axis=1) @ np.arange(w, dtype=float)) / W
        v = (wgt.sum(axis=2) @ np.arange(h, dtype=float)) / W
    org = np.asarray(origins_uv, float).reshape(-1, 2)
    uv = np.column_stack([u, v]) + org
    ok = (W > 0) & np.isfinite(d).all(axis=(1, 2)) & ~(a >= sat).any(axis=(1, 2))
    return uv, ok
