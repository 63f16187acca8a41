"""Every spot of a frame, measured the same way whether the frame is a whole detector image from a
user's file or a readout window inside rigsim: detect connected pixels above a threshold, then
centroid each spot on its own pixels (``scurve``) or on a window around them (``tcom``, ``wcom``,
``gauss``). Positions are detector pixels (``origin_uv`` is the window's place on the detector)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .centroid import METHODS
from .result import CentroidBatch, Flag, NoiseModel
from .scurve import solve_axis

FRAME_METHODS = ("scurve", "tcom", "wcom", "gauss")
"""``scurve``: first moment of the spot's pixels above the threshold, corrected for the pixel-phase
(S-curve) bias of a uniform disk (the sun image); ``tcom``/``wcom``/``gauss``: rigsim.imaging's
thresholded, windowed and Gaussian-fit centroiders on a window around the spot."""


def default_threshold_dn(noise: NoiseModel) -> float:
    """5σ of the read noise, at least 3 quantisation steps (3 DN; 48 DN for 12-bit codes in 16-bit words)
    above the offset."""
    return max(3.0 * noise.quantum_dn, 5.0 * noise.read_noise_dn)


def _scurve(a: np.ndarray, sel: np.ndarray, var: np.ndarray, x0: int, y0: int):
    w = np.where(sel, a, 0.0)
    S = w.sum()
    v, u = np.indices(w.shape)
    mu, mv = (u * w).sum() / S, (v * w).sum() / S
    var_u = ((u - mu) ** 2 * w).sum() / S
    var_v = ((v - mv) ** 2 * w).sum() / S
    cu, _ = solve_axis(mu + x0, var_u)
    cv, _ = solve_axis(mv + y0, var_v)
    s_u = math.sqrt(float(((u - mu) ** 2 * var * sel).sum())) / S  # the moment's noise (the correction's
    s_v = math.sqrt(float(((v - mv) ** 2 * var * sel).sum())) / S  # slope is ~1 at this width)
    return cu, cv, s_u, s_v, float(S)


def measure_frame(img, noise: NoiseModel, *, method: str = "scurve", threshold_dn: float | None = None,
                  saturation_dn: float | None = None, origin_uv=(0, 0), detector_shape: tuple[int, int] | None = None,
                  min_area_px: int = 3, margin_px: int = 3, sigma_px: float | None = None) -> CentroidBatch:
    """Every spot of a frame (``img[v, u]`` in DN, the offset included): (u, v) in detector pixels,
    1σ, flux (DN above the threshold for ``scurve``), background and flags, brightest first.

    ``noise``: the detector (its offset is subtracted; gain and read noise give the threshold and
    the σ). ``saturation_dn``: raw DN at or above which a spot is SATURATED. ``origin_uv``,
    ``detector_shape`` (rows, cols): where the image sits on the detector; a spot touching the
    detector's or the image's border is flagged EDGE."""
    import cv2

    if method not in FRAME_METHODS:
        raise ValueError(f"method = {method!r}: allowed {', '.join(FRAME_METHODS)}")
    raw = np.asarray(img)
    if raw.ndim != 2:
        raise ValueError(f"a frame is a 2-D image; got shape {raw.shape}")
    a = raw.astype(float) - noise.offset_dn
    thr = default_threshold_dn(noise) if threshold_dn is None else float(threshold_dn)
    h, w = a.shape
    ou, ov = int(origin_uv[0]), int(origin_uv[1])
    dh, dw = detector_shape if detector_shape is not None else (h, w)
    n, labels, stats, _ = cv2.connectedComponentsWithStats((a > thr).astype(np.uint8), connectivity=8)
    rows = []
    for k in range(1, n):
        x0, y0, bw, bh, area = (int(s) for s in stats[k])
        if area < min_area_px:
            continue
        fl = Flag(0)
        if x0 == 0 or y0 == 0 or x0 + bw == w or y0 + bh == h or ou + x0 == 0 or ov + y0 == 0 \
                or ou + x0 + bw == dw or ov + y0 + bh == dh:
            fl |= Flag.EDGE
        win = (slice(y0, y0 + bh), slice(x0, x0 + bw))
        sel = labels[win] == k
        if saturation_dn is not None and np.any(raw[win][sel] >= saturation_dn):
            fl |= Flag.SATURATED
        if method == "scurve":
            var = noise.variance(np.clip(a[win], 0.0, None) + noise.offset_dn)
            cu, cv, su, sv, flux = _scurve(a[win], sel, var, x0 + ou, y0 + ov)
            rows.append((cu, cv, su, sv, flux, 0.0, int(fl)))
            continue
        m = margin_px
        ys, xs = slice(max(0, y0 - m), min(h, y0 + bh + m)), slice(max(0, x0 - m), min(w, x0 + bw + m))
        kw = {"noise": dataclasses.replace(noise, offset_dn=0.0),
              "flags": int(fl), "origin_uv": (xs.start + ou, ys.start + ov),
              "saturation": None if saturation_dn is None else saturation_dn - noise.offset_dn}
        if method == "tcom":
            kw["threshold"] = thr
        if sigma_px is not None and method == "gauss":
            kw["sigma_px"] = sigma_px
        if method == "gauss" and sigma_px is None:
            kw["fit_sigma"] = True
        c = METHODS[method](a[ys, xs], **kw)
        rows.append((c.u, c.v, c.sigma_u, c.sigma_v, c.flux, c.background, int(c.flags)))
    if not rows:
        z = np.zeros(0)
        return CentroidBatch(z, z, z, z, z, z, np.zeros(0, dtype=np.int64), method)
    r = np.array(rows, dtype=float)
    order = np.argsort(-r[:, 4], kind="stable")
    r = r[order]
    return CentroidBatch(r[:, 0], r[:, 1], r[:, 2], r[:, 3], r[:, 4], r[:, 5], r[:, 6].astype(np.int64), method)


REJECT = Flag.INVALID | Flag.SATURATED | Flag.EDGE
"""A spot with any of these flags gives no measurement (the sun-sensor sweep leaves its frame out)."""


def single_spot(spots: CentroidBatch) -> int | None:
    """The frame's one spot (a sun image, an autocollimator return): the brightest, if it has none
    of the :data:`REJECT` flags; None otherwise (no spot, or the brightest one is unusable)."""
    if len(spots) == 0 or spots.flags[0] & int(REJECT):
        return None
    return 0
