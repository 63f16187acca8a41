"""Star-camera calibration from identified stars alone: the intrinsics (f, u0, v0, k1, k2) and every
frame's attitude R(cam←ICRS) fitted together to the measured centroids (a bundle adjustment on the
celestial sphere; no attitude source needed).

Each star gives two residuals, measured − projected, divided by its centroid σ. The centroid σ is
the centroider's (its inverse Fisher matrix) combined in quadrature with a floor ``s`` that the data
estimate: ``s`` is raised until χ²/dof = 1 when the centroider's σ alone leave χ²/dof above its 2σ
chance range (PSF mismatch, pixel response, an imperfect camera model: whatever the noise model
does not explain). Both χ²/dof are reported, so a user sees how far the noise model is from the data.

The nominal values enter as priors with the nominal σ (pseudo-observations): on a narrow field a
principal-point shift and a common rotation of every frame move the stars alike, and only the
field's curvature and distortion tell them apart; the prior keeps such a fit well posed and its
covariance says how much the data added. Stars whose normalised residual exceeds ``reject_sigma``
after the fit are left out and the fit repeated (a wrong match, a blend, a hot pixel).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.estimation.star_calibration import THETA_NAMES, FrameObs
from rigsim.optics.camera import PinholeBrown

__all__ = ["BundleResult", "HeldOut", "bundle_adjust", "field_of_view_deg", "held_out_check", "predict_frame"]

# θ = (f, u0, v0, k1, k2) → the camera's 9 parameters (fx, fy, cx, cy, k1, k2, p1, p2, k3)
_T9 = np.zeros((9, 5))
_T9[0, 0] = _T9[1, 0] = 1.0
_T9[2, 1] = _T9[3, 2] = _T9[4, 3] = _T9[5, 4] = 1.0


@dataclass
class BundleResult:
    """The fit: θ over ``THETA_NAMES`` (the entries not in ``names`` held at their start), the
    covariance of the estimated entries, each frame's attitude and its covariance (rad², about the
    camera axes), the noise floor the data needed, and the statistics of the fit."""

    theta: np.ndarray
    names: tuple[str, ...]
    cov: np.ndarray
    R: list
    R_cov: list
    sigma_floor_px: float
    chi2_reduced_model: float      # with the centroider's σ alone
    chi2_reduced: float            # with the floor (1 by construction when a floor was needed)
    dof: int
    n_stars: int
    n_rejected: int
    residual_rms_px: float
    used: list = field(default_factory=list)        # per frame: bool mask of the stars kept
    residuals: list = field(default_factory=list)   # per frame: (n, 2) measured − fitted, px
    success: bool = True
    message: str = ""

    @property
    def sigma(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))

    @property
    def x(self) -> np.ndarray:
        return np.array([self.theta[THETA_NAMES.index(n)] for n in self.names])

    def camera(self, nominal: PinholeBrown) -> PinholeBrown:
        f, u0, v0, k1, k2 = self.theta
        return nominal.with_params(fx=f, fy=f, cx=u0, cy=v0, k1=k1, k2=k2)


def field_of_view_deg(camera: PinholeBrown) -> tuple[float, float]:
    """(horizontal, vertical) field of view in degrees: the angle between the rays through the middles
    of the detector's outer edges, on the row and the column of the principal point (pixel edges at
    −0.5 and W − 0.5). Distortion included: the angle the sky subtends across the detector."""
    W, H = camera.width, camera.height
    d = camera.unproject(np.array([[-0.5, camera.cy], [W - 0.5, camera.cy], [camera.cx, -0.5], [camera.cx, H - 0.5]]))
    return (float(np.degrees(np.arccos(np.clip(d[0] @ d[1], -1, 1)))),
            float(np.degrees(np.arccos(np.clip(d[2] @ d[3], -1, 1)))))


def _theta0(camera: PinholeBrown) -> np.ndarray:
    return np.array([camera.fx, camera.cx, camera.cy, camera.k1, camera.k2], float)


def _model(theta_full, rotvecs, frames, base_params, R0):
    """Projected pixels and the Jacobian blocks per frame: (uv (n,2), d/dθ (n,2,5), d/drot (n,2,3))."""
    params = base_params.copy()
    params[[0, 1, 2, 3, 4, 5]] = [theta_full[0], theta_full[0], *theta_full[1:5]]
    out = []
    cam_params = params
    for k, fo in enumerate(frames):
        Rk = Rotation.from_rotvec(rotvecs[k]).as_matrix() @ R0[k]
        p = fo.dirs_icrs @ Rk.T
        uv, du_dp, du_dk = _project(p, cam_params)
        du_dth = du_dk @ _T9
        # left perturbation R ← exp([δ]×) R: ∂p/∂δ = −[p]×
        px = np.zeros((len(p), 3, 3))
        px[:, 0, 1], px[:, 0, 2] = p[:, 2], -p[:, 1]
        px[:, 1, 0], px[:, 1, 2] = -p[:, 2], p[:, 0]
        px[:, 2, 0], px[:, 2, 1] = p[:, 1], -p[:, 0]
        du_drot = du_dp @ px
        out.append((uv, du_dth, du_drot))
    return out


def _project(p, params):
    from rigsim.optics.camera import project

    return project(p, params, get_gradients=True)


def _solve(frames, sig, camera0, est_idx, prior_sigma, R0, theta_start):
    """Weighted least squares (Levenberg–Marquardt) over θ[est_idx] and one rotation vector per frame."""
    base = camera0.params().astype(float)
    th0 = _theta0(camera0)
    nf = len(frames)
    ne = len(est_idx)
    prior_w = np.array([0.0 if prior_sigma[i] is None else 1.0 / prior_sigma[i] for i in est_idx])

    def unpack(x):
        th = theta_start.copy()
        th[est_idx] = x[:ne]
        return th, x[ne:].reshape(nf, 3)

    def fun(x):
        th, rv = unpack(x)
        res = [((uv - fo.uv) / s).ravel() for (uv, _, _), fo, s in zip(_model(th, rv, frames, base, R0), frames, sig)]
        res.append(prior_w * (th[est_idx] - th0[est_idx]))
        r = np.concatenate(res)
        return np.where(np.isfinite(r), r, 1e6)

    def jac(x):
        th, rv = unpack(x)
        blocks = _model(th, rv, frames, base, R0)
        rows = sum(2 * len(fo) for fo in frames) + ne
        J = np.zeros((rows, ne + 3 * nf))
        r0 = 0
        for k, ((_, dth, drot), fo, s) in enumerate(zip(blocks, frames, sig)):
            n = len(fo)
            w = 1.0 / s  # (n, 2)
            J[r0:r0 + 2 * n, :ne] = (dth[:, :, est_idx] * w[:, :, None]).reshape(2 * n, ne)
            J[r0:r0 + 2 * n, ne + 3 * k:ne + 3 * k + 3] = (drot * w[:, :, None]).reshape(2 * n, 3)
            r0 += 2 * n
        J[r0:r0 + ne, :ne] = np.diag(prior_w)
        return np.where(np.isfinite(J), J, 0.0)

    x = np.concatenate([theta_start[est_idx], np.zeros(3 * nf)])
    r = fun(x)
    cost = float(r @ r)
    lam, ok, message = 1e-6, False, "iteration limit"
    for _ in range(100):  # Levenberg–Marquardt on the (small) normal equations
        J = jac(x)
        A, g = J.T @ J, J.T @ r
        D = np.diag(np.maximum(np.diag(A), 1e-30))
        while True:
            try:
                step = -np.linalg.solve(A + lam * D, g)
            except np.linalg.LinAlgError:
                step = None
            if step is not None:
                r_new = fun(x + step)
                c_new = float(r_new @ r_new)
                if c_new <= cost:
                    break
            lam *= 10.0
            if lam > 1e12:
                step = None
                break
        if step is None:
            ok, message = True, "no step lowers the cost"
            break
        gained = cost - c_new
        x, r, cost = x + step, r_new, c_new
        lam = max(lam / 10.0, 1e-12)
        if gained <= 1e-10 * max(cost, 1.0):  # χ² no longer moves (Gauss–Newton converges quadratically)
            ok, message = True, "converged"
            break
    th, rv = unpack(x)
    Rs = [Rotation.from_rotvec(rv[k]).as_matrix() @ R0[k] for k in range(nf)]
    J = jac(x)
    try:
        cov_all = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov_all = np.linalg.pinv(J.T @ J)
    return th, Rs, cov_all, ok, message


def bundle_adjust(frames: list[FrameObs], camera0: PinholeBrown, R0: list, *,
                  estimate: tuple[str, ...] = THETA_NAMES, prior_sigma: dict | None = None,
                  sigma_floor_px: float | str = "estimate", reject_sigma: float = 5.0, max_rounds: int = 5
                  ) -> BundleResult:
    """Fit θ (``estimate``, a subset of ``THETA_NAMES``) and every frame's attitude to identified
    stars. ``camera0``: the nominal camera (start and prior mean); ``R0``: each frame's starting
    attitude R(cam←ICRS) (e.g. from its identification); ``prior_sigma``: name → 1σ of the nominal
    value (None or absent: no prior). ``sigma_floor_px``: "estimate" (from the residuals) or a
    value in px. Frames with fewer than 3 stars are left out (their attitude is NaN)."""
    names = tuple(n for n in THETA_NAMES if n in estimate)
    unknown = set(estimate) - set(THETA_NAMES)
    if unknown:
        raise ValueError(f"estimate = {sorted(unknown)}: allowed {', '.join(THETA_NAMES)}")
    est_idx = np.array([THETA_NAMES.index(n) for n in names], int)
    ps = [None if prior_sigma is None else prior_sigma.get(n) for n in THETA_NAMES]
    keep_frames = [k for k, fo in enumerate(frames) if len(fo) >= 3]
    th_start = _theta0(camera0)
    nan_R = np.full((3, 3), np.nan)
    if not keep_frames:
        return BundleResult(th_start, names, np.full((len(names), len(names)), np.nan), [nan_R] * len(frames),
                            [nan_R] * len(frames), float("nan"), float("nan"), float("nan"), 0, 0, 0, float("nan"),
                            success=False, message="no frame has 3 identified stars")
    used = [np.ones(len(frames[k]), bool) for k in keep_frames]
    R_start = [np.asarray(R0[k], float) for k in keep_frames]
    floor = 0.0 if sigma_floor_px == "estimate" else float(sigma_floor_px)
    n_rej = 0
    n0 = sum(2 * len(frames[k]) for k in keep_frames) - 3 * len(keep_frames) - len(names)
    if n0 <= 0:
        return BundleResult(th_start, names, np.full((len(names), len(names)), np.nan), [nan_R] * len(frames),
                            [nan_R] * len(frames), float("nan"), float("nan"), float("nan"), int(n0), 0, 0, float("nan"),
                            success=False, message=f"{n0} degrees of freedom: too few stars for "
                                                   f"{len(names)} intrinsics and {len(keep_frames)} attitudes")
    for _ in range(max_rounds):
        fr = [FrameObs(frames[k].uv[m], frames[k].sigma_uv[m], frames[k].dirs_icrs[m]) for k, m in zip(keep_frames, used)]
        n_obs = sum(2 * len(f) for f in fr)
        dof = n_obs - 3 * len(fr) - len(names)
        if dof <= 0:  # (rejections never take a frame below 3 stars, so only after a first solve)
            break
        sig_model = [f.sigma_uv for f in fr]
        th, Rs, cov_all, ok, msg = _solve(fr, sig_model, camera0, est_idx, ps, R_start, th_start)
        resid = [f.uv - uv for f, (uv, _, _) in zip(fr, _model(th, np.zeros((len(fr), 3)), fr, camera0.params(), Rs))]
        chi2_model = sum(float(np.sum((r / s) ** 2)) for r, s in zip(resid, sig_model)) / dof
        if sigma_floor_px == "estimate":
            floor = _floor_for_unit_chi2(resid, sig_model, dof) if chi2_model > 1.0 + 2.0 * np.sqrt(2.0 / dof) else 0.0
        sig = [np.sqrt(s ** 2 + floor ** 2) for s in sig_model]
        if floor > 0:
            th, Rs, cov_all, ok, msg = _solve(fr, sig, camera0, est_idx, ps, Rs, th)
            resid = [f.uv - uv for f, (uv, _, _) in zip(fr, _model(th, np.zeros((len(fr), 3)), fr, camera0.params(), Rs))]
        chi2 = sum(float(np.sum((r / s) ** 2)) for r, s in zip(resid, sig)) / dof
        # leave out every star beyond reject_sigma (keeping 3 per frame), then refit
        changed = False
        for j, (r, s) in enumerate(zip(resid, sig)):
            z = np.sqrt(np.sum((r / s) ** 2, axis=1) / 2.0)
            bad = np.flatnonzero(z > reject_sigma)
            bad = bad[np.argsort(-z[bad])][:max(0, int(used[j].sum()) - 3)]
            if bad.size:
                used[j][np.flatnonzero(used[j])[bad]] = False
                n_rej += int(bad.size)
                changed = True
        R_start, th_start = Rs, th
        if not changed:
            break
    ne = len(names)
    cov = cov_all[:ne, :ne]
    R_full, Rc_full, used_full, res_full = [], [], [], []
    pos = {k: j for j, k in enumerate(keep_frames)}
    for k in range(len(frames)):
        if k in pos:
            j = pos[k]
            R_full.append(Rs[j])
            Rc_full.append(cov_all[ne + 3 * j:ne + 3 * j + 3, ne + 3 * j:ne + 3 * j + 3])
            used_full.append(used[j])
            full = np.full((len(frames[k]), 2), np.nan)
            full[used[j]] = resid[j]
            res_full.append(full)
        else:
            R_full.append(nan_R)
            Rc_full.append(nan_R)
            used_full.append(np.zeros(len(frames[k]), bool))
            res_full.append(np.full((len(frames[k]), 2), np.nan))
    allr = np.concatenate(resid)
    return BundleResult(th, names, cov, R_full, Rc_full, float(floor), float(chi2_model), float(chi2), int(dof),
                        int(sum(len(f) for f in fr)), n_rej, float(np.sqrt(np.mean(allr ** 2))), used_full, res_full,
                        bool(ok), str(msg))


def _floor_for_unit_chi2(resid, sig, dof) -> float:
    """The s (px) for which Σ r² / (σ² + s²) = dof (bisection on a monotone function)."""
    r2 = np.concatenate([np.ravel(r) ** 2 for r in resid])
    s2 = np.concatenate([np.ravel(s) ** 2 for s in sig])
    lo, hi = 0.0, float(np.sqrt(np.max(r2)) + 1.0)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if np.sum(r2 / (s2 + mid * mid)) > dof:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class HeldOut:
    """Stars of frames left out of the calibration, predicted with it (each frame's attitude fitted
    to its own stars with the calibrated camera): the rms of measured − predicted (px), and of the
    same divided by its σ (centroid σ with the floor, plus the calibration's covariance propagated)."""

    frame: int
    n_stars: int
    rms_px: float
    z_rms: float


def predict_frame(fo: FrameObs, cal: BundleResult, camera0: PinholeBrown, R0):
    """(residuals (n, 2) px, their σ (n, 2) px) of one frame's stars under the calibration ``cal``:
    the frame's attitude is refitted to its stars (3 parameters), the calibration is held. The σ
    combine the centroid σ (with ``cal``'s floor), the calibration's covariance propagated, and the
    attitude fit's own loss of degrees of freedom (leverage)."""
    cam = cal.camera(camera0)
    sig = np.sqrt(fo.sigma_uv ** 2 + cal.sigma_floor_px ** 2)
    one = bundle_adjust([fo], cam, [R0], estimate=(), sigma_floor_px=cal.sigma_floor_px, reject_sigma=np.inf)
    R = one.R[0]
    p = fo.dirs_icrs @ R.T
    uv, du_dp, du_dk = _project(p, cam.params())
    r = fo.uv - uv
    est_idx = [THETA_NAMES.index(n) for n in cal.names]
    Jth = (du_dk @ _T9)[:, :, est_idx]  # (n, 2, ne)
    # the attitude refit absorbs part of an intrinsics error: project Jθ onto the attitude's complement
    px = np.zeros((len(p), 3, 3))
    px[:, 0, 1], px[:, 0, 2] = p[:, 2], -p[:, 1]
    px[:, 1, 0], px[:, 1, 2] = -p[:, 2], p[:, 0]
    px[:, 2, 0], px[:, 2, 1] = p[:, 1], -p[:, 0]
    Jr = (du_dp @ px).reshape(-1, 3) / sig.reshape(-1, 1)
    Jt = Jth.reshape(-1, len(est_idx)) / sig.reshape(-1, 1)
    P = np.eye(Jr.shape[0]) - Jr @ np.linalg.pinv(Jr)
    C = P @ Jt @ cal.cov @ Jt.T @ P.T + P @ P.T  # whitened covariance of the residuals
    var = np.diag(C).reshape(-1, 2) * sig ** 2
    return r, np.sqrt(var)


def held_out_check(frames: list[FrameObs], camera0: PinholeBrown, R0: list, *, max_folds: int = 8, **kw) -> list[HeldOut]:
    """Leave frames out in turn (each frame alone when there are at most ``max_folds``, else
    ``max_folds`` groups of consecutive frames): calibrate on the others (:func:`bundle_adjust` with
    ``kw``) and predict each left-out frame's stars (:func:`predict_frame`)."""
    out = []
    ok = [k for k, fo in enumerate(frames) if len(fo) >= 3]
    if len(ok) < 2:
        return out
    for group in np.array_split(np.array(ok), min(len(ok), max_folds)):
        rest = [j for j in ok if j not in set(group.tolist())]
        cal = bundle_adjust([frames[j] for j in rest], camera0, [R0[j] for j in rest], **kw)
        if not (cal.success and np.all(np.isfinite(cal.cov))):
            continue  # nothing to predict with (too few stars in the rest)
        for k in group:
            r, s = predict_frame(frames[k], cal, camera0, R0[k])
            out.append(HeldOut(int(k), len(frames[k]), float(np.sqrt(np.mean(r ** 2))),
                               float(np.sqrt(np.mean((r / s) ** 2)))))
    return out
