"""Seed 004 calibration: angular-distance (AD) and angular-distance-subtraction (ADS) models, an
EKF over an image sequence, batch least squares of (f, u0, v0, k1, k2), all with Jacobians.

Every equation is a reconstruction (the patent's formulas were lost); docs/star_calibration.md
gives the reasoning. Notation: a star's measured centroid (u, v) px; intrinsics θ = (f, u0, v0,
k1, k2) (square pixels, fx = fy = f; tangential p1, p2 known and fixed); normalised distorted
coordinates x_d = ((u − u0)/f, (v − v0)/f); undistorted x = D⁻¹(x_d; k1, k2, p1, p2) (OpenCV's
Brown model, inverted by Newton); the patent's eq 5 direction w = (x, y, 1)/|(x, y, 1)|
= (X, Y, f)/D with X = f x, D = √(X² + Y² + f²); catalogue directions v (eq 6; ICRS at the
observation epoch).

Measurement models (one frame, stars ordered by brightness, (a, b) the pair farthest apart):

* ``ad`` — eq 7-8: z = vₐ·v_b, h = wₐ·w_b, over the 2N − 3 pairs (a, b), (a, j), (b, j): the
  edges of a rigid framework, so the equations are independent and their covariance has full
  rank (all N(N−1)/2 pairs carry no more information: they are functions of the 2N centroids
  and 3 attitude angles drop out).
* ``ads`` (exact subtraction, eq 10) — triplets (i, j, k): z = vᵢ·v_j − v_j·v_k,
  h = wᵢ·w_j − w_j·w_k, over the 2N − 4 triplets (a, j, b) and (j, a, b).
* ``ads_improved`` (eq 11-12, the patent's improved ADS) — with D_iD_j ≈ D_jD_k ≈ D_aD_b the f²
  terms of the numerators cancel: h = (N_ij − N_jk)/(D_iD_k), N_ij = X_iX_j + Y_iY_j; in
  normalised terms h = (xᵢ·x_j − x_j·x_k)/(|pᵢ||p_k|), p = (x, y, 1). The approximation drops
  f²(1/(D_iD_j) − 1/(D_jD_k)) ≈ (r_k² − r_i²)/(2f²), which is of the same order as h itself:
  this model is biased by construction (measured in the docs).

Equation sets (``equations``): ``'framework'`` (default) — the pairs and triplets above;
``'all'`` — every pair i < j (N(N−1)/2) and every triplet (i, j, k) with j the shared middle star
and i < k, i, k ≠ j (N(N−1)(N−2)/2); ``'chain'`` — consecutive stars in brightness order: pairs
(i, i+1) (N − 1) and triplets (i, i+1, i+2) (N − 2).

Noise (``weighting``): ``'propagated'`` — R = G Σ Gᵀ with G = ∂h/∂(centroids) and Σ the centroid
covariance (from the centroider); where a set has more equations than the 2N − 3 independent
angles (``'all'``), R is singular and the equations are projected onto its range (the
pseudo-inverse solution); ``'diagonal'`` — only the diagonal of that R (each equation treated as
independent, the usual reading of "R is the measurement noise covariance"); ``'unweighted'`` —
R = σ²I with σ² the mean of the propagated diagonal over the frame's equations.

EKF (eqs 13-19): state a subset of θ (default (u0, v0); the patent's state is the principal point),
identity transition, process noise Q = q²I, one update per frame with the frame's vector of
equations, Joseph-form covariance update.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_triangular

from rigsim.optics.camera import unproject

__all__ = ["EQUATIONS", "MODELS", "THETA_NAMES", "WEIGHTINGS", "BatchResult", "EKFResult", "FrameObs",
           "FrameSystem", "batch_lsq", "equation_sets", "frame_system", "normalized_with_jacobians", "pair_sets",
           "run_ekf"]

THETA_NAMES = ("f", "u0", "v0", "k1", "k2")
MODELS = ("ad", "ads", "ads_improved")
EQUATIONS = ("framework", "all", "chain")
WEIGHTINGS = ("propagated", "diagonal", "unweighted")


@dataclass(frozen=True)
class FrameObs:
    """Identified stars of one frame: measured centroids (px), their 1σ, catalogue unit vectors."""

    uv: np.ndarray
    sigma_uv: np.ndarray
    dirs_icrs: np.ndarray
    flux: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.uv.shape[0])

    def brightest(self, n: int) -> "FrameObs":
        if len(self) <= n:
            return self
        order = np.argsort(-self.flux)[:n] if self.flux is not None else np.argsort(
            np.hypot(*self.sigma_uv.T))[:n]
        return FrameObs(self.uv[order], self.sigma_uv[order], self.dirs_icrs[order],
                        None if self.flux is None else self.flux[order])


_THETA_TO_PARAMS = np.zeros((9, 5))
_THETA_TO_PARAMS[[0, 1, 2, 3, 4, 5], [0, 0, 1, 2, 3, 4]] = 1.0
"""∂(camera parameters, OpenCV order)/∂θ: f drives fx and fy, (u0, v0) = (cx, cy), k1, k2."""


def normalized_with_jacobians(uv, theta, p12=(0.0, 0.0)):
    """Undistorted normalised coordinates x (N, 2) and ∂x/∂θ (N, 2, 5), ∂x/∂(u, v) (N, 2, 2), valid.

    The camera model's inverse (:func:`rigsim.optics.camera.unproject` with fx = fy = f, k3 = 0 and
    the known tangential terms) and its implicit-function Jacobians, mapped onto θ = (f, u0, v0, k1, k2)."""
    f, u0, v0, k1, k2 = (float(t) for t in theta)
    p1, p2 = (float(p) for p in p12)
    params = np.array([f, f, u0, v0, k1, k2, p1, p2, 0.0])
    uv = np.asarray(uv, dtype=float)
    # an EKF on a biased model (improved ADS) may wander far outside the distortion model's domain:
    # keep its values there (the filter decides), and report where they are valid
    xy, dxy_duv, dxy_dp, ok = unproject(uv, params, get_gradients=True, keep_invalid=True)
    return xy, dxy_dp @ _THETA_TO_PARAMS, dxy_duv, ok


def pair_sets(uv: np.ndarray):
    """(a, b) = the two stars farthest apart; AD pairs (2N−3, 2); ADS triplets (2N−4, 3)."""
    n = uv.shape[0]
    d2 = np.sum((uv[:, None, :] - uv[None, :, :]) ** 2, axis=-1)
    a, b = np.unravel_index(int(np.argmax(d2)), d2.shape)
    others = np.array([j for j in range(n) if j not in (a, b)], dtype=np.int64)
    pairs = np.concatenate([[[a, b]], np.stack([np.full_like(others, a), others], 1),
                            np.stack([np.full_like(others, b), others], 1)]).astype(np.int64)
    trip = np.concatenate([np.stack([np.full_like(others, a), others, np.full_like(others, b)], 1),
                           np.stack([others, np.full_like(others, a), np.full_like(others, b)], 1)]).astype(np.int64)
    return pairs, trip


def equation_sets(uv: np.ndarray, equations: str = "framework", flux: np.ndarray | None = None):
    """AD pairs (M, 2) and ADS triplets (M', 3) of one frame's stars for an equation set of
    :data:`EQUATIONS` (module docstring); ``chain`` orders the stars by decreasing ``flux`` (the
    given order without it)."""
    if equations == "framework":
        return pair_sets(uv)
    n = uv.shape[0]
    if equations == "all":
        pairs = np.stack(np.triu_indices(n, 1), 1).astype(np.int64)
        i, k = np.triu_indices(n, 1)
        jj = np.repeat(np.arange(n), i.size)
        ii, kk = np.tile(i, n), np.tile(k, n)
        keep = (ii != jj) & (kk != jj)
        return pairs, np.stack([ii[keep], jj[keep], kk[keep]], 1).astype(np.int64)
    if equations == "chain":
        o = np.argsort(-np.asarray(flux, float), kind="stable") if flux is not None else np.arange(n)
        return (np.stack([o[:-1], o[1:]], 1).astype(np.int64),
                np.stack([o[:-2], o[1:-1], o[2:]], 1).astype(np.int64))
    raise ValueError(f"equations = {equations!r}: allowed {', '.join(EQUATIONS)}")


@dataclass
class FrameSystem:
    """One frame's equations at θ: z, h, H = ∂h/∂θ (M, 5), G = ∂h/∂centroids (M, 2N), the centroid
    variances ``var`` (2N,) and the ``weighting``; R (M, M) is formed on demand."""

    z: np.ndarray
    h: np.ndarray
    H: np.ndarray
    G: np.ndarray
    var: np.ndarray
    weighting: str
    valid: bool

    @property
    def r_diag(self) -> np.ndarray:
        """Diagonal of the propagated R = G Σ Gᵀ (M,), without forming R."""
        return np.einsum("mq,q,mq->m", self.G, self.var, self.G)

    @property
    def sigma2(self) -> float:
        """The ``unweighted`` variance: the mean of the propagated diagonal."""
        return float(np.mean(self.r_diag))

    @property
    def R(self) -> np.ndarray:
        if self.weighting == "diagonal":
            return np.diag(self.r_diag)
        if self.weighting == "unweighted":
            return self.sigma2 * np.eye(self.h.size)
        R = (self.G * self.var[None, :]) @ self.G.T
        # 1e-9 relative floor: a nearly degenerate framework (near-collinear stars) must not make
        # R numerically singular; it changes no weight by more than 1e-9 of the mean variance
        R[np.diag_indices_from(R)] += 1e-9 * np.mean(np.diag(R))
        return R

    def reduced(self):
        """(T, R') with which the frame's equations enter an estimator: T (r, M) maps z, h, H
        (None = identity), R' is the covariance of T(z − h), as variances (1-D) when diagonal.
        Propagated sets with more equations than the 2N − 3 independent angles are projected onto
        the range of R (its pseudo-inverse)."""
        if self.weighting == "diagonal":
            return None, self.r_diag
        if self.weighting == "unweighted":
            return None, np.full(self.h.size, self.sigma2)
        if self.h.size <= self.G.shape[1] - 3:
            return None, self.R
        # R = A Aᵀ with A = G Σ^½ (M, 2N): its range from the small eigenproblem AᵀA = V Λ Vᵀ,
        # U = A V Λ^-½; the 3 attitude directions (Λ ≈ 0) and rounding (< 1e-10 Λmax) are dropped
        # (einsum, not BLAS: multithreaded BLAS on these thin products thrashes a loaded machine)
        A = self.G * np.sqrt(self.var)[None, :]
        lam, V = np.linalg.eigh(np.einsum("mp,mq->pq", A, A))
        keep = lam > 1e-10 * lam[-1]
        lam, V = lam[keep], V[:, keep]
        Ut = np.einsum("pk,mp->km", V, A) / np.sqrt(lam)[:, None]
        return Ut, lam + 1e-9 * np.mean(lam)


def _model_terms(model: str, x: np.ndarray, pairs, trip):
    """h (M,), star indices (M, 3) and ∂h/∂x per star (M, 3, 2)."""
    p = np.concatenate([x, np.ones((x.shape[0], 1))], 1)
    n = np.linalg.norm(p, axis=1)
    w = p / n[:, None]
    # ∂w/∂x (N, 3, 2) = (I − w wᵀ)[:, :2] / n
    dw = (np.eye(3)[None, :, :2] - w[:, :, None] * w[:, None, :2]) / n[:, None, None]
    if model == "ad":
        ia, ib = pairs[:, 0], pairs[:, 1]
        h = np.einsum("mi,mi->m", w[ia], w[ib])
        ca = np.einsum("mic,mi->mc", dw[ia], w[ib])
        cb = np.einsum("mic,mi->mc", dw[ib], w[ia])
        idx = np.stack([ia, ib, ia], 1)
        coef = np.stack([ca, cb, np.zeros_like(ca)], 1)
        return h, idx, coef
    i, j, k = trip[:, 0], trip[:, 1], trip[:, 2]
    idx = trip
    if model == "ads":
        h = np.einsum("mi,mi->m", w[i], w[j]) - np.einsum("mi,mi->m", w[j], w[k])
        ci = np.einsum("mic,mi->mc", dw[i], w[j])
        cj = np.einsum("mic,mi->mc", dw[j], w[i] - w[k])
        ck = -np.einsum("mic,mi->mc", dw[k], w[j])
        return h, idx, np.stack([ci, cj, ck], 1)
    if model == "ads_improved":
        den = n[i] * n[k]
        g = np.einsum("mc,mc->m", x[i], x[j]) - np.einsum("mc,mc->m", x[j], x[k])
        h = g / den
        ci = x[j] / den[:, None] - h[:, None] * x[i] / (n[i] ** 2)[:, None]
        cj = (x[i] - x[k]) / den[:, None]
        ck = -x[j] / den[:, None] - h[:, None] * x[k] / (n[k] ** 2)[:, None]
        return h, idx, np.stack([ci, cj, ck], 1)
    raise ValueError(f"model = {model!r}: allowed {MODELS}")


def _measurement(model: str, V: np.ndarray, pairs, trip) -> np.ndarray:
    if model == "ad":
        return np.einsum("mi,mi->m", V[pairs[:, 0]], V[pairs[:, 1]])
    i, j, k = trip[:, 0], trip[:, 1], trip[:, 2]
    return np.einsum("mi,mi->m", V[i], V[j]) - np.einsum("mi,mi->m", V[j], V[k])


def frame_system(fo: FrameObs, theta, model: str = "ad", weighting: str = "propagated",
                 p12=(0.0, 0.0), sets=None, equations: str = "framework") -> FrameSystem:
    """All of one frame's equations at intrinsics ``theta`` (see the module docstring); ``sets``
    (pairs, triplets) overrides ``equations``."""
    if weighting not in WEIGHTINGS:
        raise ValueError(f"weighting = {weighting!r}: allowed {', '.join(WEIGHTINGS)}")
    N = len(fo)
    pairs, trip = sets if sets is not None else equation_sets(fo.uv, equations, fo.flux)
    x, dx_dth, dx_duv, ok = normalized_with_jacobians(fo.uv, theta, p12)
    h, idx, coef = _model_terms(model, x, pairs, trip)
    z = _measurement(model, fo.dirs_icrs, pairs, trip)
    H = np.einsum("msc,mscp->mp", coef, dx_dth[idx])
    gs = np.einsum("msc,mscq->msq", coef, dx_duv[idx])  # (M, 3, 2)
    M = h.shape[0]
    G = np.zeros((M, N, 2))
    rows = np.repeat(np.arange(M), 3)
    np.add.at(G, (rows, idx.ravel()), gs.reshape(-1, 2))
    G = G.reshape(M, 2 * N)
    var = (np.asarray(fo.sigma_uv, float) ** 2).reshape(-1)
    return FrameSystem(z, h, H, G, var, weighting, bool(np.all(ok)))


# ------------------------------------------------------------------------------ EKF

def _cho(S: np.ndarray):
    """Cholesky factor (lower) of a symmetric PSD matrix, with growing diagonal jitter if needed."""
    S = 0.5 * (S + S.T)
    jitter = 0.0
    scale = float(np.mean(np.diag(S))) or 1.0
    for _ in range(8):
        try:
            return cho_factor(S + np.eye(S.shape[0]) * jitter, lower=True)
        except np.linalg.LinAlgError:
            jitter = scale * (1e-9 if jitter == 0.0 else jitter / scale * 100.0)
    raise np.linalg.LinAlgError("measurement covariance is not positive definite even with jitter")


@dataclass
class EKFResult:
    model: str
    names: tuple[str, ...]
    x: np.ndarray
    P: np.ndarray
    history_x: np.ndarray       # (K+1, n): prior, then after each frame
    history_sigma: np.ndarray   # (K+1, n)
    nis: np.ndarray             # (K,) normalised innovation squared per frame
    n_eq: np.ndarray            # (K,) equations per frame
    theta: np.ndarray           # full θ with the estimated entries replaced
    dof: np.ndarray | None = None  # (K,) dimension of each update (= n_eq unless R was rank-deficient)

    @property
    def sigma(self) -> np.ndarray:
        return np.sqrt(np.diag(self.P))


def _update(P, nu, H, T, R):
    """One measurement update of state covariance P with innovation ν, Jacobian H and (T, R) from
    :meth:`FrameSystem.reduced`: (Δx, P⁺, NIS). Diagonal R: information form (cost linear in the
    number of equations); full R: gain form with the Joseph update."""
    if T is not None:
        nu, H = T @ nu, T @ H
    if R.ndim == 1:
        HtRi = H.T / R[None, :]
        A = np.linalg.inv(P) + HtRi @ H
        Pn = np.linalg.inv(A)
        Pn = 0.5 * (Pn + Pn.T)
        g = HtRi @ nu
        dx = Pn @ g
        return dx, Pn, float(nu @ (nu / R) - g @ dx)
    n = P.shape[0]
    S = H @ P @ H.T + R
    cf = _cho(S)
    K = cho_solve(cf, H @ P).T  # P Hᵀ S⁻¹
    IKH = np.eye(n) - K @ H
    return K @ nu, IKH @ P @ IKH.T + K @ R @ K.T, float(nu @ cho_solve(cf, nu))


def run_ekf(frames, theta0, *, model: str = "ad", estimate=("u0", "v0"), prior_sigma=None,
            process_sigma: float = 0.0, weighting: str = "propagated", p12=(0.0, 0.0),
            max_stars: int | None = None, equations: str = "framework") -> EKFResult:
    """EKF over a sequence of :class:`FrameObs` (eqs 13-19). θ entries not in ``estimate`` stay at
    ``theta0`` (known or assumed). ``prior_sigma`` per estimated entry (default 10 px / 10 px…).
    ``equations`` ∈ :data:`EQUATIONS`, ``weighting`` ∈ :data:`WEIGHTINGS` (module docstring)."""
    if model not in MODELS:
        raise ValueError(f"model = {model!r}: allowed {MODELS}")
    if equations not in EQUATIONS:
        raise ValueError(f"equations = {equations!r}: allowed {', '.join(EQUATIONS)}")
    est = [THETA_NAMES.index(e) for e in estimate]
    theta = np.asarray(theta0, dtype=float).copy()
    n = len(est)
    ps = np.full(n, 10.0) if prior_sigma is None else np.asarray(prior_sigma, float)
    P = np.diag(ps**2)
    Q = np.eye(n) * process_sigma**2
    hx = [theta[est].copy()]
    hs = [np.sqrt(np.diag(P))]
    nis, neq, dof = [], [], []
    for fo in frames:
        if max_stars is not None:
            fo = fo.brightest(max_stars)
        if len(fo) < 4:
            nis.append(np.nan)
            neq.append(0)
            dof.append(0)
            hx.append(theta[est].copy())
            hs.append(np.sqrt(np.diag(P)))
            continue
        P = P + Q
        sysm = frame_system(fo, theta, model, weighting, p12, equations=equations)
        T, R = sysm.reduced()
        nu = sysm.z - sysm.h
        dx, P, q = _update(P, nu, sysm.H[:, est], T, R)
        theta[est] = theta[est] + dx
        nis.append(q)
        neq.append(nu.size)
        dof.append(nu.size if T is None else T.shape[0])
        hx.append(theta[est].copy())
        hs.append(np.sqrt(np.diag(P)))
    return EKFResult(model, tuple(estimate), theta[est].copy(), P, np.array(hx), np.array(hs),
                     np.array(nis), np.array(neq), theta, np.array(dof))


# ------------------------------------------------------------------------------ batch LSQ

@dataclass
class BatchResult:
    model: str
    names: tuple[str, ...]
    theta: np.ndarray       # full θ
    x: np.ndarray           # estimated entries
    cov: np.ndarray         # covariance of the estimated entries (inverse normal matrix)
    chi2: float             # whitened residual sum of squares
    n_eq: int
    success: bool
    message: str
    residuals: list = field(default_factory=list)   # per frame: (z − h) at the solution

    @property
    def sigma(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))

    @property
    def chi2_reduced(self) -> float:
        return self.chi2 / max(1, self.n_eq - len(self.names))


def _whitener(sysm: FrameSystem):
    """The map A ↦ W A with WᵀW = R⁻¹ (or the pseudo-inverse on R's range) for the frame's weighting."""
    T, R = sysm.reduced()
    if R.ndim == 1:
        d = 1.0 / np.sqrt(R)
        if T is None:
            return lambda A: (A.T * d).T
        W = T * d[:, None]
    else:
        L = np.tril(_cho(R)[0])
        W = solve_triangular(L, np.eye(R.shape[0]), lower=True)  # L⁻¹
        W = W if T is None else W @ T
    return lambda A: W @ A


def batch_lsq(frames, theta0, *, estimate=THETA_NAMES, model: str = "ad", weighting: str = "propagated",
              p12=(0.0, 0.0), max_stars: int | None = None, passes: int = 2,
              equations: str = "framework") -> BatchResult:
    """Weighted least squares of the chosen θ entries over all frames' equations (Gauss–Newton
    through ``scipy.optimize.least_squares``), whitened by each frame's R (re-evaluated at the
    solution for a second pass). Covariance = (Jᵀ R⁻¹ J)⁻¹ at the solution. ``equations`` and
    ``weighting`` as in :func:`run_ekf`."""
    from scipy.optimize import least_squares

    est = [THETA_NAMES.index(e) for e in estimate]
    fos = [fo.brightest(max_stars) if max_stars else fo for fo in frames]
    fos = [fo for fo in fos if len(fo) >= 4]
    sets = [equation_sets(fo.uv, equations, fo.flux) for fo in fos]
    theta = np.asarray(theta0, dtype=float).copy()
    scale = np.array([1.0, 1.0, 1.0, 1e-3, 1e-3])[est]

    def whiteners(th):
        return [_whitener(frame_system(fo, th, model, weighting, p12, st)) for fo, st in zip(fos, sets)]

    def full(xe):
        th = theta.copy()
        th[est] = xe
        return th

    # every frame's stars through the camera model in one call (the model is per point), and the
    # catalogue measurements once (they do not depend on θ)
    uv_all = np.concatenate([np.asarray(fo.uv, float) for fo in fos]) if fos else np.zeros((0, 2))
    cuts = np.cumsum([0] + [len(fo) for fo in fos])
    zs = [_measurement(model, fo.dirs_icrs, *st) for fo, st in zip(fos, sets)]
    res = None
    for _ in range(passes):
        Ls = whiteners(theta)

        cache: dict = {}

        def evaluate(xe):
            key = tuple(np.asarray(xe, float))
            if cache.get("key") != key:
                th = full(xe)
                r_out, j_out = [], []
                x_all, dx_all, _dx_duv, _ok = normalized_with_jacobians(uv_all, th, p12)
                for a, b, st, z in zip(cuts[:-1], cuts[1:], sets, zs):
                    x, dx_dth = x_all[a:b], dx_all[a:b]
                    h, idx, coef = _model_terms(model, x, *st)
                    H = np.einsum("msc,mscp->mp", coef, dx_dth[idx])[:, est]
                    r_out.append(h - z)
                    j_out.append(H)
                r = np.concatenate([Li(ri) for Li, ri in zip(Ls, r_out)])
                J = np.concatenate([Li(ji) for Li, ji in zip(Ls, j_out)])
                cache.update(key=key, r=r, J=J)
            return cache

        def fun(xe):
            return evaluate(xe)["r"]

        def jac(xe):
            return evaluate(xe)["J"]

        res = least_squares(fun, theta[est], jac=jac, method="lm", x_scale=scale, xtol=1e-12, ftol=1e-12)
        theta = full(res.x)
    J = res.jac
    cov = np.linalg.inv(J.T @ J)
    resid = []
    for fo, st in zip(fos, sets):
        s = frame_system(fo, theta, model, weighting, p12, st)
        resid.append(s.z - s.h)
    return BatchResult(model, tuple(estimate), theta, theta[est].copy(), cov, float(res.fun @ res.fun),
                       int(res.fun.size), bool(res.success), str(res.message), resid)
