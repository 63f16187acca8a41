"""Turntable kinematics: the pose of the mount (inner frame) in the rot (base) frame.

A turntable is a chain of axes listed outermost first. With angles θ_k about axis
directions a_k, the innermost (mount) frame is

    R_rot_from_mount(θ) = W_1(θ_1) Rot(a_1, θ_1) · W_2(θ_2) Rot(a_2, θ_2) · …

where each axis direction a_k is its nominal X'/Y'/Z' rotated by the axis's true
misalignment (non-perpendicularity), and W_k is an optional wobble (a small tilt whose
azimuth turns with θ_k). The *true* model uses every error of the rig; the *nominal*
model (what estimators use) has ideal axes and, optionally, a different nesting order —
the documents disagree on it (docs/readings.md, option ``axis_order``).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from rigsim.errors import GeometryError
from rigsim.frames import RAD_PER_ARCSEC, rot_axis
from rigsim.rig.cube_mirror import Turntable

NOMINAL_D = np.array([0.0, 0.0, 1.0])
"""The nominal reference direction in the rot frame: +Z′, towards the sun simulator / the autocollimator."""

_E = {"X": np.array([1.0, 0.0, 0.0]), "Y": np.array([0.0, 1.0, 0.0]), "Z": np.array([0.0, 0.0, 1.0])}


@dataclass(frozen=True)
class AxisKinematics:
    label: str
    direction: np.ndarray  # unit vector in the parent frame at zero pose
    wobble_rad: float = 0.0
    wobble_phase_rad: float = 0.0

    def matrix(self, theta) -> np.ndarray:
        R = rot_axis(self.direction, theta)
        if self.wobble_rad:
            th = np.asarray(theta, dtype=float)
            e1 = np.cross(self.direction, [0.0, 0.0, 1.0] if abs(self.direction[2]) < 0.9 else [1.0, 0.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(self.direction, e1)
            ph = th + self.wobble_phase_rad
            rv = self.wobble_rad * (np.cos(ph)[..., None] * e1 + np.sin(ph)[..., None] * e2)
            W = Rotation.from_rotvec(rv.reshape(-1, 3)).as_matrix().reshape(*th.shape, 3, 3)
            R = W @ R
        return R


class TurntableModel:
    """Forward kinematics for a chain of axes (outermost first).

    Poses are mappings ``{label: angle_rad}`` (labels "X", "Y", "Z" for X', Y', Z');
    missing labels are at zero. Arrays broadcast.
    """

    def __init__(self, axes: Sequence[AxisKinematics]):
        self.axes = list(axes)
        self.labels = [a.label for a in self.axes]

    @classmethod
    def true(cls, tt: Turntable) -> "TurntableModel":
        axes = []
        for a in tt.axes:
            mis = np.asarray(a.misalignment_arcsec) * RAD_PER_ARCSEC
            d = Rotation.from_rotvec(mis).as_matrix() @ _E[a.label]
            axes.append(AxisKinematics(a.label, d / np.linalg.norm(d), a.wobble_arcsec * RAD_PER_ARCSEC, np.radians(a.wobble_phase_deg)))
        return cls(axes)

    @classmethod
    def nominal(cls, labels_outer_first: Sequence[str]) -> "TurntableModel":
        return cls([AxisKinematics(lab, _E[lab]) for lab in labels_outer_first])

    @classmethod
    def nominal_for(cls, tt: Turntable, axis_order: str | None = None) -> "TurntableModel":
        """Ideal axes; ``axis_order`` overrides the nesting (e.g. ``"XY"``: X' carries Y')."""
        labels = list(axis_order) if axis_order else [a.label for a in tt.axes]
        if sorted(labels) != sorted(a.label for a in tt.axes):
            raise ValueError(f"axis_order {axis_order!r} must be a permutation of {[a.label for a in tt.axes]}")
        return cls.nominal(labels)

    def R_rot_from_mount(self, pose: Mapping[str, float | np.ndarray]) -> np.ndarray:
        R = None
        for ax in self.axes:
            th = np.asarray(pose.get(ax.label, 0.0), dtype=float)
            M = ax.matrix(th)
            R = M if R is None else R @ M
        return R

    def solve_alignment(
        self,
        n_mount: np.ndarray,
        d_rot: np.ndarray,
        free: Sequence[str],
        start: Mapping[str, float],
        fixed: Mapping[str, float] | None = None,
        max_move_rad: float = np.radians(20.0),
    ) -> dict[str, float]:
        """Angles of the ``free`` axes (near ``start``) at which the mount vector ``n_mount``
        points along ``d_rot``; other axes at ``fixed`` (default: their ``start`` value).

        Exact to ~1e-13 rad. Raises :class:`GeometryError` if no such pose exists within
        ``max_move_rad`` of ``start``.
        """
        n_mount = np.asarray(n_mount, float) / np.linalg.norm(n_mount)
        d_rot = np.asarray(d_rot, float) / np.linalg.norm(d_rot)
        base = {lab: float(start.get(lab, 0.0)) for lab in self.labels}
        if fixed:
            base.update({k: float(v) for k, v in fixed.items()})
        free = list(free)

        def resid(x):
            pose = dict(base)
            pose.update(zip(free, x))
            return self.R_rot_from_mount(pose) @ n_mount - d_rot

        x0 = np.array([base[f] for f in free])
        sol = least_squares(resid, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
        err = np.linalg.norm(sol.fun)
        if err > 1e-10 or np.max(np.abs(sol.x - x0)) > max_move_rad:
            raise GeometryError(
                f"no pose of axes {free} within {np.degrees(max_move_rad):.0f}° of "
                f"{ {k: round(float(np.degrees(v)), 3) for k, v in base.items()} } (deg) aligns the face normal "
                f"with the beam (residual {err:.2e}); check the cube orientation and procedure.nominal_poses_deg"
            )
        out = dict(base)
        out.update(zip(free, (float(v) for v in sol.x)))
        return out


def pose_deg_to_rad(pose_deg: Mapping[str, float]) -> dict[str, float]:
    return {k: float(np.radians(v)) for k, v in pose_deg.items()}


# ------------------------------------------------------------------------------ readings vs true poses
class _Angles(Mapping):
    """Turntable angles in radians by axis label (``"X"``, ``"Y"``, ``"Z"``): floats, or equal-length
    arrays for a sweep. Immutable; ``dict(a)`` gives a plain copy."""

    __slots__ = ("_rad",)

    def __init__(self, rad: Mapping[str, float | np.ndarray] | None = None, **more):
        d = dict(rad or {})
        d.update(more)
        object.__setattr__(self, "_rad", d)

    def __setattr__(self, name, value):
        raise AttributeError(f"{type(self).__name__} is immutable")

    def __getitem__(self, label: str):
        return self._rad[label]

    def __iter__(self) -> Iterator[str]:
        return iter(self._rad)

    def __len__(self) -> int:
        return len(self._rad)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self._rad!r})"

    def __reduce__(self):
        return (type(self), (self._rad,))

    @classmethod
    def from_deg(cls, deg: Mapping[str, float | np.ndarray]):
        return cls({k: np.radians(v) if np.ndim(v) else float(np.radians(v)) for k, v in deg.items()})

    def deg(self) -> dict:
        return {k: np.degrees(v) if np.ndim(v) else float(np.degrees(v)) for k, v in self._rad.items()}

    def replace(self, **rad):
        """A copy with some axes changed (radians)."""
        return type(self)({**self._rad, **rad})


class TurntableReading(_Angles):
    """What the turntable's encoders display: true angle + encoder bias + encoder noise. The only
    turntable angles an estimator sees."""


class TruePose(_Angles):
    """The turntable's true angles: known to the simulator (truth), never to an estimator."""


def as_reading(angles) -> TurntableReading:
    """``angles`` as a :class:`TurntableReading`; a plain mapping (a user's own log) is taken as one.

    Raises TypeError for a :class:`TruePose`: estimators see readings, never true poses."""
    if isinstance(angles, TurntableReading):
        return angles
    if isinstance(angles, TruePose):
        raise TypeError("a TruePose was passed where a TurntableReading is expected: estimators see the "
                        "turntable's readings (true angle + encoder error), never its true pose")
    if isinstance(angles, Mapping):
        return TurntableReading(angles)
    raise TypeError(f"turntable angles must be a TurntableReading or a mapping {{label: rad}}, got {type(angles).__name__}")
