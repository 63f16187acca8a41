"""Where things are: the rig in the rot (lab) frame, in millimetres, and exact ray traces.

This is the analytic model that both the renderers (rigsim.render) and the truth
written into frame sidecars use, so a rendered frame and its truth come from one geometry.

Lab frame = rot frame: origin at the intersection of the turntable axes, +Z' towards the sun
simulator / autocollimator. The mount (inner frame) is at ``R_rot_from_mount(θ)`` with no
translation (axis offsets are not modelled). The cube's centre sits at
``cube.centre_in_mount_mm`` in the mount frame.

Diaphragm layout (seed 000): the screen is a plane perpendicular to +Z' at
``z_screen = z(face centre at the face's exact null pose) + distance_to_cube_mm``; the hole is
at the point of the screen whose pencil along the beam hits that face centre. The sun
simulator's exit aperture is ``distance_from_simulator_mm`` further along +Z'.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rigsim.errors import GeometryError
from rigsim.optics.cube import FACE_NORMALS, reflect
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import pose_deg_to_rad
from rigsim.truth.cube_mirror.realization import Realization


@dataclass(frozen=True)
class RigidPose:
    """``p_rot = R @ p_local + t`` (mm)."""

    R: np.ndarray
    t: np.ndarray

    def apply(self, p) -> np.ndarray:
        return np.asarray(p, float) @ self.R.T + self.t

    def matrix4(self) -> np.ndarray:
        M = np.eye(4)
        M[:3, :3] = self.R
        M[:3, 3] = self.t
        return M


def mount_pose(real: Realization, pose_rad: dict) -> RigidPose:
    return RigidPose(real.turntable.R_rot_from_mount(pose_rad), np.zeros(3))


def cube_pose(rig: CubeMirrorRig, real: Realization, pose_rad: dict) -> RigidPose:
    """Ideal cube frame → rot (the cube's true orientation and position at this pose)."""
    R_rm = real.turntable.R_rot_from_mount(pose_rad)
    return RigidPose(R_rm @ real.R_cube_from_mount.T, R_rm @ np.asarray(rig.cube.centre_in_mount_mm, float))


def face_in_rot(rig: CubeMirrorRig, real: Realization, face: str, pose_rad: dict) -> tuple[np.ndarray, np.ndarray]:
    """(centre_mm, outward unit normal) of a cube face in the rot frame, true tilts included."""
    cp = cube_pose(rig, real, pose_rad)
    centre = cp.apply(0.5 * rig.cube.edge_mm * FACE_NORMALS[face])
    R_rm = real.turntable.R_rot_from_mount(pose_rad)
    n = R_rm @ real.face_normals_mount[face]
    return centre, n / np.linalg.norm(n)


def plane_hit(origin, direction, p0, n) -> tuple[np.ndarray, float]:
    """Intersection of the ray ``origin + s·direction`` with the plane (p0, n); returns (point, s)."""
    origin = np.asarray(origin, float)
    direction = np.asarray(direction, float)
    den = float(direction @ n)
    if abs(den) < 1e-15:
        raise GeometryError("the ray is parallel to the plane")
    s = float((np.asarray(p0, float) - origin) @ n) / den
    return origin + s * direction, s


def in_square_face(point, centre, n, edge_mm: float, R_rot_from_cube: np.ndarray) -> bool:
    """Is ``point`` (on the face plane) inside the square face of side ``edge_mm``?"""
    local = R_rot_from_cube.T @ (np.asarray(point, float) - np.asarray(centre, float))
    # drop the component along the face normal; the two others must be within ±edge/2
    axis = int(np.argmax(np.abs(R_rot_from_cube.T @ n)))
    others = [i for i in range(3) if i != axis]
    return bool(np.all(np.abs(local[others]) <= 0.5 * edge_mm))


@dataclass(frozen=True)
class DiaphragmLayout:
    face: str
    null_pose_rad: dict
    hole_centre_mm: np.ndarray  # rot frame
    screen_normal: np.ndarray  # +Z' (towards the simulator)
    z_screen_mm: float
    simulator_exit_mm: np.ndarray


def diaphragm_layout(rig: CubeMirrorRig, real: Realization, face_index: int = 0) -> DiaphragmLayout:
    """Place the screen and hole for face ``face_index`` (at its exact, error-free null pose)."""
    if rig.diaphragm_screen is None:
        raise GeometryError("this rig has no diaphragm screen")
    face = rig.procedure.faces[face_index]
    start = pose_deg_to_rad(rig.procedure.nominal_poses_deg[face_index])
    free = [a.label for a in rig.turntable.axes if a.label in ("X", "Y")]
    null = real.turntable.solve_alignment(real.face_normals_mount[face], real.d_sun_rot, free, start)
    centre, _ = face_in_rot(rig, real, face, null)
    d = real.d_sun_rot
    z_screen = float(centre[2] + rig.diaphragm_screen.distance_to_cube_mm)
    hole, _ = plane_hit(centre, d, np.array([0.0, 0.0, z_screen]), np.array([0.0, 0.0, 1.0]))
    exit_ = hole + d * rig.diaphragm_screen.distance_from_simulator_mm / d[2]
    return DiaphragmLayout(face, null, hole, np.array([0.0, 0.0, 1.0]), z_screen, exit_)


@dataclass(frozen=True)
class ReturnSpot:
    """Exact trace of the pencil through the hole: hole → face → screen."""

    hit_on_face_mm: np.ndarray
    on_face: bool
    reflected_dir: np.ndarray
    spot_mm: np.ndarray  # on the screen plane, rot frame
    offset_mm: np.ndarray  # spot − hole, (x, y) in the screen plane
    tilt_rad: float  # angle between the face normal and the beam


def trace_return_spot(rig: CubeMirrorRig, real: Realization, layout: DiaphragmLayout, pose_rad: dict) -> ReturnSpot:
    """Exact ray trace of the beam's central ray at turntable pose ``pose_rad`` (true kinematics)."""
    d = real.d_sun_rot
    prop = -d  # light propagates away from the simulator
    centre, n = face_in_rot(rig, real, layout.face, pose_rad)
    hit, s = plane_hit(layout.hole_centre_mm, prop, centre, n)
    if s <= 0:
        raise GeometryError(f"face {layout.face} is behind the screen at this pose")
    cp = cube_pose(rig, real, pose_rad)
    on_face = in_square_face(hit, centre, n, rig.cube.edge_mm, cp.R) and float(prop @ n) < 0
    r = reflect(prop, n)
    spot, s2 = plane_hit(hit, r, np.array([0.0, 0.0, layout.z_screen_mm]), layout.screen_normal)
    if s2 <= 0:
        raise GeometryError("the reflected beam does not come back to the screen")
    tilt = float(np.arctan2(np.linalg.norm(np.cross(n, d)), n @ d))
    return ReturnSpot(hit, on_face, r, spot, (spot - layout.hole_centre_mm)[:2], tilt)
