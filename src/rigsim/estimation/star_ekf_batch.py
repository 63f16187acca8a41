"""Several seed-004 EKFs on the same frames at once: :func:`run_ekf_batch`.

The Monte-Carlo studies run the same filter (model, equation set, weighting, estimated entries)
from several starting intrinsics θ0 on the same frames (the focal-length cases). Each frame's
equations then share the star sets, the catalogue measurement z and the centroid covariance; only
the linearisation point differs. :func:`run_ekf_batch` carries B filters through the frames
together, every array with a leading batch axis, so that one pass of numpy calls serves all of
them. Each filter is :func:`rigsim.estimation.star_calibration.run_ekf`'s, step by step (same
equations, same update forms: gain form with the Joseph update for a full R, information form
for a diagonal one, the pseudo-inverse projection for rank-deficient propagated sets); only the
rounding of the batched products differs (a test holds them together).
"""

from __future__ import annotations

import numpy as np

from rigsim.estimation.star_calibration import (
    EQUATIONS,
    MODELS,
    THETA_NAMES,
    WEIGHTINGS,
    EKFResult,
    FrameObs,
    _measurement,
    _update,
    equation_sets,
)
from rigsim.optics.camera import unproject

__all__ = ["run_ekf_batch"]

_THETA_TO_PARAMS = np.zeros((9, 5))
_THETA_TO_PARAMS[[0, 1, 2, 3, 4, 5], [0, 0, 1, 2, 3, 4]] = 1.0


def _normalized(uv, thetas, p12):
    """x (B, N, 2), ∂x/∂θ (B, N, 2, 5), ∂x/∂(u, v) (B, N, 2, 2) of centroids uv (B or 1, N, 2) under B
    intrinsics (B, 5)."""
    B = thetas.shape[0]
    params = np.empty((B, 1, 9))
    params[:, 0, 0] = params[:, 0, 1] = thetas[:, 0]
    params[:, 0, 2:6] = thetas[:, 1:5]
    params[:, 0, 6], params[:, 0, 7], params[:, 0, 8] = float(p12[0]), float(p12[1]), 0.0
    xy, dxy_duv, dxy_dp, _ok = unproject(uv, params, get_gradients=True, keep_invalid=True)
    return xy, dxy_dp @ _THETA_TO_PARAMS, dxy_duv


def _model_terms(x: np.ndarray, trip):
    """The improved ADS model's terms with per-filter star triplets (B, M, 3): h (B, M), indices (B, M, 3),
    ∂h/∂x (B, M, 3, 2). (AD and ADS go through :func:`_pair_terms`.)"""
    p = np.concatenate([x, np.ones(x.shape[:-1] + (1,))], -1)
    n = np.linalg.norm(p, axis=-1)
    bb = np.arange(x.shape[0])[:, None]
    i, j, k = trip[..., 0], trip[..., 1], trip[..., 2]
    xi, xj, xk = x[bb, i], x[bb, j], x[bb, k]
    ni, nk = n[bb, i], n[bb, k]
    den = ni * nk
    g = (xi[..., 0] * xj[..., 0] + xi[..., 1] * xj[..., 1]) - (xj[..., 0] * xk[..., 0] + xj[..., 1] * xk[..., 1])
    h = g / den
    ci = xj / den[..., None] - h[..., None] * xi / (ni ** 2)[..., None]
    cj = (xi - xk) / den[..., None]
    ck = -xj / den[..., None] - h[..., None] * xk / (nk ** 2)[..., None]
    return h, trip, np.stack([ci, cj, ck], 2)


