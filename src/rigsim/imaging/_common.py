"""Shared input handling for the centroiders: shape checks, masks, per-ROI background and noise,
quality flags that do not depend on the method. Internal module."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .result import CentroidBatch, Flag, NoiseModel

MAD_TO_SD = 1.482602218505602
#: pixels with |value| above this are treated like non-finite ones (no detector gets near it;
#: beyond it squares and sums of pixels overflow float64)
MAX_ABS_PIXEL = 1e30


@dataclass
class Prepared:
    data: np.ndarray  # (N, h, w) float64, bad pixels set to 0
    good: np.ndarray  # (N, h, w) bool: finite, not masked (saturated pixels are *good* here)
    sat: np.ndarray  # (N, h, w) bool: at/above saturation (subset of good)
    bg: np.ndarray  # (N,) background level per ROI (DN)
    bg_sd: np.ndarray  # (N,) background noise sd per ROI (DN)
    flags: np.ndarray  # (N,) int flags so far
    single: bool
    noise: NoiseModel | None
    x: np.ndarray  # (w,) u coordinate of columns
    y: np.ndarray  # (h,) v coordinate of rows
    gain: float = 1.0  # K (DN/e-) of the signal's shot noise when there is no NoiseModel

    @property
    def n(self) -> int:
        return self.data.shape[0]

    def variance(self, expected: np.ndarray, bg: np.ndarray | None = None, idx=None) -> np.ndarray:
        """Pixel variance (DN^2) for expected values ``expected`` (N, h, w) (background included).

        With a NoiseModel: its Poisson + read-noise formula. Without one: the measured
        background variance plus the signal above background as Poisson with gain K = 1 DN/e-.
        """
        if self.noise is not None:
            var = self.noise.variance(expected)
            floor = self.noise.min_variance_dn2
        else:
            sel = slice(None) if idx is None else idx
            b = self.bg[sel] if bg is None else bg
            var = (self.bg_sd[sel] ** 2)[:, None, None] + self.gain * np.maximum(expected - b[:, None, None], 0.0)
            floor = 1e-12 * max(float(np.max(np.abs(self.data), initial=0.0)), 1.0) ** 2  # data <= 1e30
        return np.maximum(var, floor)

    def variance_flat(self, expected: np.ndarray, roi: np.ndarray) -> np.ndarray:
        """Like `variance` for a flat array of pixels belonging to ROIs ``roi``."""
        if self.noise is not None:
            return np.maximum(self.noise.variance(expected), self.noise.min_variance_dn2)
        var = self.bg_sd[roi] ** 2 + self.gain * np.maximum(expected - self.bg[roi], 0.0)
        return np.maximum(var, 1e-300)


def as_stack(img) -> tuple[np.ndarray, bool]:
    a = np.asarray(img)
    if a.dtype == object or not (np.issubdtype(a.dtype, np.number) or a.dtype == bool):
        raise TypeError(f"image must be a numeric array, got dtype {a.dtype}")
    if np.iscomplexobj(a):
        raise TypeError("image must be real, got a complex array")
    if a.ndim == 2:
        return a[None], True
    if a.ndim == 3:
        return a, False
    raise ValueError(f"image must have shape (h, w) or (N, h, w), got shape {a.shape}")


def _per_roi(value, n: int, name: str) -> np.ndarray | None:
    if value is None:
        return None
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        return np.full(n, float(a))
    if a.shape != (n,):
        raise ValueError(f"{name} must be a scalar or have shape ({n},), got shape {a.shape}")
    return a


def prepare(
    img,
    *,
    mask=None,
    saturation=None,
    background=None,
    noise: NoiseModel | None = None,
    flags=None,
    background_sd=None,
    gain: float | None = None,
) -> Prepared:
    """The stack, its usable and saturated pixels, each ROI's background and its noise. Without a
    ``noise`` model, ``background_sd`` (scalar or per ROI, DN) replaces the ring's measured noise and
    ``gain`` (K, DN/e-) is the signal's shot-noise gain (e.g. from a position-dependent sky map and
    a known or measured gain)."""
    stack, single = as_stack(img)
    n, h, w = stack.shape
    if noise is not None and not isinstance(noise, NoiseModel):
        raise TypeError(f"noise must be a rigsim.imaging.NoiseModel or None, got {type(noise).__name__}")
    if saturation is None and np.issubdtype(stack.dtype, np.integer):
        saturation = float(np.iinfo(stack.dtype).max)
    data = stack.astype(float, copy=False)
    with np.errstate(invalid="ignore"):
        finite = np.abs(data) <= MAX_ABS_PIXEL  # False for NaN and inf as well
    all_finite = bool(finite.all())
    good = finite if (all_finite and mask is None) else finite.copy()
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != stack.shape[-m.ndim :] and m.shape != stack.shape:
            raise ValueError(f"mask shape {m.shape} does not match image shape {np.asarray(img).shape}")
        good &= ~np.broadcast_to(m, stack.shape)
    fl = np.zeros(n, dtype=np.int64)
    fin = _per_roi(flags, n, "flags")
    if fin is not None:
        fl |= fin.astype(np.int64)
    fl[np.any(~finite, axis=(1, 2))] |= Flag.NAN
    if saturation is not None:
        sat = good & (data >= float(saturation))
    else:
        sat = np.zeros_like(good)
    fl[np.any(sat, axis=(1, 2))] |= Flag.SATURATED
    if not good.all():
        data = np.where(good, data, 0.0)

    # background and its noise from the outer ring of each ROI (robust: median, MAD)
    ring = np.zeros((h, w), dtype=bool)
    if h >= 3 and w >= 3:
        ring[0, :] = ring[-1, :] = ring[:, 0] = ring[:, -1] = True
    med = np.full(n, np.nan)
    mad = np.full(n, np.nan)
    sd_given = None if noise is not None else _per_roi(background_sd, n, "background_sd")
    bg_given = _per_roi(background, n, "background")
    need_mad = noise is None and sd_given is None
    if (bg_given is None or need_mad) and ring.any():
        ring_ok = good[:, ring] & ~sat[:, ring]
        rv = data[:, ring]  # (N, nring)
        full = ring_ok.all(axis=1)
        if full.any():  # every ring pixel usable: one vectorised median
            med[full] = np.median(rv[full], axis=1)
            if need_mad:
                mad[full] = np.median(np.abs(rv[full] - med[full, None]), axis=1)
        for i in np.flatnonzero(~full & ring_ok.any(axis=1)):
            r = rv[i][ring_ok[i]]
            med[i] = np.median(r)
            mad[i] = np.median(np.abs(r - med[i]))
    bg = med if bg_given is None else bg_given
    if noise is not None:
        # the noise model is the stated truth about the detector: use it for the background noise
        bg_sd = np.sqrt(noise.variance(np.where(np.isfinite(bg), bg, 0.0)))
    elif sd_given is not None:
        bg_sd = sd_given.copy()
    else:
        bg_sd = MAD_TO_SD * mad
    # no usable ring (tiny ROI, or ring all bad): fall back to robust stats of all good pixels
    bad_bg = ~np.isfinite(bg) | ~np.isfinite(bg_sd)
    for i in np.flatnonzero(bad_bg):
        vals = data[i][good[i] & ~sat[i]]
        if vals.size == 0:
            continue
        if not np.isfinite(bg[i]):
            bg[i] = np.percentile(vals, 25.0)
        if not np.isfinite(bg_sd[i]):
            bg_sd[i] = MAD_TO_SD * np.median(np.abs(vals - np.median(vals)))
    x = np.arange(w, dtype=float)
    y = np.arange(h, dtype=float)
    # nothing usable at all
    none_good = ~np.any(good, axis=(1, 2))
    fl[none_good] |= Flag.EMPTY | Flag.INVALID
    all_sat = np.any(good, axis=(1, 2)) & ~np.any(good & ~sat, axis=(1, 2))
    fl[all_sat] |= Flag.INVALID
    if h < 3 or w < 3:
        fl |= Flag.EMPTY | Flag.INVALID
    k = 1.0 if gain is None else float(gain)
    if not (np.isfinite(k) and k > 0):
        raise ValueError(f"gain must be finite and > 0 DN/e-, got {gain!r}")
    return Prepared(data, good, sat, bg, bg_sd, fl, single, noise, x, y, k)


def secondary_peak_flags(p: Prepared, resid: np.ndarray, nsigma: float = 5.0) -> np.ndarray:
    """BLENDED where a ROI has a significant second local maximum separated from the main one
    by a significant dip. ``resid`` is the background-subtracted data (N, h, w)."""
    n, h, w = resid.shape
    out = np.zeros(n, dtype=bool)
    if h < 3 or w < 3 or n == 0:
        return out
    if p.good.all() and not p.sat.any():
        a = resid.astype(np.float32)
    else:
        a = np.where(p.good & ~p.sat, resid, -np.inf).astype(np.float32)
    # 3x3 maximum filter (separable; the array border acts as -inf)
    m = a.copy()
    np.maximum(m[:, :, 1:], a[:, :, :-1], out=m[:, :, 1:])
    np.maximum(m[:, :, :-1], a[:, :, 1:], out=m[:, :, :-1])
    m2 = m.copy()
    np.maximum(m2[:, 1:, :], m[:, :-1, :], out=m2[:, 1:, :])
    np.maximum(m2[:, :-1, :], m[:, 1:, :], out=m2[:, :-1, :])
    # local maxima are sparse: test their significance only there
    ni, vi, ui = np.nonzero((a >= m2) & (a > 0))
    vals = a[ni, vi, ui].astype(float)
    var_pk = p.variance_flat(vals + p.bg[ni], ni)
    sig = vals * vals > (nsigma * nsigma) * var_pk
    cnt = np.bincount(ni[sig], minlength=n)
    cand = np.flatnonzero(cnt >= 2)
    signif = np.zeros(a.shape, dtype=bool)
    signif[ni[sig], vi[sig], ui[sig]] = True
    sd = np.sqrt(p.variance(resid[cand] + p.bg[cand, None, None], idx=cand)) if cand.size else None
    for ci, i in enumerate(cand):
        vv, uu = np.nonzero(signif[i])
        hts = a[i, vv, uu]
        order = np.argsort(hts)[::-1]
        v1, u1 = vv[order[0]], uu[order[0]]
        for k in order[1:]:
            v2, u2 = vv[k], uu[k]
            nsamp = int(max(abs(v2 - v1), abs(u2 - u1))) * 2 + 1
            t = np.linspace(0.0, 1.0, nsamp + 1)
            lv = np.rint(v1 + t * (v2 - v1)).astype(int)
            lu = np.rint(u1 + t * (u2 - u1)).astype(int)
            line = resid[i, lv, lu]
            ok = p.good[i, lv, lu]
            if not np.all(ok):
                continue
            saddle = line.min()
            h2 = float(a[i, v2, u2])
            dip_sd = np.sqrt(sd[ci, v2, u2] ** 2 + sd[ci, lv[np.argmin(line)], lu[np.argmin(line)]] ** 2)
            if h2 - saddle > max(3.0 * dip_sd, 0.1 * h2):
                out[i] = True
                break
    return out


def edge_flags(p: Prepared, u: np.ndarray, v: np.ndarray, margin_px: np.ndarray) -> np.ndarray:
    """EDGE where the centre is within ``margin_px`` of the array's outer pixel boundary, or the
    brightest good pixel lies on the border row/column."""
    n, h, w = p.data.shape
    lo_u, hi_u = -0.5 + margin_px, (w - 0.5) - margin_px
    lo_v, hi_v = -0.5 + margin_px, (h - 0.5) - margin_px
    with np.errstate(invalid="ignore"):
        near = (u < lo_u) | (u > hi_u) | (v < lo_v) | (v > hi_v)
    a = np.where(p.good, p.data, -np.inf).reshape(n, -1)
    k = np.argmax(a, axis=1)
    pv, pu = np.divmod(k, w)
    on_border = (pv == 0) | (pv == h - 1) | (pu == 0) | (pu == w - 1)
    return near | on_border


def finish(
    p: Prepared,
    method: str,
    u,
    v,
    su,
    sv,
    flux,
    bg,
    flags,
    origin_uv=None,
    extra: dict | None = None,
):
    """Apply INVALID -> NaN, origin shift, and return a Centroid or a CentroidBatch."""
    n = p.n
    u = np.asarray(u, dtype=float).copy()
    v = np.asarray(v, dtype=float).copy()
    su = np.asarray(su, dtype=float).copy()
    sv = np.asarray(sv, dtype=float).copy()
    flags = np.asarray(flags, dtype=np.int64).copy()
    h, w = p.data.shape[1:]
    with np.errstate(invalid="ignore"):
        outside = ~((u >= -0.5) & (u <= w - 0.5) & (v >= -0.5) & (v <= h - 0.5))
    nonfinite = ~(np.isfinite(u) & np.isfinite(v) & np.isfinite(su) & np.isfinite(sv))
    flags[outside | nonfinite] |= Flag.INVALID
    inv = (flags & Flag.INVALID) != 0
    u[inv] = v[inv] = su[inv] = sv[inv] = np.nan
    if origin_uv is not None:
        o = np.asarray(origin_uv, dtype=float)
        o = np.broadcast_to(o, (n, 2))
        u = u + o[:, 0]
        v = v + o[:, 1]
    batch = CentroidBatch(
        u=u,
        v=v,
        sigma_u=su,
        sigma_v=sv,
        flux=np.asarray(flux, dtype=float),
        background=np.asarray(bg, dtype=float),
        flags=flags,
        method=method,
        extra=extra or {},
    )
    if p.single:
        return batch[0]
    return batch


def trivial_result(p: Prepared, method: str, origin_uv=None):
    """Result for inputs with nothing to measure (N = 0, or ROIs smaller than 3 x 3)."""
    nan = np.full(p.n, np.nan)
    return finish(p, method, nan, nan, nan, nan, nan, nan, p.flags | Flag.INVALID | Flag.EMPTY, origin_uv)
