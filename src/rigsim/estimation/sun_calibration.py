"""Unified intrinsic + extrinsic least-squares calibration of a sun sensor on a turntable
(seed 001 step B; seed 000 step 1).

Observation i: turntable readings θ_i and the centroid (u_i, v_i) of the sun image. Model:

    s_i = R_sun_from_mount · R_rot_from_mount(θ_i)ᵀ · d_rot        (sun direction, sensor frame)
    (u_i, v_i) = PinholeBrown(fx, fy, cx, cy, k1, k2, p1, p2[, k3]).project(s_i)

Unknowns: the intrinsics and a small rotation δ with R_sun_from_mount = exp([δ]×) R₀
(R₀ from a Kabsch/Wahba start), so the covariance of δ is directly the per-axis
uncertainty of R(sun←rot) in the sensor frame. Solved with scipy.optimize.least_squares;
covariance = s²(JᵀJ)⁻¹ with s² the residual variance (or a known centroid σ).

Outliers (``outlier_sigma``): a frame whose residual, over its centroid's own 1σ and over the
robust (MAD) scale of all such normalised residuals, exceeds the limit is left out and the fit is
repeated until no frame does. The first judgement uses a Cauchy-loss fit, which an outlier with
leverage cannot bend towards itself (docs/campaign.md, "Outliers in the sweep").

With the centroids' σ, an unweighted fit is judged against their rms σ̄
(:class:`~rigsim.estimation.fit_quality.FitQuality`): the covariance is then the noise model's,
σ̄²(JᵀJ)⁻¹, scaled by χ²/dof when that is above 1 beyond chance — the residual scatter's,
s²(JᵀJ)⁻¹ with s² = RSS/dof. ``weighted``: each residual is weighted by 1/√(σᵢ² + s²), with the
floor s that brings χ²/dof to 1 (0 when the σ alone fit); the covariance is (JᵀWJ)⁻¹, and the fit
is judged against each frame's own σ.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from rigsim.estimation.fit_quality import FitQuality, judge_residuals
from rigsim.optics.camera import PinholeBrown, project
from rigsim.rig.turntable import TurntableModel, as_reading

INTRINSIC_NAMES = ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"]


@dataclass
class SunCalibration:
    camera: PinholeBrown
    R_sun_from_rot: np.ndarray
    param_names: list[str]
    params: np.ndarray
    covariance: np.ndarray
    rms_px: float
    n_points: int
    residuals_px: np.ndarray = field(repr=False)  # of the frames used
    uv: np.ndarray = field(repr=False)  # the frames used
    outliers: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # input rows left out as outliers
    outside_field: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # input rows beyond the field
    fit: FitQuality | None = None  # the residuals against the centroids' σ (when the caller gave one)
    noise_floor_px: float = 0.0  # weighted fit: the σ added to every centroid's in quadrature (noise_floor)

    @property
    def sigma(self) -> dict[str, float]:
        return dict(zip(self.param_names, np.sqrt(np.diag(self.covariance))))

    @property
    def rotation_covariance_rad2(self) -> np.ndarray:
        """Covariance of the small rotation error of R(sun←rot), about the sensor axes."""
        return self.covariance[-3:, -3:]


def _skew(v: np.ndarray) -> np.ndarray:
    """[v]× of one 3-vector."""
    x, y, w = (float(c) for c in v)
    return np.array([[0.0, -w, y], [w, 0.0, -x], [-y, x, 0.0]])


def _so3_left_jacobian(d: np.ndarray) -> np.ndarray:
    """J_l(δ) with exp([δ + ε]×) ≈ exp([J_l ε]×)·exp([δ]×): I + (1−cos θ)/θ²·[δ]× + (θ−sin θ)/θ³·[δ]×²."""
    th = float(np.linalg.norm(d))
    K = _skew(np.asarray(d, float))
    if th < 1e-6:  # series: the terms above lose precision near 0
        return np.eye(3) + 0.5 * K + K @ K / 6.0
    # (1 − cos θ)/θ² as 2·sin²(θ/2)/θ²: 1 − cos θ cancels to a relative error ε/θ² (1e-4 at θ = 1e-6)
    return np.eye(3) + 2.0 * np.sin(0.5 * th) ** 2 / th**2 * K + (th - np.sin(th)) / th**3 * (K @ K)


class SweepModel:
    """The calibration's residuals and their analytic Jacobian: unknowns x = (the intrinsics named in
    ``names``, δ) with R(sun←mount) = exp([δ]×)·R_ref; residuals = projected − measured centroids
    (2N,). ∂uv/∂intrinsics comes from the camera model; ∂uv/∂δ = ∂uv/∂s · (−[s]× J_l(δ))."""

    def __init__(self, m_dirs: np.ndarray, uv: np.ndarray, names):
        self.m_dirs, self.uv, self.names = np.asarray(m_dirs, float), np.asarray(uv, float), list(names)
        self.cols = [INTRINSIC_NAMES.index(k) for k in self.names]

    def params(self, x) -> np.ndarray:
        q = np.zeros(len(INTRINSIC_NAMES))
        q[self.cols] = x[: len(self.names)]
        return q

    def residual(self, x, R_ref) -> np.ndarray:
        R = Rotation.from_rotvec(x[-3:]).as_matrix() @ R_ref
        return (project(self.m_dirs @ R.T, self.params(x)) - self.uv).ravel()

    def jacobian(self, x, R_ref) -> np.ndarray:
        R = Rotation.from_rotvec(x[-3:]).as_matrix() @ R_ref
        s = self.m_dirs @ R.T
        _, du_ds, du_dq = project(s, self.params(x), get_gradients=True)
        # ∂uv/∂s·(−[s]×): each row g of ∂uv/∂s becomes (s × g)ᵀ; then one (2N, 3)·J_l(δ) product
        g0, g1, g2 = du_ds[..., 0], du_ds[..., 1], du_ds[..., 2]
        s0, s1, s2 = (c[:, None] for c in s.T)
        sxg = np.stack([s1 * g2 - s2 * g1, s2 * g0 - s0 * g2, s0 * g1 - s1 * g0], axis=-1)
        n = len(self.names)
        J = np.empty(du_ds.shape[:2] + (n + 3,))
        J[..., :n] = du_dq[..., self.cols]
        J[..., n:] = (sxg.reshape(-1, 3) @ _so3_left_jacobian(x[-3:])).reshape(sxg.shape)
        return J.reshape(-1, n + 3)


def sun_directions_in_mount(model: TurntableModel, poses: Mapping[str, np.ndarray], d_rot=(0.0, 0.0, 1.0)) -> np.ndarray:
    """(N, 3) sun directions in the mount frame for poses {label: angles (N,)}."""
    R = model.R_rot_from_mount(poses)  # (N, 3, 3)
    d = np.asarray(d_rot, float) / np.linalg.norm(d_rot)
    return np.einsum("nji,j->ni", R, d)


def calibrate_sun_sensor(
    poses_rad: Mapping[str, np.ndarray],
    uv: np.ndarray,
    model: TurntableModel,
    width: int,
    height: int,
    f_guess_px: float,
    d_rot=(0.0, 0.0, 1.0),
    fit_k3: bool = False,
    fit_tangential: bool = True,
    centroid_sigma_px: float | None = None,
    sigma_uv: np.ndarray | None = None,
    outlier_sigma: float = 0.0,
    max_field_deg: float = 90.0,
    noise_source: str = "the centroids' σ",
    weighted: bool = False,
) -> SunCalibration:
    """Fit intrinsics and R(sun←rot) to observed sun-image centroids.

    ``poses_rad``: the turntable *readings* per observation (a :class:`~rigsim.rig.turntable.TurntableReading`
    of arrays, or a mapping {label: rad array}; a true pose is refused); ``uv``: (N, 2) centroids.
    ``f_guess_px``: design focal length in pixels (a starting value only). ``sigma_uv``: each
    centroid's 1σ (N, 2) or None (all equal); it scales the outlier test, and with ``weighted`` it
    weights the fit (module docstring), else the fit is unweighted.
    ``outlier_sigma`` > 0: leave out, and refit without, every frame whose normalised residual
    (module docstring) exceeds it; 0 keeps every frame. ``max_field_deg`` < 90: leave out every frame
    whose centroid lies farther than that from the axis, through the nominal camera (``f_guess_px``,
    principal point at the detector's centre): the sensor's usable field. ``noise_source``: with
    ``sigma_uv`` (finite and > 0 everywhere), the fit is judged against it (``SunCalibration.fit``)
    and the covariance is the noise model's, scaled by χ²/dof beyond chance (module docstring);
    the phrase names the σ in the reports.
    """
    uv = np.asarray(uv, float)
    m_dirs = sun_directions_in_mount(model, as_reading(poses_rad), d_rot)
    inside = np.arange(len(uv))
    if max_field_deg < 90.0:
        r = np.hypot(uv[:, 0] - (width - 1) / 2, uv[:, 1] - (height - 1) / 2)
        inside = np.flatnonzero(r <= f_guess_px * np.tan(np.radians(max_field_deg)))
    n = len(inside)
    if n < 8:
        raise ValueError(f"calibration needs at least 8 points on the detector, got {n}"
                         + (f" within {max_field_deg:g}° of the axis" if n < len(uv) else ""))
    sig_in = None if sigma_uv is None else np.array(np.broadcast_to(np.asarray(sigma_uv, float), uv.shape))[inside]
    # equal σ weigh every frame alike: the unweighted fit is the same solution, at a third of the cost
    weighted = bool(weighted and sig_in is not None and np.all(np.isfinite(sig_in)) and np.all(sig_in > 0)
                    and np.ptp(sig_in) > 0.0)
    fit = _judge(m_dirs[inside], uv[inside], sig_in, outlier_sigma, width, height, f_guess_px, fit_k3, fit_tangential,
                 centroid_sigma_px, weighted)
    fit.outliers = inside[fit.outliers]
    fit.outside_field = np.setdiff1d(np.arange(len(uv)), inside)
    if sigma_uv is not None:
        sig = np.array(np.broadcast_to(np.asarray(sigma_uv, float), uv.shape))
        used = np.setdiff1d(inside, fit.outliers)
        if np.all(np.isfinite(sig[used])) and np.all(sig[used] > 0):
            if weighted:
                q = judge_residuals(fit.residuals_px, sig[used], len(fit.params),
                                    f"{noise_source}, rms {float(np.sqrt(np.mean(sig[used] ** 2))):.3g} px, each frame's own")
                fit.fit = dataclasses.replace(q, floor=fit.noise_floor_px if q.beyond_chance else 0.0)
            else:
                _judge_against_noise(fit, sig[used], noise_source)
    return fit


def _judge_against_noise(fit: SunCalibration, sig: np.ndarray, noise_source: str) -> None:
    """Judge the fit against the centroids' σ (its used frames') and put the noise model's covariance,
    scaled by χ²/dof beyond chance, in place of the residual scatter's. The fit is unweighted, so
    it is judged against one σ, the rms of the frames' (a frame with a small σ would otherwise
    weigh in the χ² what it does not weigh in the fit)."""
    s_rms = float(np.sqrt(np.mean(sig**2)))
    fit.fit = judge_residuals(fit.residuals_px, s_rms, len(fit.params), f"{noise_source}, rms {s_rms:.3g} px")
    res = fit.residuals_px.ravel()
    s2 = float(res @ res) / max(res.size - len(fit.params), 1)
    if s2 > 0 and np.isfinite(s2):
        fit.covariance = fit.covariance * (s_rms**2 * fit.fit.covariance_scale / s2)


def _judge(m_dirs, uv, sigma_uv, outlier_sigma, width, height, f_guess_px, fit_k3, fit_tangential,
           centroid_sigma_px, weighted: bool = False) -> SunCalibration:
    """The fit with the outlier test of :func:`calibrate_sun_sensor` (``outliers`` index ``uv``)."""
    n = len(uv)
    def fit_all(m, u, *a, rows=None):
        if not weighted:
            return _fit(m, u, *a)
        return _weighted_fit(m, u, sigma_uv if rows is None else np.asarray(sigma_uv)[rows], *a)
    fit = fit_all(m_dirs, uv, width, height, f_guess_px, fit_k3, fit_tangential, centroid_sigma_px)
    if outlier_sigma <= 0.0:
        return fit
    sig = np.ones_like(uv) if sigma_uv is None else np.array(np.broadcast_to(sigma_uv, uv.shape))
    good = np.isfinite(sig) & (sig > 0.0)
    sig[~good] = float(np.median(sig[good])) if good.any() else 1.0  # an unknown σ: the typical one
    plain, used = fit, np.arange(n)
    z = np.abs(_robust_residuals(fit, m_dirs, uv, sig)) / sig
    for _ in range(10):  # every frame is judged against each new fit (a frame left out may come back)
        scale = 1.4826 * float(np.median(z[used]))
        if not scale > 0.0:
            break
        keep = np.flatnonzero(z.max(axis=1) <= outlier_sigma * scale)
        if len(keep) < 8 or np.array_equal(keep, used):
            break
        try:
            refit = fit_all(m_dirs[keep], uv[keep], width, height, f_guess_px, fit_k3, fit_tangential, centroid_sigma_px,
                            rows=keep)
        except ValueError:  # a non-physical camera on the frames left: keep the last fit
            break
        used, fit = keep, refit
        z = np.abs(fit.camera.project(m_dirs @ fit.R_sun_from_rot.T) - uv) / sig
    if len(used) == n:
        return plain
    fit.outliers = np.setdiff1d(np.arange(n), used)
    return fit


def noise_floor(residuals, sigma, n_params: int) -> float:
    """The floor s ≥ 0 that, added in quadrature to each residual's σ, makes χ²/dof = 1 (0 when the
    σ alone leave χ²/dof ≤ 1): what the residuals show beyond the centroids' noise (the model's own
    errors: the turntable's, the distortion model's)."""
    from scipy.optimize import brentq

    r2 = np.asarray(residuals, float).ravel() ** 2
    v = np.broadcast_to(np.asarray(sigma, float), np.shape(residuals)).ravel() ** 2
    dof = max(r2.size - n_params, 1)

    def excess(s):
        return float(np.sum(r2 / (v + s * s))) / dof - 1.0

    if excess(0.0) <= 0.0:
        return 0.0
    hi = float(np.sqrt(np.mean(r2))) * 2.0 + 1e-12
    while excess(hi) > 0.0:
        hi *= 2.0
    return float(brentq(excess, 0.0, hi, xtol=1e-9 * hi))


def _weighted_fit(m_dirs, uv, sigma_uv, width, height, f_guess_px, fit_k3, fit_tangential, centroid_sigma_px):
    """The least squares weighted by each centroid's σ in quadrature with :func:`noise_floor`'s floor,
    which is found from the residuals (twice: from the unweighted fit's, then the weighted fit's)."""
    sig = np.array(np.broadcast_to(np.asarray(sigma_uv, float), np.shape(uv)))
    fit = _fit(m_dirs, uv, width, height, f_guess_px, fit_k3, fit_tangential, centroid_sigma_px)
    s = 0.0
    for _ in range(2):
        s = noise_floor(fit.residuals_px, sig, len(fit.params))
        fit = _fit(m_dirs, uv, width, height, f_guess_px, fit_k3, fit_tangential, centroid_sigma_px,
                   weights=1.0 / np.sqrt(sig**2 + s * s))
    fit.noise_floor_px = s
    return fit


def _robust_residuals(fit: SunCalibration, m_dirs, uv, sig) -> np.ndarray:
    """Residuals (N, 2) of a fit that outliers cannot pull: the plain fit's model refitted with a
    Cauchy loss on the residuals over each centroid's σ (scale 3σ). A frame far off at the field's
    edge, where the distortion terms have leverage, bends a least-squares fit towards itself and
    hides its own residual; here it does not."""
    names = fit.param_names[:-3]
    sm = SweepModel(m_dirs, uv, names)
    R = fit.R_sun_from_rot
    w = 1.0 / sig.ravel()
    x = np.concatenate([fit.params[:-3], np.zeros(3)])
    # the Cauchy M-estimate by iteratively reweighted least squares: each pass is a weighted least
    # squares (MINPACK's Levenberg–Marquardt) with the weights 1/(1 + (r/3σ)²) of the last pass's
    # residuals, until they settle. The same estimate as scipy's trust-region fit with loss="cauchy",
    # whose SVD of the whole Jacobian made it four times the plain fit's cost.
    c = 1.0 / (1.0 + (sm.residual(x, R) * w / 3.0) ** 2)
    for _ in range(30):
        ww = w * np.sqrt(c)
        x = least_squares(lambda p: sm.residual(p, R) * ww, x, jac=lambda p: sm.jacobian(p, R) * ww[:, None],
                          method="lm", x_scale="jac").x
        c_new = 1.0 / (1.0 + (sm.residual(x, R) * w / 3.0) ** 2)
        done = np.max(np.abs(c_new - c)) < 1e-3
        c = c_new
        if done:
            break
    return sm.residual(x, R).reshape(-1, 2)


def _fit(m_dirs, uv, width, height, f_guess_px, fit_k3, fit_tangential, centroid_sigma_px,
         weights=None) -> SunCalibration:
    """The least squares of :func:`calibrate_sun_sensor` on the given frames; ``weights`` (N, 2): each
    residual's 1/σ (None: unweighted; the covariance is then the residual scatter's or the given σ's)."""
    n = len(uv)
    names = ["fx", "fy", "cx", "cy", "k1", "k2"] + (["p1", "p2"] if fit_tangential else []) + (["k3"] if fit_k3 else [])
    p0 = {"fx": f_guess_px, "fy": f_guess_px, "cx": (width - 1) / 2, "cy": (height - 1) / 2}

    def camera(x) -> PinholeBrown:
        d = dict(zip(names, x[: len(names)]))
        return PinholeBrown(**{k: d.get(k, 0.0) for k in INTRINSIC_NAMES}, width=width, height=height)

    # Start: undistorted pinhole with the guess, rotation by Wahba (scipy align_vectors).
    cam0 = PinholeBrown(f_guess_px, f_guess_px, p0["cx"], p0["cy"], width=width, height=height)
    s_obs = cam0.unproject(uv)
    R0 = Rotation.align_vectors(s_obs, m_dirs)[0].as_matrix()
    x_int = np.array([p0.get(k, 0.0) for k in names])

    sm = SweepModel(m_dirs, uv, names)
    if weights is None:
        residual, jacobian = sm.residual, sm.jacobian
    else:
        w = np.asarray(weights, float).ravel()

        def residual(x, R):
            return sm.residual(x, R) * w

        def jacobian(x, R):
            return sm.jacobian(x, R) * w[:, None]

    # first pass from the start; the second re-linearises δ around its estimate (δ ≈ 0 at the end,
    # so the covariance of δ is that of R(sun←rot) about the sensor axes)
    sol = least_squares(residual, np.concatenate([x_int, np.zeros(3)]), jac=jacobian, args=(R0,), method="lm",
                        xtol=1e-14, ftol=1e-14, gtol=1e-14, x_scale="jac")
    R_ref = Rotation.from_rotvec(sol.x[-3:]).as_matrix() @ R0
    x = np.concatenate([sol.x[:-3], np.zeros(3)])
    sol = least_squares(residual, x, jac=jacobian, args=(R_ref,), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        x_scale="jac")
    R_fin = Rotation.from_rotvec(sol.x[-3:]).as_matrix() @ R_ref
    res = sol.fun if weights is None else sol.fun / w
    dof = max(res.size - sol.x.size, 1)
    if weights is None:
        s2 = centroid_sigma_px**2 if centroid_sigma_px is not None else float(res @ res) / dof
    else:  # the weights are the residuals' 1/σ: the covariance is the noise model's, χ²/dof 1 by construction
        s2 = 1.0
    J = sol.jac
    cov = np.linalg.pinv(J.T @ J) * s2
    return SunCalibration(
        camera=camera(sol.x),
        R_sun_from_rot=R_fin,
        param_names=names + ["rx", "ry", "rz"],
        params=np.concatenate([sol.x[:-3], np.zeros(3)]),
        covariance=cov,
        rms_px=float(np.sqrt(np.mean(res.reshape(-1, 2) ** 2) * 2)),
        n_points=n,
        residuals_px=res.reshape(-1, 2),
        uv=uv,
    )


def sweep_poses(axes: Sequence[str], range_deg: float, step_deg: float, fixed: Mapping[str, float] | None = None) -> dict[str, np.ndarray]:
    """Grid of poses over two axes, ±range every step (seed 001: ±60° every 5°)."""
    k = int(round(range_deg / step_deg))
    vals = np.radians(np.arange(-k, k + 1) * step_deg)
    A, B = np.meshgrid(vals, vals, indexing="ij")
    poses = {axes[0]: A.ravel(), axes[1]: B.ravel()}
    for lab, v in (fixed or {}).items():
        poses[lab] = np.full(A.size, v)
    return poses