def _pair_terms(model, x, dxe, dx_duv, pairs, trip):
    """h (B, M), star indices (B, M, 3), ∂h/∂θ (B, M, n) and ∂h/∂(u, v) per star (B, M, 3, 2) of the AD
    and exact ADS models from per-pair tables: every equation is a dot product wₐ·w_b (AD) or a
    difference of two (ADS, wᵢ·w_j − w_j·w_k), so the products and their derivatives are formed once
    per pair of stars (N² of them) and gathered per equation (an ``all`` set has N³/2 triplets)."""
    B, N = x.shape[:2]
    p = np.concatenate([x, np.ones(x.shape[:-1] + (1,))], -1)
    n = np.linalg.norm(p, axis=-1)
    w = p / n[..., None]
    dw = (np.eye(3)[None, None, :, :2] - w[..., :, None] * w[..., None, :2]) / n[..., None, None]
    gram = (w @ np.swapaxes(w, 1, 2)).reshape(B, N * N)                  # wₐ·w_b
    C = np.swapaxes(np.swapaxes(dw, 2, 3) @ np.swapaxes(w, 1, 2)[:, None], 2, 3)  # (∂wₐ/∂xₐ)ᵀ w_b (B, N, N, 2)
    D = C @ dxe                                                          # through star a: ∂/∂θ (B, N, N, n)
    E = (D + np.swapaxes(D, 1, 2)).reshape(B, N * N, -1)                 # ∂(wₐ·w_b)/∂θ
    F = (C @ dx_duv).reshape(B, N * N, 2)                                # ∂(wₐ·w_b)/∂(uₐ, vₐ)
    bb = np.arange(B)[:, None]
    if model == "ad":
        a, b = pairs[..., 0], pairs[..., 1]
        ab, ba = a * N + b, b * N + a
        gs = np.stack([F[bb, ab], F[bb, ba], np.zeros((B, a.shape[1], 2))], 2)
        return gram[bb, ab], np.stack([a, b, a], -1), E[bb, ab], gs
    i, j, k = trip[..., 0], trip[..., 1], trip[..., 2]
    ij, jk = i * N + j, j * N + k
    gs = np.stack([F[bb, ij], F[bb, j * N + i] - F[bb, jk], -F[bb, k * N + j]], 2)
    return gram[bb, ij] - gram[bb, jk], trip, E[bb, ij] - E[bb, jk], gs


def _info_update(P, nu, H, w):
    """Information-form updates of B filters: weights w = 1/R (B, M) (0 drops an equation)."""
    HtRi = np.swapaxes(H, 1, 2) * w[:, None, :]
    Pn = np.linalg.inv(np.linalg.inv(P) + HtRi @ H)
    Pn = 0.5 * (Pn + np.swapaxes(Pn, 1, 2))
    g = np.einsum("bnm,bm->bn", HtRi, nu)
    dx = np.einsum("bnk,bk->bn", Pn, g)
    q = np.einsum("bm,bm->b", nu, nu * w) - np.einsum("bn,bn->b", g, dx)
    return dx, Pn, q


def _gain_update(P, nu, H, R):
    """Gain-form (Joseph) updates of B filters with full R (B, M, M); a filter whose S is not
    positive definite takes the single filter's jittered path."""
    HP = H @ P
    S = HP @ np.swapaxes(H, 1, 2) + R
    S = 0.5 * (S + np.swapaxes(S, 1, 2))
    try:
        L = np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        out = [_update(P[b], nu[b], H[b], None, R[b]) for b in range(P.shape[0])]
        return np.array([o[0] for o in out]), np.array([o[1] for o in out]), np.array([o[2] for o in out])
    Linv_HP = np.linalg.solve(L, HP)
    K = np.swapaxes(np.linalg.solve(np.swapaxes(L, 1, 2), Linv_HP), 1, 2)   # P Hᵀ S⁻¹
    n = P.shape[1]
    IKH = np.eye(n)[None] - K @ H
    Pn = IKH @ P @ np.swapaxes(IKH, 1, 2) + K @ R @ np.swapaxes(K, 1, 2)
    y = np.linalg.solve(L, nu[..., None])[..., 0]
    return np.einsum("bnm,bm->bn", K, nu), Pn, np.einsum("bm,bm->b", y, y)


def _sets_and_z(fo, model, equations, cache):
    """(pairs, triplets, z) of a frame, memoised in ``cache`` (keyed by the frame object) when given."""
    key = (id(fo), equations, model == "ad")
    got = None if cache is None else cache.get(key)
    if got is None or got[0] is not fo:
        pairs, trip = equation_sets(fo.uv, equations, fo.flux)
        got = (fo, pairs, trip, _measurement(model, fo.dirs_icrs, pairs, trip))
        if cache is not None:
            cache[key] = got
    return got[1:]


