"""Spot centroiders. Each takes one ROI (h, w) -> `Centroid`, or a stack (N, h, w) ->
`CentroidBatch`, and returns positions (u, v) in px in the ROI's own coordinates (pixel (0, 0)'s
centre at (0, 0)), plus ``origin_uv`` if given, with 1-sigma uncertainties and `Flag` bits.

* `centroid_tcom`: thresholded centre of mass (seed 003's "带阈值的质心算法").
* `centroid_tcom_peak`: the same over the brightest blob only (a ghost beside the spot is left out).
* `centroid_wcom`: iterative Gaussian-windowed centre of mass (as SExtractor/sep ``winpos``).
* `centroid_gauss`: weighted least-squares fit of a pixel-integrated Gaussian, vectorised
  Gauss–Newton over the batch; attains the Cramér–Rao bound.
* `centroid_gauss_lsq`: the same model fitted per spot with scipy.optimize.least_squares; can
  also fit an axis-aligned elliptical PSF (sigma_u != sigma_v). Slow; for single spots.

Common keyword arguments
------------------------
background : None, float or (N,) array
    Background level (DN). None: median of the ROI's outer ring of pixels.
noise : NoiseModel or None
    Pixel noise of the bias-subtracted frame. None: background noise is measured (MAD of the
    ring) and the signal is assumed Poisson with gain K = 1 DN/e-.
saturation : float or None
    Pixels at or above it are flagged SATURATED (and ignored by the Gaussian fits). For integer
    arrays None means the dtype's maximum.
mask : bool array, True = ignore the pixel. Non-finite pixels are always ignored (flag NAN).
flags : int or (N,) int array of Flag bits to carry in (e.g. EDGE from `extract_rois`).
origin_uv : (2,) or (N, 2) offset added to the returned positions (ROI origin in the frame).
min_snr : flux / sigma_flux below which FAINT is set.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import erf

from ._common import (
    Prepared,
    edge_flags,
    finish,
    prepare,
    secondary_peak_flags,
    trivial_result,
)
from .result import Centroid, CentroidBatch, Flag, NoiseModel

__all__ = [
    "centroid_tcom",
    "centroid_tcom_peak",
    "centroid_wcom",
    "centroid_gauss",
    "centroid_gauss_lsq",
    "centroid_gauss_multi",
    "centroid",
    "METHODS",
]

_SQRT2 = math.sqrt(2.0)
_MIN_WINDOW_PX = 0.8
_INV_SQRT2PI = 1.0 / math.sqrt(2.0 * math.pi)


def _peak_index(p: Prepared, d: np.ndarray):
    n, h, w = d.shape
    a = np.where(p.good, d, -np.inf).reshape(n, -1)
    k = np.argmax(a, axis=1)
    return np.divmod(k, w)  # (pv, pu)


def _peak_region(p: Prepared, above: np.ndarray) -> np.ndarray:
    """The pixels of ``above`` (n, h, w) 8-connected to each ROI's brightest pixel among them."""
    from scipy import ndimage

    n = above.shape[0]
    out = np.zeros_like(above)
    k = np.argmax(np.where(above, p.data, -np.inf).reshape(n, -1), axis=1)
    for i in np.flatnonzero(above.reshape(n, -1).any(axis=1)):
        lab, _ = ndimage.label(above[i], structure=np.ones((3, 3), bool))
        out[i] = lab == lab.flat[k[i]]
    return out


def _threshold_moments(p: Prepared, thr: np.ndarray, mode: str, region: str = "roi"):
    """Thresholded first moments. Returns u, v, W (sum of weights), var_u, var_v, flux, var_flux, npix."""
    d = p.data
    above = p.good & (d > thr[:, None, None])
    if region == "peak":
        above = _peak_region(p, above)
    if mode == "subtract":
        wgt = np.where(above, d - thr[:, None, None], 0.0)
    elif mode == "mask":
        wgt = np.where(above, d - p.bg[:, None, None], 0.0)
    else:
        raise ValueError(f"mode must be 'subtract' or 'mask', got {mode!r}")
    W = wgt.sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.einsum("nhw,w->n", wgt, p.x) / W
        v = np.einsum("nhw,h->n", wgt, p.y) / W
        var = np.where(above, p.variance(np.where(p.good, d, 0.0)), 0.0)
        dx = p.x[None, None, :] - u[:, None, None]
        dy = p.y[None, :, None] - v[:, None, None]
        var_u = np.sum(var * dx * dx, axis=(1, 2)) / W**2
        var_v = np.sum(var * dy * dy, axis=(1, 2)) / W**2
    flux = np.sum(np.where(above, d - p.bg[:, None, None], 0.0), axis=(1, 2))
    var_flux = np.sum(var, axis=(1, 2))
    return u, v, W, var_u, var_v, flux, var_flux, above.sum(axis=(1, 2))


