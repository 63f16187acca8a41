"""Seed 000's aiming camera: the one camera model (:class:`~rigsim.optics.camera.PinholeBrown`, here
without distortion) placed in the scene, looking at the diaphragm screen's hole from
``view_angle_deg`` off the screen normal, and the homography from the screen plane to its pixels.

The screen is the plane ⟂ Z′ through the hole; screen coordinates (s, t) are lab X′, Y′ in mm from
the hole. The camera sits ``working_distance_mm`` from the hole, on the cube side of the screen,
displaced towards azimuth ``view_azimuth_deg`` (0: +X′), aimed at the hole (which images on the
principal point); image "down" is −Y′ as far as the view allows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rigsim.optics.camera import PinholeBrown

__all__ = ["PosedCamera", "aiming_camera", "screen_homography", "nominal_screen_homography"]

_EZ = np.array([0.0, 0.0, 1.0])


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


@dataclass(frozen=True)
class PosedCamera:
    """A camera in a scene: its intrinsics (OpenCV camera frame: x right, y down, z forward) and its
    pose; ``R_world_from_cam`` has the camera axes as columns, ``centre`` is in scene millimetres."""

    intrinsics: PinholeBrown
    R_world_from_cam: np.ndarray
    centre: np.ndarray

    @property
    def width(self) -> int:
        return self.intrinsics.width

    @property
    def height(self) -> int:
        return self.intrinsics.height

    @property
    def f_px(self) -> float:
        return self.intrinsics.fx

    @property
    def cx(self) -> float:
        return self.intrinsics.cx

    @property
    def cy(self) -> float:
        return self.intrinsics.cy

    @property
    def K(self) -> np.ndarray:
        return self.intrinsics.camera_matrix()

    def project(self, p_scene) -> tuple[np.ndarray, np.ndarray]:
        """Scene points (..., 3) → pixels (..., 2) and the in-front mask."""
        return self.intrinsics.project_valid((np.asarray(p_scene, float) - self.centre) @ self.R_world_from_cam)

    def on_detector(self, uv, margin: float = 0.0) -> np.ndarray:
        return self.intrinsics.on_detector(uv, margin_px=margin)

    def as_dict(self) -> dict:
        return {"R_world_from_cam": self.R_world_from_cam, "centre_scene_mm": self.centre, "f_px": self.f_px,
                "cx": self.cx, "cy": self.cy, "width": self.width, "height": self.height,
                "camera_frame": "OpenCV (x right, y down, z forward)"}


def aiming_camera(spec, hole_scene, *, view_azimuth_deg: float = 0.0, principal_point_px=None) -> PosedCamera:
    """The aiming camera of a rig's ``[aiming_camera]`` table ``spec`` looking at the hole at
    ``hole_scene`` (module docstring). ``principal_point_px`` defaults to the detector centre."""
    W, H = (int(x) for x in spec.resolution_px)
    f_px = spec.focal_length_mm / (spec.pixel_pitch_um * 1e-3)
    cx, cy = ((W - 1) / 2.0, (H - 1) / 2.0) if principal_point_px is None else \
        (float(principal_point_px[0]), float(principal_point_px[1]))
    a = math.radians(spec.view_angle_deg)
    psi = math.radians(view_azimuth_deg)
    side = np.array([math.cos(psi), math.sin(psi), 0.0])
    hole = np.asarray(hole_scene, float)
    C = hole + spec.working_distance_mm * (math.sin(a) * side - math.cos(a) * _EZ)
    fwd = _unit(hole - C)
    up = np.array([0.0, 1.0, 0.0])
    if abs(up @ fwd) > 0.99:
        up = np.array([1.0, 0.0, 0.0])
    y_c = -_unit(up - (up @ fwd) * fwd)  # image down = −(lab up)
    x_c = np.cross(y_c, fwd)
    R = np.column_stack([x_c, y_c, fwd])
    return PosedCamera(PinholeBrown(float(f_px), float(f_px), cx, cy, width=W, height=H), R, C)


def screen_homography(camera: PosedCamera, hole_scene) -> np.ndarray:
    """3×3 homography from screen coordinates (s, t) mm about the hole to the camera's pixels."""
    Rc = camera.R_world_from_cam.T
    Hmat = camera.K @ np.column_stack([Rc @ np.array([1.0, 0.0, 0.0]), Rc @ np.array([0.0, 1.0, 0.0]),
                                       Rc @ (np.asarray(hole_scene, float) - camera.centre)])
    return Hmat / Hmat[2, 2]


def nominal_screen_homography(spec, *, view_azimuth_deg: float = 0.0, principal_point_px=None) -> np.ndarray:
    """The screen → pixel homography from the rig's nominal aiming-camera spec alone (it depends on
    the camera's distance, angles and intrinsics, not on where the hole is)."""
    hole = np.zeros(3)
    cam = aiming_camera(spec, hole, view_azimuth_deg=view_azimuth_deg, principal_point_px=principal_point_px)
    return screen_homography(cam, hole)
