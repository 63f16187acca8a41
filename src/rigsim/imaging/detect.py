"""Detection: background estimation, thresholding and labelling, ROI extraction, multi-spot
(star) extraction with blend flags.

Pipeline: `estimate_background` -> `detect` (threshold at background + k * rms, connected
components with OpenCV, peaks inside each component; components with several separated peaks are
split and flagged BLENDED) -> `extract_rois` (fixed-size cut-outs, NaN outside the frame, EDGE) ->
a centroider from `centroid`. `find_spots` runs all of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ._common import MAD_TO_SD
from .centroid import METHODS
from .result import CentroidBatch, Flag, NoiseModel

__all__ = [
    "Background",
    "Detections",
    "Rois",
    "estimate_background",
    "detect",
    "extract_rois",
    "find_spots",
]


@dataclass(frozen=True)
class Background:
    """Background level and rms (DN); scalars for a global estimate, (h, w) maps for a mesh."""

    level: float | np.ndarray
    rms: float | np.ndarray
    flags: Flag = Flag.OK


def _as_frame(img) -> np.ndarray:
    a = np.asarray(img)
    if a.dtype == object or not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise TypeError(f"frame must be a real numeric array, got dtype {a.dtype}")
    if a.ndim != 2:
        raise ValueError(f"frame must have shape (h, w), got shape {a.shape}")
    return a


def _clipped_stats(vals: np.ndarray, nsigma: float, max_iter: int) -> tuple[float, float]:
    """Sigma-clipped median and MAD-based rms of a 1-D array of finite values. Whole-numbered values
    (a frame's codes) are clipped on their histogram (:func:`_clipped_stats_codes`): the same numbers,
    bit for bit, about six times faster on a megapixel frame."""
    if vals.size >= _HISTOGRAM_MIN_SIZE:
        lo, hi = float(vals.min()), float(vals.max())
        if hi - lo < _HISTOGRAM_MAX_SPAN and np.array_equal(vals, np.rint(vals)):
            return _clipped_stats_codes(vals, lo, hi, nsigma, max_iter)
    v = vals
    med, rms = np.nan, np.nan
    for _ in range(max_iter):
        if v.size == 0:
            break
        med = float(np.median(v))
        rms = float(MAD_TO_SD * np.median(np.abs(v - med)))
        if rms == 0:
            # more than half the pixels share one value (e.g. a noise-free frame)
            rms = float(np.std(v))
            if rms == 0:
                break
        keep = np.abs(v - med) <= nsigma * rms
        if keep.all():
            break
        v = v[keep]
    return med, rms


_HISTOGRAM_MIN_SIZE = 4096
_HISTOGRAM_MAX_SPAN = 1 << 20


def _median_of_counts(counts: np.ndarray) -> float:
    """The median (as :func:`numpy.median`: the mean of the two middle values when their number is even) of a
    multiset given as counts of the values 0, 1, 2, …"""
    c = np.cumsum(counts)
    n = int(c[-1])
    a = float(np.searchsorted(c, (n - 1) // 2, side="right"))
    b = float(np.searchsorted(c, n // 2, side="right"))
    return a if n % 2 else (a + b) / 2.0


def _clipped_stats_codes(vals: np.ndarray, lo: float, hi: float, nsigma: float, max_iter: int) -> tuple[float, float]:
    """:func:`_clipped_stats` of whole-numbered values within ``lo``…``hi``. Every clip keeps the values in an
    interval around the median, so the kept values are always those of one interval of the histogram; values,
    medians (whole or half) and distances are exact in float64, so every comparison is the array path's."""
    counts = np.bincount((vals - lo).astype(np.int64), minlength=int(hi - lo) + 1)
    ka, kb = 0, len(counts) - 1                          # the kept values: lo + ka … lo + kb
    med, rms = np.nan, np.nan
    for _ in range(max_iter):
        cnt = counts[ka:kb + 1]
        if not cnt.any():
            break
        m = _median_of_counts(cnt)                       # in units above lo + ka
        med = lo + ka + m
        k = np.arange(cnt.size)
        twice = np.abs(2 * k - int(2 * m))               # 2·|value − median|, whole
        mad = _median_of_counts(np.bincount(twice, weights=cnt, minlength=1).astype(np.int64)) / 2.0
        rms = float(MAD_TO_SD * mad)
        if rms == 0:
            v = vals[(vals >= lo + ka) & (vals <= lo + kb)]
            rms = float(np.std(v))
            if rms == 0:
                break
        inside = np.abs(k - m) <= nsigma * rms
        if not cnt[~inside].any() or not inside.any():  # all kept, or none (the array path then stops too)
            break
        ka, kb = ka + int(np.argmax(inside)), ka + int(cnt.size - 1 - np.argmax(inside[::-1]))
    return med, rms


def estimate_background(
    img,
    *,
    box_px: int | None = None,
    nsigma_clip: float = 3.0,
    max_iter: int = 5,
    mask=None,
    saturation: float | None = None,
) -> Background:
    """Sigma-clipped median background and its rms.

    ``box_px`` None: one global level. Otherwise the frame is cut into ``box_px`` squares, each
    gets a clipped median/rms, and the grid is bilinearly interpolated to (h, w) maps (OpenCV
    resize). Non-finite, masked and saturated pixels are ignored. A frame with no usable pixel
    gives NaN levels and flags EMPTY | NAN (no exception).
    """
    a = _as_frame(img).astype(float, copy=False)
    good = np.isfinite(a)
    if mask is not None:
        good &= ~np.asarray(mask, dtype=bool)
    if saturation is not None:
        good &= ~(a >= saturation)
    fl = Flag.OK
    if not np.all(np.isfinite(a)):
        fl |= Flag.NAN
    if not good.any():
        return Background(np.nan, np.nan, fl | Flag.EMPTY)
    if box_px is None:
        med, rms = _clipped_stats(a[good], nsigma_clip, max_iter)
        return Background(med, rms, fl)
    box = int(box_px)
    if box < 4:
        raise ValueError(f"box_px must be >= 4, got {box_px!r}")
    h, w = a.shape
    ny, nx = max(1, int(round(h / box))), max(1, int(round(w / box)))
    ye = np.linspace(0, h, ny + 1).astype(int)
    xe = np.linspace(0, w, nx + 1).astype(int)
    lev = np.full((ny, nx), np.nan)
    rms = np.full((ny, nx), np.nan)
    for j in range(ny):
        for i in range(nx):
            g = good[ye[j] : ye[j + 1], xe[i] : xe[i + 1]]
            vals = a[ye[j] : ye[j + 1], xe[i] : xe[i + 1]][g]
            if vals.size >= 8:
                lev[j, i], rms[j, i] = _clipped_stats(vals, nsigma_clip, max_iter)
    # fill empty tiles with the global estimate
    gmed, grms = _clipped_stats(a[good], nsigma_clip, max_iter)
    lev = np.where(np.isfinite(lev), lev, gmed)
    rms = np.where(np.isfinite(rms), rms, grms)
    lev_map = cv2.resize(lev.astype(np.float64), (w, h), interpolation=cv2.INTER_LINEAR)
    rms_map = cv2.resize(rms.astype(np.float64), (w, h), interpolation=cv2.INTER_LINEAR)
    return Background(lev_map, rms_map, fl)


@dataclass(frozen=True)
class Detections:
    """Sources found by `detect`, as arrays of shape (N,), plus the label image.

    u, v: flux-weighted centre of the source's pixels above threshold (a first estimate only;
    run a centroider on ROIs for accuracy). peak_u, peak_v: brightest pixel. peak, flux: above
    background (DN). frame_flags: EMPTY (nothing found / nothing usable), NAN, SATURATED.
    """

    u: np.ndarray
    v: np.ndarray
    peak_u: np.ndarray
    peak_v: np.ndarray
    peak: np.ndarray
    flux: np.ndarray
    npix: np.ndarray
    label: np.ndarray
    flags: np.ndarray
    labels: np.ndarray
    background: Background
    threshold: float | np.ndarray
    frame_flags: Flag

    def __len__(self) -> int:
        return int(self.u.shape[0])


def _local_maxima(a: np.ndarray) -> np.ndarray:
    """Pixels >= all 8 neighbours (a is float32 with -inf for unusable pixels)."""
    k = np.ones((3, 3), np.uint8)
    dil = cv2.dilate(a, k, borderType=cv2.BORDER_CONSTANT, borderValue=-np.inf)
    return (a >= dil) & np.isfinite(a)


def _separated(img: np.ndarray, bgl: np.ndarray, rms: np.ndarray, p1, p2, dip_nsigma: float,
               dip_fraction: float, noise: NoiseModel | None) -> bool:
    """True if the straight line between peaks p1 (brighter) and p2 dips significantly."""
    (v1, u1), (v2, u2) = p1, p2
    nsamp = int(max(abs(v2 - v1), abs(u2 - u1))) * 2 + 1
    t = np.linspace(0.0, 1.0, nsamp + 1)
    lv = np.rint(v1 + t * (v2 - v1)).astype(int)
    lu = np.rint(u1 + t * (u2 - u1)).astype(int)
    line = img[lv, lu] - bgl[lv, lu]
    if not np.all(np.isfinite(line)):
        return True
    k = int(np.argmin(line))
    h2 = img[v2, u2] - bgl[v2, u2]

    def var(val, bg_rms):  # pixel variance: background noise + signal shot noise
        k_gain = 1.0 if noise is None else noise.gain_dn_per_e  # K = 1 DN/e- without a NoiseModel
        return bg_rms**2 + k_gain * max(val, 0.0)

    sd = math.sqrt(var(h2, rms[v2, u2]) + var(line[k], rms[lv[k], lu[k]]))
    return (h2 - line[k]) > max(dip_nsigma * sd, dip_fraction * h2)


def detect(
    img,
    *,
    threshold_sigma: float = 5.0,
    min_area_px: int = 3,
    background: Background | float | None = None,
    box_px: int | None = None,
    saturation: float | None = None,
    mask=None,
    deblend: bool = True,
    dip_nsigma: float = 3.0,
    dip_fraction: float = 0.03,
    noise: NoiseModel | None = None,
) -> Detections:
    """Find spots: pixels above background + ``threshold_sigma`` * rms, 8-connected components
    of at least ``min_area_px`` pixels. With ``deblend``, a component holding several local maxima
    that are separated by a significant dip (``dip_nsigma`` times its noise, and at least
    ``dip_fraction`` of the fainter peak's height) is split into one source per peak, each
    flagged BLENDED. ``noise`` (optional) sets the shot-noise part of the dip test (default K = 1
    DN/e-).

    Per-source flags: SATURATED (a pixel >= ``saturation``), EDGE (touches the frame border or a
    non-finite/masked pixel region), NAN (non-finite pixels adjacent), BLENDED.
    """
    a = _as_frame(img)
    if saturation is None and np.issubdtype(a.dtype, np.integer):
        saturation = float(np.iinfo(a.dtype).max)
    a = a.astype(float, copy=False)
    h, w = a.shape
    finite = np.isfinite(a)
    usable = finite.copy()
    if mask is not None:
        usable &= ~np.asarray(mask, dtype=bool)
    sat = usable & (a >= saturation) if saturation is not None else np.zeros_like(usable)
    nan_flag = Flag.OK if finite.all() else Flag.NAN
    if not usable.any():
        return _empty_detections(a.shape, Background(np.nan, np.nan, nan_flag | Flag.EMPTY), nan_flag | Flag.EMPTY)
    if not np.any(usable & ~sat):
        fl0 = nan_flag | Flag.SATURATED | Flag.EMPTY
        return _empty_detections(a.shape, Background(np.nan, np.nan, fl0), fl0)
    if background is None:
        bg = estimate_background(a, box_px=box_px, mask=mask, saturation=saturation)
    elif isinstance(background, Background):
        bg = background
    else:
        b2 = estimate_background(a, mask=mask, saturation=saturation)
        bg = Background(float(background), b2.rms, b2.flags)
    frame_flags = Flag(bg.flags) | nan_flag
    if not np.all(np.isfinite(np.asarray(bg.level))):
        return _empty_detections(a.shape, bg, frame_flags | Flag.EMPTY)
    if saturation is not None and sat.any():
        frame_flags |= Flag.SATURATED
    bgl = np.broadcast_to(np.asarray(bg.level, dtype=float), a.shape)
    rms = np.broadcast_to(np.asarray(bg.rms, dtype=float), a.shape)
    if not np.all(np.isfinite(rms)) or np.all(rms <= 0):
        # a constant frame (rms 0): nothing can be significant unless saturated
        rms = np.where(np.isfinite(rms) & (rms > 0), rms, np.inf)
    thr = bgl + threshold_sigma * rms
    with np.errstate(invalid="ignore"):
        above = usable & ((a > thr) | sat)
    n_lab, labels, stats, _ = cv2.connectedComponentsWithStats(above.astype(np.uint8), connectivity=8)
    bad_nb = cv2.dilate((~usable).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    af = np.where(usable, a, -np.inf).astype(np.float32)
    lmax = _local_maxima(af) & above
    # saturated plateaus: one peak per plateau (keep the first pixel of each)
    out = {k: [] for k in ("u", "v", "pu", "pv", "peak", "flux", "npix", "label", "flags")}
    keep_lab = np.zeros(n_lab, dtype=bool)
    for lab in range(1, n_lab):
        x0, y0, ww, hh, area = stats[lab]
        if area < min_area_px:
            continue
        keep_lab[lab] = True
        sl = (slice(y0, y0 + hh), slice(x0, x0 + ww))
        comp = labels[sl] == lab
        sub = a[sl]
        d = np.where(comp, sub - bgl[sl], 0.0)
        fl = Flag.OK
        if np.any(comp & sat[sl]):
            fl |= Flag.SATURATED
        if y0 == 0 or x0 == 0 or y0 + hh == h or x0 + ww == w:
            fl |= Flag.EDGE
        if np.any(comp & bad_nb[sl]):
            fl |= Flag.EDGE
            if not finite.all() and np.any(comp & cv2.dilate((~finite[sl]).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)):
                fl |= Flag.NAN
        # peaks in this component, brightest first; saturated plateau pixels are one peak
        pv_, pu_ = np.nonzero(comp & lmax[sl] & ~sat[sl])
        pk = list(zip(pv_ + y0, pu_ + x0))
        if np.any(comp & sat[sl]):
            sv_, su_ = np.nonzero(comp & sat[sl])
            pk = [(int(np.mean(sv_)) + y0, int(np.mean(su_)) + x0)] + pk
            pk = [pk[0]] + [p for p in pk[1:] if abs(p[0] - pk[0][0]) + abs(p[1] - pk[0][1]) > 2]
        if not pk:
            k = int(np.argmax(np.where(comp, sub, -np.inf)))
            pk = [(k // ww + y0, k % ww + x0)]
        pk.sort(key=lambda p: -(a[p] if np.isfinite(a[p]) else -np.inf))
        peaks = [pk[0]]
        if deblend:
            for p in pk[1:]:
                if all(_separated(a, bgl, rms, q, p, dip_nsigma, dip_fraction, noise) for q in peaks):
                    peaks.append(p)
        if len(peaks) == 1:
            yy, xx = np.nonzero(comp)
            wsum = d[yy, xx].sum()
            u = float((d[yy, xx] * (xx + x0)).sum() / wsum) if wsum > 0 else float(peaks[0][1])
            v = float((d[yy, xx] * (yy + y0)).sum() / wsum) if wsum > 0 else float(peaks[0][0])
            members = [(peaks[0], u, v, float(wsum), int(area))]
        else:
            fl |= Flag.BLENDED
            # assign component pixels to the nearest peak (simple Voronoi split)
            yy, xx = np.nonzero(comp)
            pa = np.array(peaks, dtype=float)
            dist = (yy[:, None] + y0 - pa[None, :, 0]) ** 2 + (xx[:, None] + x0 - pa[None, :, 1]) ** 2
            owner = np.argmin(dist, axis=1)
            members = []
            for j, p in enumerate(peaks):
                sel = owner == j
                dv_ = d[yy[sel], xx[sel]]
                ws = dv_.sum()
                u = float((dv_ * (xx[sel] + x0)).sum() / ws) if ws > 0 else float(p[1])
                v = float((dv_ * (yy[sel] + y0)).sum() / ws) if ws > 0 else float(p[0])
                members.append((p, u, v, float(ws), int(sel.sum())))
        for (pv0, pu0), u, v, fx, npx in members:
            out["u"].append(u)
            out["v"].append(v)
            out["pu"].append(int(pu0))
            out["pv"].append(int(pv0))
            out["peak"].append(float(a[pv0, pu0] - bgl[pv0, pu0]))
            out["flux"].append(fx)
            out["npix"].append(npx)
            out["label"].append(lab)
            out["flags"].append(int(fl))
    labels = np.where(keep_lab[labels], labels, 0)
    if not out["u"]:
        frame_flags |= Flag.EMPTY
    if not finite.all():
        frame_flags |= Flag.NAN
    return Detections(
        u=np.array(out["u"], dtype=float),
        v=np.array(out["v"], dtype=float),
        peak_u=np.array(out["pu"], dtype=int),
        peak_v=np.array(out["pv"], dtype=int),
        peak=np.array(out["peak"], dtype=float),
        flux=np.array(out["flux"], dtype=float),
        npix=np.array(out["npix"], dtype=int),
        label=np.array(out["label"], dtype=int),
        flags=np.array(out["flags"], dtype=np.int64),
        labels=labels,
        background=bg,
        threshold=thr if np.ndim(bg.level) else float(np.asarray(thr).flat[0]),
        frame_flags=frame_flags,
    )


def _empty_detections(shape, bg: Background, frame_flags: Flag) -> Detections:
    z = np.zeros(0)
    zi = np.zeros(0, dtype=int)
    return Detections(
        z, z, zi, zi, z, z, zi, zi, np.zeros(0, dtype=np.int64), np.zeros(shape, dtype=np.int32), bg, np.nan, frame_flags
    )


@dataclass(frozen=True)
class Rois:
    """Fixed-size cut-outs. ``stack[n, j, i]`` is frame pixel (u0[n] + i, v0[n] + j); pixels
    outside the frame are NaN and set the EDGE flag."""

    stack: np.ndarray  # (N, size, size)
    origin_uv: np.ndarray  # (N, 2) frame coordinates (u0, v0) of stack[:, 0, 0]
    flags: np.ndarray  # (N,) int Flag bits

    def __len__(self) -> int:
        return int(self.stack.shape[0])


def extract_rois(img, u, v, size_px: int = 9, *, fill: float = np.nan) -> Rois:
    """Cut ``size_px`` x ``size_px`` ROIs centred on the pixels nearest to (u, v).

    Vectorised (one fancy-indexing gather); ``size_px`` must be odd. Parts of a ROI outside the
    frame are filled with ``fill`` (NaN: ignored by the centroiders) and flagged EDGE.
    """
    a = _as_frame(img)
    size = int(size_px)
    if size < 3 or size % 2 == 0:
        raise ValueError(f"size_px must be an odd integer >= 3, got {size_px!r}")
    u = np.atleast_1d(np.asarray(u, dtype=float))
    v = np.atleast_1d(np.asarray(v, dtype=float))
    if u.shape != v.shape or u.ndim != 1:
        raise ValueError(f"u and v must be 1-D and of equal length, got shapes {u.shape}, {v.shape}")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(v))):
        raise ValueError("u and v must be finite")
    h, w = a.shape
    r = size // 2
    cu = np.floor(u + 0.5).astype(np.int64)
    cv = np.floor(v + 0.5).astype(np.int64)
    off = np.arange(-r, r + 1)
    rr = cv[:, None, None] + off[None, :, None]
    cc = cu[:, None, None] + off[None, None, :]
    inside = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
    stack = a[np.clip(rr, 0, h - 1), np.clip(cc, 0, w - 1)].astype(float)
    cut = ~inside.all(axis=(1, 2))
    if cut.any():
        stack = np.where(inside, stack, fill)
    fl = np.where(cut, int(Flag.EDGE), 0).astype(np.int64)
    origin = np.stack([cu - r, cv - r], axis=1).astype(float)
    return Rois(stack, origin, fl)


def find_spots(
    img,
    *,
    method: str = "gauss",
    roi_px: int | None = None,
    sigma_px: float | None = None,
    noise: NoiseModel | None = None,
    threshold_sigma: float = 5.0,
    min_area_px: int = 3,
    saturation: float | None = None,
    box_px: int | None = None,
    mask=None,
    deblend_fit: bool = True,
    **centroid_kwargs,
) -> tuple[CentroidBatch, Detections]:
    """Detect all spots in a frame and centroid each on its own ROI (one batched call).

    ``roi_px`` defaults to the odd size covering +-4 sigma (``sigma_px`` or 1.5 px), at least 7.
    Returned positions are in frame coordinates. Flags: from detection (BLENDED, SATURATED, EDGE),
    from ROI extraction (EDGE), from the centroider; also BLENDED when another detection's peak
    lies inside a spot's ROI. With ``deblend_fit`` and a Gaussian method, each group of blended
    spots (up to 8) is then refitted jointly by `centroid_gauss_multi` (they keep BLENDED).
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {sorted(METHODS)}, got {method!r}")
    a = _as_frame(img)
    det = detect(
        a, threshold_sigma=threshold_sigma, min_area_px=min_area_px, saturation=saturation, box_px=box_px,
        mask=mask, noise=noise,
    )
    s_guess = 1.5 if sigma_px is None else float(sigma_px)
    size = roi_px if roi_px is not None else max(7, 2 * int(math.ceil(4.0 * s_guess)) + 1)
    n = len(det)
    if n == 0:
        z = np.zeros(0)
        return CentroidBatch(z, z, z, z, z, z, np.zeros(0, dtype=np.int64), method), det
    rois = extract_rois(a, det.peak_u.astype(float), det.peak_v.astype(float), size)
    fl = rois.flags | det.flags
    # neighbours inside the ROI
    r = size // 2
    du = np.abs(det.peak_u[:, None] - det.peak_u[None, :])
    dv = np.abs(det.peak_v[:, None] - det.peak_v[None, :])
    close = (du <= r) & (dv <= r)
    np.fill_diagonal(close, False)
    fl[close.any(axis=1)] |= Flag.BLENDED
    kw = dict(centroid_kwargs)
    if method in ("gauss", "gauss_lsq") and sigma_px is not None:
        kw.setdefault("sigma_px", sigma_px)
    if method == "gauss" and sigma_px is None:
        kw.setdefault("fit_sigma", True)
    if method == "wcom" and sigma_px is not None:
        kw.setdefault("window_sigma_px", sigma_px)
    roi_mask = None
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        roi_mask = extract_rois(m.astype(float), det.peak_u.astype(float), det.peak_v.astype(float), size, fill=1.0).stack > 0.5
    res = METHODS[method](
        rois.stack,
        noise=noise,
        saturation=saturation,
        flags=fl,
        origin_uv=rois.origin_uv,
        mask=roi_mask,
        **kw,
    )
    # NaN fill outside the frame is not a data defect: keep EDGE, drop the NAN it caused
    only_outside = (rois.flags & Flag.EDGE) != 0
    if only_outside.any() and np.all(np.isfinite(a)):
        res.flags[only_outside] &= ~int(Flag.NAN)
    if deblend_fit and method in ("gauss", "gauss_lsq"):
        _refit_blends(a, det, res, fl, close, r, sigma_px, noise, saturation, mask)
    return res, det


def _refit_blends(a, det, res: CentroidBatch, pre_flags, close, r, sigma_px, noise, saturation, mask, max_group: int = 8):
    """Replace the single-spot fits of blended groups (spots whose ROIs hold another spot's peak)
    by one joint multi-Gaussian fit per group. The BLENDED flag stays."""
    from scipy.sparse.csgraph import connected_components

    from .centroid import centroid_gauss_multi

    n_grp, grp = connected_components(close, directed=False)
    h, w = a.shape
    for g in range(n_grp):
        idx = np.flatnonzero(grp == g)
        if len(idx) < 2 or len(idx) > max_group:
            continue
        u0 = max(int(det.peak_u[idx].min()) - r, 0)
        v0 = max(int(det.peak_v[idx].min()) - r, 0)
        u1 = min(int(det.peak_u[idx].max()) + r + 1, w)
        v1 = min(int(det.peak_v[idx].max()) + r + 1, h)
        sub = a[v0:v1, u0:u1]
        sub_mask = None if mask is None else np.asarray(mask, dtype=bool)[v0:v1, u0:u1]
        start = np.stack([det.peak_u[idx] - u0, det.peak_v[idx] - v0], axis=1).astype(float)
        good_prev = np.isfinite(res.u[idx]) & np.isfinite(res.flux[idx])
        start[good_prev] = np.stack([res.u[idx] - u0, res.v[idx] - v0], axis=1)[good_prev]
        flux0 = np.where(good_prev & (res.flux[idx] > 0), res.flux[idx], np.maximum(det.flux[idx], 1e-6))
        m = centroid_gauss_multi(
            sub, start, sigma_px=sigma_px if sigma_px is not None else 1.0, fit_sigma=sigma_px is None,
            flux0=flux0, noise=noise, saturation=saturation, mask=sub_mask, origin_uv=(u0, v0),
        )
        for j, i in enumerate(idx):
            res.u[i], res.v[i] = m.u[j], m.v[j]
            res.sigma_u[i], res.sigma_v[i] = m.sigma_u[j], m.sigma_v[j]
            res.flux[i], res.background[i] = m.flux[j], m.background[j]
            # detection / frame-edge flags stay; the single-spot fit's own flags are replaced
            res.flags[i] = int(pre_flags[i]) | int(m.flags[j]) | int(Flag.BLENDED)