def centroid_tcom(
    img,
    *,
    threshold=None,
    threshold_sigma: float = 3.0,
    mode: str = "subtract",
    background=None,
    noise: NoiseModel | None = None,
    saturation=None,
    mask=None,
    flags=None,
    origin_uv=None,
    min_snr: float = 5.0,
    edge_margin_px: float = 1.0,
    region: str = "roi",
) -> Centroid | CentroidBatch:
    """Thresholded centre of mass (seed 003: "初始参考点质心采用带阈值的质心算法计算").

    Seed 003 names the method but does not define it; rigsim uses the common definition of the
    star-sensor literature (``mode="subtract"``):

        w_k = I_k - T  if I_k > T  else 0,     u = sum(w_k u_k) / sum(w_k)   (same for v)

    with T = ``threshold`` (DN, absolute) or, if None, T = background + ``threshold_sigma`` *
    background_sd. ``mode="mask"`` instead weights the selected pixels by I_k - background.
    ``region="roi"``: every pixel of the ROI above T counts (no connectivity test). ``"peak"``: only
    the pixels above T 8-connected to the brightest of them — the spot's own blob, without a ghost or
    another spot that the threshold separates from it. sigma_u, sigma_v propagate the pixel noise
    through the weighted mean; they ignore the noise of the threshold and of which pixels pass it
    (measured: within 10 % of the Monte-Carlo scatter for SNR 30-300, sigma = 1 px).
    """
    p = prepare(img, mask=mask, saturation=saturation, background=background, noise=noise, flags=flags)
    n = p.n
    if n == 0 or min(p.data.shape[1:]) < 3:
        return trivial_result(p, "tcom", origin_uv)
    thr_given = None if threshold is None else np.broadcast_to(np.asarray(threshold, dtype=float), (n,))
    if region not in ("roi", "peak"):
        raise ValueError(f"region must be 'roi' or 'peak', got {region!r}")
    thr = p.bg + threshold_sigma * p.bg_sd if thr_given is None else thr_given.astype(float)
    u, v, W, var_u, var_v, flux, var_flux, npix = _threshold_moments(p, thr, mode, region)
    fl = p.flags.copy()
    empty = ~(W > 0) | (npix == 0)
    fl[empty] |= Flag.EMPTY | Flag.INVALID
    with np.errstate(invalid="ignore", divide="ignore"):
        snr = flux / np.sqrt(var_flux)
    fl[~empty & ~(snr >= min_snr)] |= Flag.FAINT
    fl[edge_flags(p, u, v, np.full(n, edge_margin_px))] |= Flag.EDGE
    fl[secondary_peak_flags(p, p.data - p.bg[:, None, None])] |= Flag.BLENDED
    return finish(
        p, "tcom", u, v, np.sqrt(var_u), np.sqrt(var_v), flux, p.bg, fl, origin_uv,
        extra={"threshold": thr, "npix": npix},
    )


