"""The truth side of a rig: every true quantity of one rig instance, and its random errors.

Estimators never import this module. Renderers and the analytic campaigns do.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.frames import RAD_PER_ARCSEC
from rigsim.optics.cube import face_normal_cube
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import NOMINAL_D, AxisKinematics, TruePose, TurntableModel


def _perp_basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(d, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(d, e1)


def tilt(d: np.ndarray, eps_rad: np.ndarray) -> np.ndarray:
    """Tilt unit vector ``d`` by the 2-vector ``eps`` (rad) about two axes perpendicular to it."""
    e1, e2 = _perp_basis(d)
    return Rotation.from_rotvec(eps_rad[0] * e1 + eps_rad[1] * e2).as_matrix() @ d


@dataclass
class Noise:
    """Random errors of one campaign (1σ)."""

    encoder_sigma_rad: dict[str, float] = field(default_factory=dict)
    null_sigma_rad: float = 0.0
    centroid_sigma_px: float = 0.0


@dataclass
class Realization:
    """Every true quantity of one rig instance (what the estimators never see)."""

    turntable: TurntableModel
    encoder_bias_rad: dict[str, float]
    d_sun_rot: np.ndarray
    R_sun_from_mount: np.ndarray
    R_cube_from_mount: np.ndarray  # ideal cube frame
    face_normals_mount: dict[str, np.ndarray]
    null_bias_rad: list[np.ndarray]  # per measured face: equivalent bias of the null (aiming mounting)
    plane_mirror_normal_mount: np.ndarray | None = None

    @property
    def R_cube_from_sun(self) -> np.ndarray:
        return self.R_cube_from_mount @ self.R_sun_from_mount.T

    def reading_to_true(self, error_rad: Mapping[str, float], free) -> Callable[[Mapping], TruePose]:
        """The turntable's true pose when it reads ``reading``: for the axes in ``free``,
        true = reading − encoder bias − ``error_rad`` (the encoder's error near this position); the
        other axes are set to their value and read back exactly."""
        bias, err, free = self.encoder_bias_rad, dict(error_rad or {}), set(free)

        def f(reading: Mapping) -> TruePose:
            return TruePose({k: (v - bias.get(k, 0.0) - err.get(k, 0.0)) if k in free else v
                             for k, v in reading.items()})

        return f


def realization_from_rig(rig: CubeMirrorRig, ideal: bool = False) -> Realization:
    """The rig file's own true errors (``ideal=True``: all errors zero)."""
    tt = TurntableModel.nominal_for(rig.turntable) if ideal else TurntableModel.true(rig.turntable)
    bias = {a.label: (0.0 if ideal else a.encoder_bias_arcsec * RAD_PER_ARCSEC) for a in rig.turntable.axes}
    mis = np.zeros(3) if ideal else np.asarray(rig.sun_simulator.direction_misalignment_arcsec) * RAD_PER_ARCSEC
    d_sun = Rotation.from_rotvec(mis).as_matrix() @ NOMINAL_D
    R_cm = rig.R_cube_from_mount()
    tilts = None if ideal else rig.cube.face_tilt_arcsec
    normals = {f: R_cm.T @ face_normal_cube(f, tilts) for f in rig.procedure.faces}
    if rig.procedure.method == "diaphragm" and not ideal:
        b = np.asarray(rig.aiming_camera.mounting_bias_arcsec) * RAD_PER_ARCSEC
        null_bias = [b[:2].copy(), b[:2].copy()]
    else:
        null_bias = [np.zeros(2), np.zeros(2)]
    pm = None
    if rig.plane_mirror is not None:
        t = np.zeros(3) if ideal else np.asarray(rig.plane_mirror.normal_tilt_arcsec) * RAD_PER_ARCSEC
        pm = Rotation.from_rotvec(t).as_matrix() @ NOMINAL_D
    return Realization(tt, bias, d_sun, rig.R_sun_from_mount(), R_cm, normals, null_bias, pm)


def noise_from_rig(rig: CubeMirrorRig) -> Noise:
    enc = {a.label: a.encoder_sigma_arcsec * RAD_PER_ARCSEC for a in rig.turntable.axes}
    return Noise(enc, rig.null_sigma_rad, rig.sun_sensor.centroid_sigma_px)


def perpendicularity_perturbed(turntable: TurntableModel, angles_rad) -> TurntableModel:
    """``turntable`` with each inner axis turned by ``angles_rad[k]`` towards its parent, about
    their common normal (k = 0: the second axis against the first, …): non-perpendicularity."""
    axes = list(turntable.axes)
    new = [axes[0]]
    for (parent, ax), e in zip(zip(axes[:-1], axes[1:]), angles_rad):
        w = np.cross(ax.direction, parent.direction)
        w /= np.linalg.norm(w)
        new.append(AxisKinematics(ax.label, Rotation.from_rotvec(float(e) * w).as_matrix() @ ax.direction))
    return TurntableModel(new)


def draw_realization(rig: CubeMirrorRig, rng: np.random.Generator, sources: set[str]) -> Realization:
    """A random rig instance: errors drawn from the rig's 1σ specifications.

    ``sources`` ⊂ {"perpendicularity", "mounting", "plane_mirror"}; others stay ideal.
    """
    base = realization_from_rig(rig, ideal=True)
    if "perpendicularity" in sources and rig.turntable.perpendicularity_sigma_arcsec > 0:
        s = rig.turntable.perpendicularity_sigma_arcsec * RAD_PER_ARCSEC
        base.turntable = perpendicularity_perturbed(
            base.turntable, [rng.normal(0.0, s) for _ in range(len(base.turntable.axes) - 1)])
    if "mounting" in sources and rig.procedure.method == "diaphragm":
        s = rig.aiming_camera.mounting_sigma_arcsec * RAD_PER_ARCSEC
        base.null_bias_rad = [rng.normal(0.0, s, 2), rng.normal(0.0, s, 2)]
    if "plane_mirror" in sources and rig.plane_mirror is not None:
        s = rig.plane_mirror.perpendicularity_spec_arcsec * RAD_PER_ARCSEC
        base.plane_mirror_normal_mount = tilt(NOMINAL_D, rng.normal(0.0, s, 2))
    return base


