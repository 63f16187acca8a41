"""Unified intrinsic + extrinsic least-squares calibration of a sun sensor on a turntable
(seed 001 step B; seed 000 step 1).

Observation i: turntable readings θ_i and the centroid (u_i, v_i) of the sun image. Model:

    s_i = R_sun_from_mount · R_rot_from_mount(θ_i)ᵀ · d_rot        (sun direction, sensor frame)
    (u_i, v_i) = PinholeBrown(fx, fy, cx, cy, k1, k2, p1, p2[, k3]).project(s_i)

Unknowns: the intrinsics and a small rotation δ with R_sun_from_mount = exp([δ]×) R₀
(R₀ from a Kabsch/Wahba start), so the covariance of δ is directly the per-axis
uncertainty of R(sun←rot) in the sensor frame. Solved with scipy.optimize.least_squares;
covariance = s²(JᵀJ)⁻¹ with s² the residual variance (or a known centroid σ).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

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
    residuals_px: np.ndarray = field(repr=False)
    uv: np.ndarray = field(repr=False)

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
    return np.eye(3) + (1.0 - np.cos(th)) / th**2 * K + (th - np.sin(th)) / th**3 * (K @ K)


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
) -> SunCalibration:
    """Fit intrinsics and R(sun←rot) to observed sun-image centroids.

    ``poses_rad``: the turntable *readings* per observation (a :class:`~rigsim.rig.turntable.TurntableReading`
    of arrays, or a mapping {label: rad array}; a true pose is refused); ``uv``: (N, 2) centroids.
    ``f_guess_px``: design focal length in pixels (a starting value only).
    """
    uv = np.asarray(uv, float)
    m_dirs = sun_directions_in_mount(model, as_reading(poses_rad), d_rot)
    n = len(uv)
    if n < 8:
        raise ValueError(f"calibration needs at least 8 points on the detector, got {n}")

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
    residual, jacobian = sm.residual, sm.jacobian

    # first pass from the start; the second re-linearises δ around its estimate (δ ≈ 0 at the end,
    # so the covariance of δ is that of R(sun←rot) about the sensor axes)
    sol = least_squares(residual, np.concatenate([x_int, np.zeros(3)]), jac=jacobian, args=(R0,), method="lm",
                        xtol=1e-14, ftol=1e-14, gtol=1e-14, x_scale="jac")
    R_ref = Rotation.from_rotvec(sol.x[-3:]).as_matrix() @ R0
    x = np.concatenate([sol.x[:-3], np.zeros(3)])
    sol = least_squares(residual, x, jac=jacobian, args=(R_ref,), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        x_scale="jac")
    R_fin = Rotation.from_rotvec(sol.x[-3:]).as_matrix() @ R_ref
    res = sol.fun
    dof = max(res.size - sol.x.size, 1)
    s2 = centroid_sigma_px**2 if centroid_sigma_px is not None else float(res @ res) / dof
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