def _frame_update(fos, thetas, est, P, model, weighting, p12, equations, cache):
    """One frame per filter (``fos``: B frames of N stars each, or one shared frame) through B filters:
    (Δx (B, n), P⁺ (B, n, n), NIS (B,), equations, dof)."""
    B = thetas.shape[0]
    shared = not isinstance(fos, (list, tuple))
    if shared:
        pairs, trip, z = _sets_and_z(fos, model, equations, cache)
        pairs, trip = (np.broadcast_to(a, (B,) + a.shape) for a in (pairs, trip))
        uv, sig = np.asarray(fos.uv, float)[None], np.asarray(fos.sigma_uv, float)[None]
    else:
        sz = [_sets_and_z(fo, model, equations, cache) for fo in fos]
        pairs, trip, z = (np.stack([t[i] for t in sz]) for i in range(3))
        uv = np.stack([np.asarray(fo.uv, float) for fo in fos])
        sig = np.stack([np.asarray(fo.sigma_uv, float) for fo in fos])
    N = uv.shape[1]
    bb = np.arange(B)[:, None]
    x, dx_dth, dx_duv = _normalized(uv, thetas, p12)
    dxe = dx_dth[..., est]
    if model == "ads_improved":
        h, idx, coef = _model_terms(x, trip)
        H = sum(coef[:, :, s, c, None] * dxe[bb, idx[..., s], c] for s in range(3) for c in range(2))
        du = dx_duv[bb[..., None], idx]                                        # (B, M, 3, 2, 2)
        gs = coef[..., 0, None] * du[..., 0, :] + coef[..., 1, None] * du[..., 1, :]
    else:
        h, idx, H, gs = _pair_terms(model, x, dxe, dx_duv, pairs, trip)
    nu = z - h
    B, M = h.shape
    var2 = np.broadcast_to(sig**2, (B, N, 2))                         # (B, N, 2)
    if weighting in ("diagonal", "unweighted"):
        # diagonal of G Σ Gᵀ: the three stars of an equation are distinct, so no cross terms
        r = np.einsum("bmsq,bmsq->bm", gs * gs, var2[bb[..., None], idx])
        if weighting == "unweighted":
            r = np.repeat(np.mean(r, axis=1, keepdims=True), M, axis=1)
        dx, Pn, q = _info_update(P, nu, H, 1.0 / r)
        return dx, Pn, q, M, M
    # G (B, M, 2N): the stars of an equation are distinct (AD's third slot is a zero placeholder), so
    # their entries are set, not summed
    ns = 2 if model == "ad" else 3
    flat = (np.arange(M)[:, None, None] * (2 * N) + 2 * idx[..., :ns, None] + np.arange(2)).reshape(B, -1)
    G = np.zeros((B, M * 2 * N))
    G[bb, flat] = gs[:, :, :ns].reshape(B, -1)
    G = G.reshape(B, M, 2 * N)
    var = var2.reshape(B, 2 * N)
    if M <= 2 * N - 3:
        R = (G * var[:, None, :]) @ np.swapaxes(G, 1, 2)
        d = np.arange(M)
        R[:, d, d] += 1e-9 * np.mean(R[:, d, d], axis=1, keepdims=True)
        dx, Pn, q = _gain_update(P, nu, H, R)
        return dx, Pn, q, M, M
    # rank-deficient propagated set: project onto the range of R = A Aᵀ, A = G Σ^½
    A = G * np.sqrt(var)[:, None, :]
    lam, V = np.linalg.eigh(np.swapaxes(A, 1, 2) @ A)
    keep = lam > 1e-10 * lam[:, -1:]
    lam_k = np.where(keep, lam, 1.0)
    At = np.swapaxes(A, 1, 2)
    Vt = np.swapaxes(V, 1, 2)
    nu_t = (Vt @ (At @ nu[..., None]))[..., 0] / np.sqrt(lam_k)       # T ν, T = Λ^-½ Vᵀ Aᵀ
    H_t = (Vt @ (At @ H)) / np.sqrt(lam_k)[..., None]
    floor = 1e-9 * np.sum(np.where(keep, lam, 0.0), axis=1, keepdims=True) / np.sum(keep, axis=1, keepdims=True)
    w = np.where(keep, 1.0 / (lam_k + floor), 0.0)
    dx, Pn, q = _info_update(P, nu_t, H_t, w)
    dof = np.sum(keep, axis=1)
    return dx, Pn, q, M, dof