def centroid_wcom(
    img,
    *,
    window_sigma_px=None,
    background=None,
    noise: NoiseModel | None = None,
    saturation=None,
    mask=None,
    flags=None,
    origin_uv=None,
    min_snr: float = 5.0,
    max_iter: int = 30,
    tol_px: float = 1e-6,
) -> Centroid | CentroidBatch:
    """Iterative Gaussian-windowed centre of mass.

    Solves  sum_k w_k (u_k - u) (I_k - B) = 0  (same for v) with w_k = exp(-r_k^2 / (2 s^2)),
    r_k the distance of pixel k from (u, v) and s = ``window_sigma_px`` (the PSF sigma is the
    usual choice, >= 0.8 px; None: estimated from the thresholded second moments, >= 1 px).
    Newton iterations start from the thresholded centre of mass. The window is point-sampled, so
    undersampled spots have a phase-dependent bias (S-curve, noise-free, max over phase: 5e-4 px
    for sigma = 1 px with s = 1 px, 0.005 px for sigma = 0.7 px, 0.025 px for sigma = 0.5 px);
    it is not included in sigma_u, sigma_v: use `centroid_gauss` for sigma < 1 px. sigma_u, sigma_v are the delta-method propagation of
    pixel noise through that equation.
    """
    p = prepare(img, mask=mask, saturation=saturation, background=background, noise=noise, flags=flags)
    n = p.n
    if n == 0 or min(p.data.shape[1:]) < 3:
        return trivial_result(p, "wcom", origin_uv)
    d = p.data - p.bg[:, None, None]
    d = np.where(p.good, d, 0.0)
    thr = p.bg + 3.0 * p.bg_sd
    u, v, W, _, _, tflux, tvar_flux, _ = _threshold_moments(p, thr, "subtract")
    fl = p.flags.copy()
    start_bad = ~(np.isfinite(u) & np.isfinite(v))
    pv, pu = _peak_index(p, d)
    u = np.where(start_bad, pu.astype(float), u)
    v = np.where(start_bad, pv.astype(float), v)
    if window_sigma_px is None:
        # second moments of the thresholded light, minus the pixel box (1/12)
        above = p.good & (p.data > thr[:, None, None])
        wgt = np.where(above, p.data - thr[:, None, None], 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            dx = p.x[None, None, :] - u[:, None, None]
            dy = p.y[None, :, None] - v[:, None, None]
            m2 = np.sum(wgt * (dx * dx + dy * dy), axis=(1, 2)) / (2.0 * W)
        # thresholding truncates the wings; the factor compensates roughly for a Gaussian
        s = np.sqrt(np.clip(1.3 * m2 - 1.0 / 12.0, 1.0, None))
        s = np.where(np.isfinite(s), s, 1.0)
    else:
        s = np.broadcast_to(np.asarray(window_sigma_px, dtype=float), (n,)).copy()
        if np.any(~(s >= _MIN_WINDOW_PX)) or np.any(~np.isfinite(s)):
            raise ValueError(
                f"window_sigma_px must be finite and >= {_MIN_WINDOW_PX} px (narrower windows are "
                f"undersampled by the pixel grid: S-curve bias up to 0.2 px), got {window_sigma_px!r}"
            )
    s2 = (s * s)[:, None, None]
    it = np.zeros(n, dtype=int)
    active = np.ones(n, dtype=bool)
    gu = gv = du_den = dv_den = None
    for k in range(max_iter):
        dx = p.x[None, None, :] - u[:, None, None]
        dy = p.y[None, :, None] - v[:, None, None]
        wgt = np.exp(-(dx * dx + dy * dy) / (2.0 * s2)) * p.good
        wd = wgt * d
        gu = np.sum(wd * dx, axis=(1, 2))
        gv = np.sum(wd * dy, axis=(1, 2))
        # derivatives of g_u w.r.t. u and of g_v w.r.t. v (cross terms are ~0 near the solution)
        du_den = np.sum(wd * (dx * dx / s2 - 1.0), axis=(1, 2))
        dv_den = np.sum(wd * (dy * dy / s2 - 1.0), axis=(1, 2))
        swd = np.sum(wd, axis=(1, 2))
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):  # a tiny curvature: the step is clipped
            newton_u = -gu / du_den
            newton_v = -gv / dv_den
            # fall back to the SExtractor step (factor 2) where Newton's curvature is not negative
            step_u = np.where(du_den < 0, newton_u, 2.0 * gu / swd)
            step_v = np.where(dv_den < 0, newton_v, 2.0 * gv / swd)
        step_u = np.clip(np.nan_to_num(step_u), -1.0, 1.0)
        step_v = np.clip(np.nan_to_num(step_v), -1.0, 1.0)
        step_u[~active] = 0.0
        step_v[~active] = 0.0
        u = u + step_u
        v = v + step_v
        it += active
        active &= (np.abs(step_u) > tol_px) | (np.abs(step_v) > tol_px)
        if not active.any():
            break
    fl[active] |= Flag.NOT_CONVERGED
    # uncertainty at the solution
    dx = p.x[None, None, :] - u[:, None, None]
    dy = p.y[None, :, None] - v[:, None, None]
    wgt = np.exp(-(dx * dx + dy * dy) / (2.0 * s2)) * p.good
    wd = wgt * d
    var = np.where(p.good, p.variance(np.where(p.good, p.data, 0.0)), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        gu_d = np.sum(wd * (dx * dx / s2 - 1.0), axis=(1, 2))
        gv_d = np.sum(wd * (dy * dy / s2 - 1.0), axis=(1, 2))
        var_u = np.sum((wgt * dx) ** 2 * var, axis=(1, 2)) / gu_d**2
        var_v = np.sum((wgt * dy) ** 2 * var, axis=(1, 2)) / gv_d**2
        flux = np.sum(d, axis=(1, 2))
        # detection SNR from the pixels above background + 3 sigma (as in centroid_tcom): the
        # whole-ROI sum is too noisy to judge faintness
        snr = tflux / np.sqrt(tvar_flux)
    bad = ~(np.sum(wd, axis=(1, 2)) > 0) | ~(gu_d < 0) | ~(gv_d < 0)
    fl[bad] |= Flag.EMPTY | Flag.INVALID
    fl[~bad & ~(snr >= min_snr)] |= Flag.FAINT
    fl[edge_flags(p, u, v, 2.0 * s)] |= Flag.EDGE
    fl[secondary_peak_flags(p, d)] |= Flag.BLENDED
    return finish(
        p, "wcom", u, v, np.sqrt(var_u), np.sqrt(var_v), flux, p.bg, fl, origin_uv,
        extra={"window_sigma_px": s, "n_iter": it},
    )


# ---------------------------------------------------------------- pixel-integrated Gaussian model
def _pix_1d(n: int, c: np.ndarray, s: np.ndarray, need_sigma: bool = True):
    """(N, n) pixel fractions of a 1-D Gaussian, and derivatives w.r.t. centre and sigma
    (the latter None unless ``need_sigma``)."""
    edges = np.arange(n + 1, dtype=float) - 0.5
    inv_s = 1.0 / s[:, None]
    z = (edges[None, :] - c[:, None]) * inv_s
    cdf = erf(z * (1.0 / _SQRT2))
    pdf = np.exp(-0.5 * z * z)
    pdf *= _INV_SQRT2PI
    e = 0.5 * (cdf[:, 1:] - cdf[:, :-1])
    de_dc = (pdf[:, :-1] - pdf[:, 1:]) * inv_s
    de_ds = None
    if need_sigma:
        pz = pdf * z
        de_ds = (pz[:, :-1] - pz[:, 1:]) * inv_s
    return e, de_dc, de_ds


def _gauss_init(p: Prepared, sigma0: np.ndarray):
    """Starting point: COM of the background-subtracted 3x3 around the brightest pixel."""
    n, h, w = p.data.shape
    d = np.where(p.good & ~p.sat, p.data - p.bg[:, None, None], 0.0)
    # brightest pixel of the 3x3 box-smoothed image (interior only): robust to single noisy pixels
    rows = d[:, :, :-2] + d[:, :, 1:-1] + d[:, :, 2:]
    sm = rows[:, :-2, :] + rows[:, 1:-1, :] + rows[:, 2:, :]  # (N, h-2, w-2)
    k = np.argmax(sm.reshape(n, -1), axis=1)
    pv, pu = np.divmod(k, w - 2)
    pv = pv + 1
    pu = pu + 1
    idx = np.arange(n)
    box = np.stack([d[idx, pv + a, pu + b] for a in (-1, 0, 1) for b in (-1, 0, 1)], axis=1)  # (N, 9)
    boxp = np.maximum(box, 0.0)
    bw = boxp.sum(axis=1)
    ob = np.array([-1, -1, -1, 0, 0, 0, 1, 1, 1], dtype=float)
    oa = np.array([-1, 0, 1, -1, 0, 1, -1, 0, 1], dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        u0 = pu + boxp @ oa / bw
        v0 = pv + boxp @ ob / bw
    u0 = np.where(np.isfinite(u0), u0, pu)
    v0 = np.where(np.isfinite(v0), v0, pv)
    # flux: 3x3 sum corrected by the Gaussian's enclosed fraction (robust to wide-ROI noise)
    ex, _, _ = _pix_1d(3, 1.0 + (u0 - pu), sigma0, False)
    ey, _, _ = _pix_1d(3, 1.0 + (v0 - pv), sigma0, False)
    frac = ex.sum(axis=1) * ey.sum(axis=1)
    f0 = np.maximum(box.sum(axis=1) / frac, 1e-6 * np.maximum(p.bg_sd, 1e-12))
    return u0, v0, f0, p.bg.copy()


def _basis_terms(F, fit_sigma):
    """Each parameter's derivative as a sum of separable terms coef * (ybasis[yi] (x) xbasis[xi]).

    y/x basis index: 0 = E, 1 = dE/dcentre, 2 = dE/dsigma, 3 = ones. Parameters: u, v, F, B[, s].
    """
    one = None
    terms = [
        [(F, 0, 1)],  # u
        [(F, 1, 0)],  # v
        [(one, 0, 0)],  # F
        [(one, 3, 3)],  # B
    ]
    if fit_sigma:
        terms.append([(F, 2, 0), (F, 0, 2)])  # s
    return terms


def _normal_equations(wts, wr, F, ex, dex, sex, ey, dey, sey, fit_sigma):
    """J^T W J (N, P, P) and J^T W r (N, P) for the separable model, without building J.

    sum_ij W_ij (a_i b_j)(c_i d_j) = (a*c)^T W (b*d): two small batched matmuls per system.
    """
    n = wts.shape[0]
    yb = [ey, dey, ey if sey is None else sey, np.ones_like(ey)]
    xb = [ex, dex, ex if sex is None else sex, np.ones_like(ex)]
    terms = _basis_terms(F, fit_sigma)
    P = len(terms)
    ypairs: dict = {}
    xpairs: dict = {}
    pair_terms = []
    for a in range(P):
        for b in range(a, P):
            lst = []
            for ca, ya, xa in terms[a]:
                for cb, yb_, xb_ in terms[b]:
                    ky = (min(ya, yb_), max(ya, yb_))
                    kx = (min(xa, xb_), max(xa, xb_))
                    ypairs.setdefault(ky, len(ypairs))
                    xpairs.setdefault(kx, len(xpairs))
                    lst.append((ca, cb, ypairs[ky], xpairs[kx]))
            pair_terms.append((a, b, lst))
    Yp = np.stack([yb[i] * yb[j] for (i, j) in ypairs], axis=1)  # (N, ny, h)
    Xp = np.stack([xb[i] * xb[j] for (i, j) in xpairs], axis=2)  # (N, w, nx)
    M = np.matmul(np.matmul(Yp, wts), Xp)  # (N, ny, nx)
    A = np.empty((n, P, P))
    for a, b, lst in pair_terms:
        acc = 0.0
        for ca, cb, iy, ix in lst:
            c = M[:, iy, ix]
            if ca is not None:
                c = c * ca
            if cb is not None:
                c = c * cb
            acc = acc + c
        A[:, a, b] = acc
        A[:, b, a] = acc
    g = None
    if wr is not None:
        Yg = np.stack(yb, axis=1)  # (N, 4, h)
        Xg = np.stack(xb, axis=2)  # (N, w, 4)
        G = np.matmul(np.matmul(Yg, wr), Xg)  # (N, 4, 4)
        g = np.empty((n, P))
        for a in range(P):
            acc = 0.0
            for ca, ya, xa in terms[a]:
                c = G[:, ya, xa]
                acc = acc + (c if ca is None else c * ca)
            g[:, a] = acc
    return A, g


def _chol(a: np.ndarray):
    """Batched Cholesky factor of small SPD matrices; NaN rows and ok=False where not SPD."""
    n, P, _ = a.shape
    L = np.zeros_like(a)
    ok = np.ones(n, dtype=bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        for j in range(P):
            d = a[:, j, j] - np.sum(L[:, j, :j] ** 2, axis=1)
            ok &= d > 0
            ljj = np.sqrt(np.where(d > 0, d, np.nan))
            L[:, j, j] = ljj
            for i in range(j + 1, P):
                L[:, i, j] = (a[:, i, j] - np.sum(L[:, i, :j] * L[:, j, :j], axis=1)) / ljj
    return L, ok


def _chol_solve(L: np.ndarray, b: np.ndarray) -> np.ndarray:
    n, P = b.shape
    y = np.zeros_like(b)
    with np.errstate(invalid="ignore", divide="ignore"):
        for i in range(P):
            y[:, i] = (b[:, i] - np.sum(L[:, i, :i] * y[:, :i], axis=1)) / L[:, i, i]
        x = np.zeros_like(b)
        for i in range(P - 1, -1, -1):
            x[:, i] = (y[:, i] - np.sum(L[:, i + 1 :, i] * x[:, i + 1 :], axis=1)) / L[:, i, i]
    return x


def _chol_inverse(L: np.ndarray) -> np.ndarray:
    n, P, _ = L.shape
    inv = np.empty_like(L)
    eye = np.eye(P)
    for k in range(P):
        inv[:, :, k] = _chol_solve(L, np.broadcast_to(eye[k], (n, P)).copy())
    return inv


def _solve_spd(A: np.ndarray, g: np.ndarray | None):
    """(solution of A x = g or None, A⁻¹, ok) for a stack of small symmetric matrices: the
    row-by-row Cholesky factorisation tells which are finite and positive definite (ok), LAPACK
    inverts those; the others give NaN."""
    finite = np.isfinite(A).all(axis=(1, 2))
    _, ok = _chol(np.where(finite[:, None, None], A, 0.0))
    ok &= finite
    inv = np.full_like(A, np.nan)
    if ok.any():
        inv[ok] = np.linalg.inv(A[ok])
    x = None if g is None else np.einsum("nij,nj->ni", inv, g)
    return x, inv, ok


def _gauss_newton(p, use, u, v, F, B, s, fit_sigma, valid, max_iter, tol_px):
    """Iteratively reweighted Gauss-Newton on the spots in ``valid``; only unconverged spots are
    carried to the next iteration. Also returns, per spot, the normal matrix J^T W J and the
    chi-square of its last iteration (evaluated before the final step, which is < tol_px)."""
    n, h, w = p.data.shape
    P = 5 if fit_sigma else 4
    n_iter = np.zeros(n, dtype=int)
    converged = np.zeros(n, dtype=bool)
    A_last = np.full((n, P, P), np.nan)
    chi2 = np.full(n, np.nan)
    act = np.flatnonzero(valid)
    for _ in range(max_iter):
        if act.size == 0:
            break
        ua, va, Fa, Ba, sa = u[act], v[act], F[act], B[act], s[act]
        ex, dex, sex = _pix_1d(w, ua, sa, fit_sigma)
        ey, dey, sey = _pix_1d(h, va, sa, fit_sigma)
        mu = Fa[:, None, None] * ey[:, :, None] * ex[:, None, :]
        mu += Ba[:, None, None]
        wts = p.variance(mu, bg=Ba, idx=act)
        np.divide(use[act] if act.size < n else use, wts, out=wts)
        r = (p.data[act] if act.size < n else p.data) - mu
        wr = wts * r
        A, g = _normal_equations(wts, wr, Fa, ex, dex, sex, ey, dey, sey, fit_sigma)
        A_last[act] = A
        chi2[act] = np.einsum("nij,nij->n", wr, r)
        step, _, ok = _solve_spd(A, g)
        step[~ok] = 0.0
        # trust region on position (and sigma) steps
        step[:, 0:2] = np.clip(step[:, 0:2], -1.0, 1.0)
        u[act] = ua + step[:, 0]
        v[act] = va + step[:, 1]
        F[act] = Fa + step[:, 2]
        B[act] = Ba + step[:, 3]
        if fit_sigma:
            s[act] = np.clip(sa + np.clip(step[:, 4], -0.5 * sa, 0.5 * sa), 0.2, float(max(h, w)))
        n_iter[act] += 1
        done = (np.abs(step[:, 0]) < tol_px) & (np.abs(step[:, 1]) < tol_px) & ok
        converged[act[done]] = True
        act = act[~done & ok]
    return u, v, F, B, s, n_iter, converged, A_last, chi2


def centroid_gauss(
    img,
    *,
    sigma_px=None,
    fit_sigma: bool = False,
    background=None,
    noise: NoiseModel | None = None,
    saturation=None,
    mask=None,
    flags=None,
    origin_uv=None,
    min_snr: float = 5.0,
    max_iter: int = 20,
    tol_px: float = 1e-4,
    background_sd=None,
    gain: float | None = None,
) -> Centroid | CentroidBatch:
    """Weighted least-squares fit of a pixel-integrated circular Gaussian (vectorised).

    Model: I_k = F * E_x(u_k; u, s) * E_y(v_k; v, s) + B with E the fraction of a 1-D Gaussian in
    each pixel (erf differences); unknowns u, v, F, B and, with ``fit_sigma``, s. Weights are
    1 / variance of the current *model* (iteratively reweighted), which makes the solution the
    Poisson(+read-noise) maximum-likelihood estimate; sigma_u, sigma_v come from the inverse
    Fisher matrix at the solution, i.e. the CRLB at the fitted parameters. Saturated and
    non-finite pixels are excluded from the fit.

    ``sigma_px`` is the PSF sigma (px): required unless ``fit_sigma`` (then it is the start value,
    default 1.0). ``extra`` holds sigma_px, sigma_flux, chi2_red and n_iter per spot. Without a
    ``noise`` model, ``background_sd`` and ``gain`` set each ROI's noise (see :func:`prepare`).
    """
    p = prepare(img, mask=mask, saturation=saturation, background=background, noise=noise, flags=flags,
                background_sd=background_sd, gain=gain)
    n, h, w = p.data.shape
    if sigma_px is None and not fit_sigma:
        raise ValueError("centroid_gauss needs sigma_px (PSF sigma in px) unless fit_sigma=True")
    s = np.broadcast_to(np.asarray(1.0 if sigma_px is None else sigma_px, dtype=float), (n,)).copy()
    if np.any(~(s > 0)) or np.any(~np.isfinite(s)):
        raise ValueError(f"sigma_px must be finite and > 0, got {sigma_px!r}")
    fl = p.flags.copy()
    if n == 0 or h < 3 or w < 3:
        return trivial_result(p, "gauss", origin_uv)
    P = 5 if fit_sigma else 4
    u, v, F, B = _gauss_init(p, s)
    use = p.good & ~p.sat
    valid0 = (fl & Flag.INVALID) == 0
    u, v, F, B, s, n_iter, converged, A, chi2 = _gauss_newton(
        p, use, u, v, F, B, s, fit_sigma, valid0, max_iter, tol_px
    )
    # covariance = inverse Fisher matrix of the last iteration
    _, cov, ok = _solve_spd(A, None)
    dof = use.sum(axis=(1, 2)) - P
    with np.errstate(invalid="ignore", divide="ignore"):
        chi2_red = chi2 / dof
        su = np.sqrt(cov[:, 0, 0])
        sv = np.sqrt(cov[:, 1, 1])
        sf = np.sqrt(cov[:, 2, 2])
        snr = F / sf
    fl[~converged & ((fl & Flag.INVALID) == 0)] |= Flag.NOT_CONVERGED
    fl[~ok | ~(dof > 0)] |= Flag.INVALID
    fl[~(F > 0)] |= Flag.EMPTY | Flag.INVALID
    fl[~(snr >= min_snr)] |= Flag.FAINT
    with np.errstate(invalid="ignore"):
        fl[chi2_red > 1.0 + 5.0 * np.sqrt(2.0 / np.maximum(dof, 1))] |= Flag.POOR_FIT
    fl[edge_flags(p, u, v, 2.0 * s)] |= Flag.EDGE
    fl[secondary_peak_flags(p, p.data - B[:, None, None])] |= Flag.BLENDED
    return finish(
        p, "gauss", u, v, su, sv, F, B, fl, origin_uv,
        extra={"sigma_px": s, "sigma_flux": sf, "chi2_red": chi2_red, "n_iter": n_iter},
    )


def centroid_gauss_lsq(
    img,
    *,
    sigma_px=None,
    fit_sigma: bool = True,
    elliptical: bool = False,
    background=None,
    noise: NoiseModel | None = None,
    saturation=None,
    mask=None,
    flags=None,
    origin_uv=None,
    min_snr: float = 5.0,
    reweight_iter: int = 4,
) -> Centroid | CentroidBatch:
    """Pixel-integrated Gaussian fitted with scipy.optimize.least_squares, one spot at a time.

    Same model, weights and uncertainty as `centroid_gauss`, plus an axis-aligned elliptical
    PSF (``elliptical=True``: separate sigma_u, sigma_v). The weights are refreshed from the
    model ``reweight_iter`` times (iteratively reweighted least squares). A stack is processed
    with a Python loop: use `centroid_gauss` for batches.
    """
    from scipy.optimize import least_squares

    p = prepare(img, mask=mask, saturation=saturation, background=background, noise=noise, flags=flags)
    n, h, w = p.data.shape
    if sigma_px is None and not fit_sigma and not elliptical:
        raise ValueError("centroid_gauss_lsq needs sigma_px unless fit_sigma or elliptical")
    s0 = np.broadcast_to(np.asarray(1.0 if sigma_px is None else sigma_px, dtype=float), (n,))
    fl = p.flags.copy()
    out = {k: np.full(n, np.nan) for k in ("u", "v", "su", "sv", "F", "B", "sF", "s_u", "s_v", "chi2")}
    if n == 0 or h < 3 or w < 3:
        return trivial_result(p, "gauss_lsq", origin_uv)
    u0, v0, f0, b0 = _gauss_init(p, s0.copy())
    npar_sig = 2 if elliptical else (1 if fit_sigma else 0)
    for i in range(n):
        if fl[i] & Flag.INVALID:
            continue
        use = (p.good[i] & ~p.sat[i]).ravel()
        data = p.data[i].ravel()[use]

        def model_and_jac(th, want_jac=True):
            uu, vv, FF, BB = th[:4]
            if elliptical:
                su_, sv_ = th[4], th[5]
            elif fit_sigma:
                su_ = sv_ = th[4]
            else:
                su_ = sv_ = s0[i]
            ex, dex, sex = _pix_1d(w, np.array([uu]), np.array([su_]))
            ey, dey, sey = _pix_1d(h, np.array([vv]), np.array([sv_]))
            ex, dex, sex, ey, dey, sey = (a[0] for a in (ex, dex, sex, ey, dey, sey))
            outer = np.outer(ey, ex).ravel()[use]
            mu = FF * outer + BB
            if not want_jac:
                return mu, None
            cols = [
                FF * np.outer(ey, dex).ravel()[use],
                FF * np.outer(dey, ex).ravel()[use],
                outer,
                np.ones_like(outer),
            ]
            if elliptical:
                cols += [FF * np.outer(ey, sex).ravel()[use], FF * np.outer(sey, ex).ravel()[use]]
            elif fit_sigma:
                cols += [FF * (np.outer(ey, sex) + np.outer(sey, ex)).ravel()[use]]
            return mu, np.stack(cols, axis=1)

        th = np.array([u0[i], v0[i], f0[i], b0[i]] + [s0[i]] * npar_sig, dtype=float)
        lo = np.array([-0.5, -0.5, -np.inf, -np.inf] + [0.2] * npar_sig)
        hi = np.array([w - 0.5, h - 0.5, np.inf, np.inf] + [float(max(h, w))] * npar_sig)
        th = np.clip(th, lo + 1e-9, hi - 1e-9)
        status_ok = True
        for _ in range(max(1, reweight_iter)):
            mu, _ = model_and_jac(th, want_jac=False)
            var = p.variance(_scatter(mu, use, h, w)[None], bg=np.array([th[3]]), idx=[i])[0].ravel()[use]
            sw = 1.0 / np.sqrt(var)

            def res(t):
                return (model_and_jac(t, want_jac=False)[0] - data) * sw

            def jac(t):
                return model_and_jac(t)[1] * sw[:, None]

            try:
                r = least_squares(res, th, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac")
            except (ValueError, np.linalg.LinAlgError):
                status_ok = False
                break
            th_new = r.x
            moved = np.max(np.abs(th_new[:2] - th[:2]))
            th = th_new
            status_ok = r.status > 0
            if moved < 1e-7:
                break
        mu, Jm = model_and_jac(th)
        var = p.variance(_scatter(mu, use, h, w)[None], bg=np.array([th[3]]), idx=[i])[0].ravel()[use]
        A = (Jm / var[:, None]).T @ Jm
        try:
            cov = np.linalg.inv(A)
        except np.linalg.LinAlgError:
            fl[i] |= Flag.INVALID
            continue
        dof = use.sum() - th.size
        out["u"][i], out["v"][i], out["F"][i], out["B"][i] = th[:4]
        out["su"][i], out["sv"][i], out["sF"][i] = np.sqrt(np.abs(np.diag(cov)[:3]))
        if elliptical:
            out["s_u"][i], out["s_v"][i] = th[4], th[5]
        else:
            out["s_u"][i] = out["s_v"][i] = th[4] if fit_sigma else s0[i]
        out["chi2"][i] = np.sum((data - mu) ** 2 / var) / dof if dof > 0 else np.nan
        if not status_ok:
            fl[i] |= Flag.NOT_CONVERGED
        with np.errstate(divide="ignore", invalid="ignore"):
            snr_i = out["F"][i] / out["sF"][i]
        if not out["F"][i] > 0:
            fl[i] |= Flag.EMPTY | Flag.INVALID
        elif not snr_i >= min_snr:
            fl[i] |= Flag.FAINT
        if dof > 0 and out["chi2"][i] > 1.0 + 5.0 * math.sqrt(2.0 / dof):
            fl[i] |= Flag.POOR_FIT
    margin = 2.0 * np.fmax(out["s_u"], out["s_v"])
    fl[edge_flags(p, out["u"], out["v"], np.where(np.isfinite(margin), margin, 2.0))] |= Flag.EDGE
    bg_fit = np.where(np.isfinite(out["B"]), out["B"], p.bg)
    fl[secondary_peak_flags(p, p.data - bg_fit[:, None, None])] |= Flag.BLENDED
    return finish(
        p, "gauss_lsq", out["u"], out["v"], out["su"], out["sv"], out["F"], out["B"], fl, origin_uv,
        extra={"sigma_u_px": out["s_u"], "sigma_v_px": out["s_v"], "sigma_flux": out["sF"], "chi2_red": out["chi2"]},
    )


def centroid_gauss_multi(
    img,
    uv0,
    *,
    sigma_px=None,
    fit_sigma: bool = False,
    flux0=None,
    background=None,
    noise: NoiseModel | None = None,
    saturation=None,
    mask=None,
    origin_uv=None,
    min_snr: float = 5.0,
    reweight_iter: int = 4,
) -> CentroidBatch:
    """Joint fit of K pixel-integrated Gaussians (shared sigma) plus one background to one image:
    the deblending fit for blended spots. ``uv0`` (K, 2) are start positions in the image's
    coordinates (e.g. the detected peaks). Same weights and uncertainty as `centroid_gauss`
    (scipy least_squares, iteratively reweighted); the returned spots carry BLENDED (K > 1)."""
    from scipy.optimize import least_squares

    p = prepare(img, mask=mask, saturation=saturation, background=background, noise=noise)
    if not p.single:
        raise ValueError("centroid_gauss_multi takes one image of shape (h, w)")
    _, h, w = p.data.shape
    uv0 = np.asarray(uv0, dtype=float).reshape(-1, 2)
    k = uv0.shape[0]
    if sigma_px is None and not fit_sigma:
        raise ValueError("centroid_gauss_multi needs sigma_px unless fit_sigma=True")
    s0 = float(1.0 if sigma_px is None else sigma_px)
    base = int(p.flags[0]) | (int(Flag.BLENDED) if k > 1 else 0)
    nan = np.full(k, np.nan)
    if k == 0:
        z = np.zeros(0)
        return CentroidBatch(z, z, z, z, z, z, np.zeros(0, dtype=np.int64), "gauss_multi")
    if base & Flag.INVALID or h < 3 or w < 3:
        return CentroidBatch(nan, nan.copy(), nan.copy(), nan.copy(), nan.copy(), nan.copy(),
                             np.full(k, base | int(Flag.INVALID), dtype=np.int64), "gauss_multi")
    use = (p.good[0] & ~p.sat[0]).ravel()
    data = p.data[0].ravel()[use]
    b0 = float(p.bg[0])
    if flux0 is None:
        iu = np.clip(np.rint(uv0[:, 0]).astype(int), 0, w - 1)
        iv = np.clip(np.rint(uv0[:, 1]).astype(int), 0, h - 1)
        f0 = np.maximum((p.data[0][iv, iu] - b0) * 2.0 * np.pi * s0 * s0, 1e-6)
    else:
        f0 = np.asarray(flux0, dtype=float).reshape(k)
    npar = 3 * k + 1 + (1 if fit_sigma else 0)

    def model_jac(th, want_jac=True):
        sig = th[-1] if fit_sigma else s0
        mu = np.full(int(use.sum()), th[3 * k])
        cols = []
        dsig = 0.0
        for i in range(k):
            uu, vv, FF = th[3 * i : 3 * i + 3]
            ex, dex, sex = (a[0] if a is not None else None for a in _pix_1d(w, np.array([uu]), np.array([sig]), fit_sigma))
            ey, dey, sey = (a[0] if a is not None else None for a in _pix_1d(h, np.array([vv]), np.array([sig]), fit_sigma))
            outer = np.outer(ey, ex).ravel()[use]
            mu = mu + FF * outer
            if want_jac:
                cols += [FF * np.outer(ey, dex).ravel()[use], FF * np.outer(dey, ex).ravel()[use], outer]
                if fit_sigma:
                    dsig = dsig + FF * (np.outer(sey, ex) + np.outer(ey, sex)).ravel()[use]
        if not want_jac:
            return mu, None
        cols.append(np.ones_like(mu))
        if fit_sigma:
            cols.append(dsig)
        return mu, np.stack(cols, axis=1)

    th = np.concatenate([np.stack([uv0[:, 0], uv0[:, 1], f0], axis=1).ravel(), [b0], [s0] if fit_sigma else []])
    lo = np.concatenate([np.tile([-0.5, -0.5, -np.inf], k), [-np.inf], [0.2] if fit_sigma else []])
    hi = np.concatenate([np.tile([w - 0.5, h - 0.5, np.inf], k), [np.inf], [float(max(h, w))] if fit_sigma else []])
    th = np.clip(th, lo + 1e-9, hi - 1e-9)
    ok = True
    for _ in range(max(1, reweight_iter)):
        mu, _ = model_jac(th, False)
        var = p.variance(_scatter(mu, use, h, w)[None], bg=np.array([th[3 * k]]))[0].ravel()[use]
        sw = 1.0 / np.sqrt(var)
        try:
            r = least_squares(lambda t: (model_jac(t, False)[0] - data) * sw, th,
                              jac=lambda t: model_jac(t)[1] * sw[:, None], bounds=(lo, hi),
                              method="trf", x_scale="jac")
        except (ValueError, np.linalg.LinAlgError):
            ok = False
            break
        moved = np.max(np.abs(r.x[: 3 * k].reshape(k, 3)[:, :2] - th[: 3 * k].reshape(k, 3)[:, :2]))
        th = r.x
        ok = r.status > 0
        if moved < 1e-7:
            break
    mu, J = model_jac(th)
    var = p.variance(_scatter(mu, use, h, w)[None], bg=np.array([th[3 * k]]))[0].ravel()[use]
    flags = np.full(k, base, dtype=np.int64)
    try:
        cov = np.linalg.inv((J / var[:, None]).T @ J)
        sd = np.sqrt(np.abs(np.diag(cov)))
    except np.linalg.LinAlgError:
        sd = np.full(npar, np.nan)
        flags |= Flag.INVALID
    par = th[: 3 * k].reshape(k, 3)
    sdp = sd[: 3 * k].reshape(k, 3)
    if not ok:
        flags |= Flag.NOT_CONVERGED
    dof = use.sum() - npar
    chi2_red = float(np.sum((data - mu) ** 2 / var) / dof) if dof > 0 else np.nan
    if dof > 0 and chi2_red > 1.0 + 5.0 * math.sqrt(2.0 / dof):
        flags |= Flag.POOR_FIT
    with np.errstate(invalid="ignore", divide="ignore"):
        snr = par[:, 2] / sdp[:, 2]
    flags[~(par[:, 2] > 0)] |= Flag.EMPTY | Flag.INVALID
    flags[~(snr >= min_snr)] |= Flag.FAINT
    sig_fit = th[-1] if fit_sigma else s0
    near = ((par[:, 0] < -0.5 + 2 * sig_fit) | (par[:, 0] > w - 0.5 - 2 * sig_fit)
            | (par[:, 1] < -0.5 + 2 * sig_fit) | (par[:, 1] > h - 0.5 - 2 * sig_fit))
    flags[near] |= Flag.EDGE
    u, v = par[:, 0].copy(), par[:, 1].copy()
    su, sv = sdp[:, 0].copy(), sdp[:, 1].copy()
    inv = (flags & Flag.INVALID) != 0
    u[inv] = v[inv] = su[inv] = sv[inv] = np.nan
    if origin_uv is not None:
        o = np.asarray(origin_uv, dtype=float).reshape(2)
        u, v = u + o[0], v + o[1]
    return CentroidBatch(u, v, su, sv, par[:, 2].copy(), np.full(k, th[3 * k]), flags, "gauss_multi",
                         extra={"sigma_px": np.full(k, sig_fit), "chi2_red": np.full(k, chi2_red)})


def _scatter(vals: np.ndarray, use: np.ndarray, h: int, w: int) -> np.ndarray:
    full = np.zeros(h * w)
    full[use] = vals
    return full.reshape(h, w)


def centroid_tcom_peak(img, **kwargs) -> Centroid | CentroidBatch:
    """:func:`centroid_tcom` of the peak's own blob (``region="peak"``): a ghost or a second spot that
    the threshold separates from the brightest one does not pull the centroid."""
    return centroid_tcom(img, region="peak", **kwargs)


METHODS = {
    "tcom": centroid_tcom,
    "tcom_peak": centroid_tcom_peak,
    "wcom": centroid_wcom,
    "gauss": centroid_gauss,
    "gauss_lsq": centroid_gauss_lsq,
}


def centroid(img, method: str = "gauss", **kwargs) -> Centroid | CentroidBatch:
    """Dispatch to one of `METHODS` by name ("tcom", "tcom_peak", "wcom", "gauss", "gauss_lsq")."""
    try:
        fn = METHODS[method]
    except KeyError:
        raise ValueError(f"method must be one of {sorted(METHODS)}, got {method!r}") from None
    return fn(img, **kwargs)
