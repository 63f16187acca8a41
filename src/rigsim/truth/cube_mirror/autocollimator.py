"""Where the seed-001 autocollimator sits in the lab for a rig instance, and the mirror it looks at
(cube face or inner-frame plane mirror) at a true turntable pose. The instrument itself is
:mod:`rigsim.optics.autocollimator`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rigsim.errors import GeometryError
from rigsim.optics.autocollimator import MirrorTarget, _plane_axes, a_frame_basis
from rigsim.optics.cube import FACE_NORMALS, face_normal_cube
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import pose_deg_to_rad
from rigsim.truth.cube_mirror.placement import cube_pose
from rigsim.truth.cube_mirror.realization import Realization


# ------------------------------------------------------------------------------ rig layout
@dataclass(frozen=True)
class AutocollimatorLayout:
    """Where the autocollimator sits in the rot (lab) frame for one target.

    ``R_rot_from_A`` has the A frame's axes as columns; ``origin_rot`` is the A frame's origin
    (the lens centre) in rot, mm. ``anchor_rot`` is the target's centre at ``reference_pose_rad``
    (the face's exact null pose, or the zero pose for the plane mirror); the axis passes through
    it and the objective's convex vertex is ``distance_mm`` from it.
    """

    target: str
    face: str | None
    axis_rot: np.ndarray  # unit, from the target towards the autocollimator (the documents' d)
    R_rot_from_A: np.ndarray
    origin_rot: np.ndarray
    anchor_rot: np.ndarray
    reference_pose_rad: dict
    plane_mirror_centre_mount_mm: np.ndarray

    def to_A(self, p_rot) -> np.ndarray:
        return (np.asarray(p_rot, float) - self.origin_rot) @ self.R_rot_from_A

    def dir_to_A(self, v_rot) -> np.ndarray:
        return np.asarray(v_rot, float) @ self.R_rot_from_A

    @property
    def anchor_A(self) -> np.ndarray:
        return self.to_A(self.anchor_rot)

    def as_dict(self) -> dict:
        return {"target": self.target, "face": self.face, "axis_rot": self.axis_rot.tolist(),
                "R_rot_from_A": self.R_rot_from_A.tolist(), "origin_rot_mm": self.origin_rot.tolist(),
                "anchor_rot_mm": self.anchor_rot.tolist(),
                "reference_pose_deg": {k: math.degrees(v) for k, v in self.reference_pose_rad.items()},
                "plane_mirror_centre_mount_mm": self.plane_mirror_centre_mount_mm.tolist()}


def reference_pose_rad(rig: CubeMirrorRig, real: Realization) -> dict:
    """The true turntable pose at which every axis *reads* zero (step A's pose)."""
    return {a.label: -real.encoder_bias_rad.get(a.label, 0.0) for a in rig.turntable.axes}


def reference_axis_rot(rig: CubeMirrorRig, real: Realization) -> np.ndarray:
    """Step A: the autocollimator adjusted to read zero on the inner-frame plane mirror, all axes
    reading zero — its axis is the plane mirror's normal in rot (noise-free; same formula as
    :func:`rigsim.procedures.cube_mirror.campaign.reference_direction`)."""
    if real.plane_mirror_normal_mount is None:
        raise GeometryError("this rig has no plane mirror; pass axis_rot explicitly")
    m = real.turntable.R_rot_from_mount(reference_pose_rad(rig, real)) @ real.plane_mirror_normal_mount
    return m / np.linalg.norm(m)


def _plane_mirror_centre_rot(real: Realization, pose_rad: dict, centre_mount) -> np.ndarray:
    return real.turntable.R_rot_from_mount(pose_rad) @ np.asarray(centre_mount, float)


def autocollimator_layout(rig: CubeMirrorRig, real: Realization, target: str = "face", face: str | None = None, *,
                          axis_rot=None, reference_pose=None, objective_vertex_z_mm: float = 2.5,
                          plane_mirror_centre_mount_mm=(0.0, 0.0, 0.0)) -> AutocollimatorLayout:
    """Place the autocollimator for ``target`` = ``"face"`` (cube face ``face``, default the
    procedure's first face) or ``"plane_mirror"``.

    The axis direction is ``axis_rot`` (unit, towards the autocollimator), by default the step-A
    direction (:func:`reference_axis_rot`). For a face, the reference pose is the exact pose near
    the procedure's nominal pose (middle and outer axes adjusted) at which the face's true normal
    is along the axis — its null; for the plane mirror it is the all-zero reading pose. The
    axis passes through the target's centre at that pose, and the objective's convex vertex
    (``objective_vertex_z_mm`` from the lens centre) is ``rig.autocollimator.distance_mm`` from it.
    ``plane_mirror_centre_mount_mm``: where the plane mirror sits on the inner frame (the rig
    schema does not say; default the axes' intersection).
    """
    if rig.autocollimator is None:
        raise GeometryError("this rig has no autocollimator")
    if target not in ("face", "plane_mirror"):
        raise ValueError(f"target = {target!r}: must be 'face' or 'plane_mirror'")
    d = reference_axis_rot(rig, real) if axis_rot is None else np.asarray(axis_rot, float)
    R = a_frame_basis(d)  # from the axis as given: a_frame_basis normalises it once, as below
    d = d / np.linalg.norm(d)
    pm_c = np.asarray(plane_mirror_centre_mount_mm, float)
    if target == "face":
        face = face or rig.procedure.faces[0]
        if face not in real.face_normals_mount:
            raise ValueError(f"face {face!r} has no true normal in this realisation (faces: {sorted(real.face_normals_mount)})")
        if reference_pose is None:
            idx = rig.procedure.faces.index(face) if face in rig.procedure.faces else 0
            start = pose_deg_to_rad(rig.procedure.nominal_poses_deg[idx])
            free = [a.label for a in rig.turntable.axes if a.label in ("X", "Y")]
            fixed = {a.label: start.get(a.label, 0.0) for a in rig.turntable.axes if a.label not in free}
            reference_pose = real.turntable.solve_alignment(real.face_normals_mount[face], d, free, start, fixed)
        cp = cube_pose(rig, real, reference_pose)
        anchor = cp.apply(0.5 * rig.cube.edge_mm * FACE_NORMALS[face])
    else:
        face = None
        if real.plane_mirror_normal_mount is None:
            raise GeometryError("this rig has no plane mirror")
        if reference_pose is None:
            reference_pose = reference_pose_rad(rig, real)
        anchor = _plane_mirror_centre_rot(real, reference_pose, pm_c)
    origin = anchor + d * (rig.autocollimator.distance_mm + objective_vertex_z_mm)
    return AutocollimatorLayout(target, face, d, R, origin, anchor, dict(reference_pose), pm_c)


def mirror_target(rig: CubeMirrorRig, real: Realization, layout: AutocollimatorLayout, pose_rad: dict,
                  reflectance: float = 1.0) -> MirrorTarget:
    """The target mirror at turntable pose ``pose_rad`` (true kinematics), in the A frame."""
    if layout.target == "face":
        cp = cube_pose(rig, real, pose_rad)
        R_rm = real.turntable.R_rot_from_mount(pose_rad)
        n_rot = R_rm @ real.face_normals_mount[layout.face]
        n_rot /= np.linalg.norm(n_rot)
        nominal = FACE_NORMALS[layout.face]
        centre_rot = cp.apply(0.5 * rig.cube.edge_mm * nominal)
        # in-plane edge directions of the (ideal) cube face, re-orthogonalised to the true normal
        k = int(np.argmax(np.abs(nominal)))
        axes = [cp.R[:, i] for i in range(3) if i != k]
        n = layout.dir_to_A(n_rot)
        e1 = layout.dir_to_A(axes[0])
        e1 = e1 - (e1 @ n) * n
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        return MirrorTarget(layout.to_A(centre_rot), n, "square", 0.5 * rig.cube.edge_mm, e1, e2, reflectance,
                            f"cube face {layout.face}")
    R_rm = real.turntable.R_rot_from_mount(pose_rad)
    n_rot = R_rm @ real.plane_mirror_normal_mount
    n = layout.dir_to_A(n_rot / np.linalg.norm(n_rot))
    e1, e2 = _plane_axes(n)
    centre = layout.to_A(_plane_mirror_centre_rot(real, pose_rad, layout.plane_mirror_centre_mount_mm))
    return MirrorTarget(centre, n, "disk", 0.5 * rig.plane_mirror.diameter_mm, e1, e2, reflectance, "plane mirror")


def _quad(centre, e1, e2, n, h):
    V = np.array([centre - h * e1 - h * e2, centre + h * e1 - h * e2, centre + h * e1 + h * e2,
                  centre - h * e1 + h * e2])
    F = np.array([[0, 1, 2], [0, 2, 3]])
    if np.cross(V[1] - V[0], V[2] - V[0]) @ n < 0:
        F = F[:, ::-1]
    return V, F


def mirror_mesh_A(rig: CubeMirrorRig, real: Realization, layout: AutocollimatorLayout, pose_rad: dict,
                  n_seg: int = 512) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (A frame, float64) and faces of the target at ``pose_rad``.

    Cube: six square faces (split vertices), each with its true normal (the measured faces from
    the realisation, the others ideal), so the mesh's face normals are the truth's. Plane
    mirror: a 512-gon fan in the mirror plane (its outline is within 5e-4 mm of the disk).
    """
    if layout.target == "face":
        cp = cube_pose(rig, real, pose_rad)
        R_rm = real.turntable.R_rot_from_mount(pose_rad)
        h = 0.5 * rig.cube.edge_mm
        Vs, Fs = [], []
        for f, nom in FACE_NORMALS.items():
            n_mount = real.face_normals_mount.get(f)
            if n_mount is None:
                n_mount = real.R_cube_from_mount.T @ face_normal_cube(f, None)
            n = layout.dir_to_A(R_rm @ n_mount)
            n /= np.linalg.norm(n)
            centre = layout.to_A(cp.apply(h * nom))
            k = int(np.argmax(np.abs(nom)))
            e1 = layout.dir_to_A(cp.R[:, (k + 1) % 3])
            e1 = e1 - (e1 @ n) * n
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(n, e1)
            V, F = _quad(centre, e1, e2, n, h)
            Fs.append(F + 4 * len(Vs))
            Vs.append(V)
        return np.vstack(Vs), np.vstack(Fs)
    m = mirror_target(rig, real, layout, pose_rad)
    ph = np.arange(n_seg) * (2 * math.pi / n_seg)
    rim = m.centre + m.half_size_mm * (np.cos(ph)[:, None] * m.e1 + np.sin(ph)[:, None] * m.e2)
    V = np.vstack([m.centre[None, :], rim])
    F = np.array([(0, 1 + j, 1 + (j + 1) % n_seg) for j in range(n_seg)])
    if np.cross(V[F[0, 1]] - V[0], V[F[0, 2]] - V[0]) @ m.normal < 0:
        F = F[:, ::-1]
    return V, F