def run_ekf_batch(frames, theta0s, *, model: str = "ad", estimate=("u0", "v0"), prior_sigma=None,
                  process_sigma: float = 0.0, weighting: str = "propagated", p12=(0.0, 0.0),
                  equations: str = "framework", cache: dict | None = None) -> list[EKFResult]:
    """:func:`~rigsim.estimation.star_calibration.run_ekf` from each row of ``theta0s`` (B, 5) with the same
    settings: one :class:`EKFResult` per row, in order. ``frames``: one sequence of :class:`FrameObs` for
    every filter, or B sequences of equal length (filter b runs on ``frames[b]``; filters whose frames differ
    in star counts run in separate batches). ``cache``: a dict kept across calls on the same frame objects
    memoises their star sets and catalogue measurements."""
    if model not in MODELS:
        raise ValueError(f"model = {model!r}: allowed {MODELS}")
    if equations not in EQUATIONS:
        raise ValueError(f"equations = {equations!r}: allowed {', '.join(EQUATIONS)}")
    if weighting not in WEIGHTINGS:
        raise ValueError(f"weighting = {weighting!r}: allowed {', '.join(WEIGHTINGS)}")
    thetas = np.array(theta0s, dtype=float, ndmin=2).copy()
    B = thetas.shape[0]
    kw = {"model": model, "estimate": estimate, "prior_sigma": prior_sigma, "process_sigma": process_sigma,
          "weighting": weighting, "p12": p12, "equations": equations, "cache": cache}
    if len(frames) and not isinstance(frames[0], FrameObs):   # one sequence per filter
        if len(frames) != B:
            raise ValueError(f"{len(frames)} frame sequences for {B} filters")
        sig = [tuple(len(fo) if len(fo) >= 4 else 0 for fo in seq) for seq in frames]
        if len(set(sig)) > 1:   # star counts differ: one batch per pattern
            out: list = [None] * B
            for pattern in dict.fromkeys(sig):
                sel = [b for b in range(B) if sig[b] == pattern]
                for b, r in zip(sel, run_ekf_batch([frames[b] for b in sel], thetas[sel], **kw)):
                    out[b] = r
            return out
        steps = [list(fos) for fos in zip(*frames)]   # one pattern: the sequences have its length
    else:
        steps = list(frames)
    return _run(steps, thetas, **kw)


def _run(steps, thetas, *, model, estimate, prior_sigma, process_sigma, weighting, p12, equations, cache):
    est = [THETA_NAMES.index(e) for e in estimate]
    B, n = thetas.shape[0], len(est)
    ps = np.full(n, 10.0) if prior_sigma is None else np.asarray(prior_sigma, float)
    P = np.repeat(np.diag(ps**2)[None], B, axis=0)
    Q = np.eye(n) * process_sigma**2
    hx, hs = [thetas[:, est].copy()], [np.sqrt(np.diagonal(P, axis1=1, axis2=2))]
    nis, neq, dof = [], [], []
    for fos in steps:
        if len(fos if not isinstance(fos, list) else fos[0]) < 4:
            nis.append(np.full(B, np.nan))
            neq.append(0)
            dof.append(np.zeros(B, int))
        else:
            P = P + Q[None]
            dx, P, q, m, d = _frame_update(fos, thetas, est, P, model, weighting, p12, equations, cache)
            thetas[:, est] = thetas[:, est] + dx
            nis.append(q)
            neq.append(m)
            dof.append(np.broadcast_to(d, (B,)))
        hx.append(thetas[:, est].copy())
        hs.append(np.sqrt(np.diagonal(P, axis1=1, axis2=2)))
    hx, hs, nis, dof = np.array(hx), np.array(hs), np.array(nis).reshape(-1, B), np.array(dof).reshape(-1, B)
    return [EKFResult(model, tuple(estimate), thetas[b, est].copy(), P[b].copy(), hx[:, b], hs[:, b], nis[:, b],
                      np.array(neq), thetas[b].copy(), dof[:, b].astype(int)) for b in range(B)]
