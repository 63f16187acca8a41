"""A user's planar calibration target seen by a rig's true camera (``rigsim render target``).

The target (:mod:`rigsim.optics.targets`) is a self-luminous rectangle (a back-lit print or a screen)
whose radiance is its bitmap: white at ``white_fraction`` of the detector's usable full well on axis,
black at ``black_reflectance`` of white. Chessboards use a nearest-texel lookup with one texel per
square, so their edges (and corners) are exact; circles and images are bilinear. The camera is the
``rigsim_pinhole`` sensor with the true intrinsics and distortion (``response="flux"``: cos⁴ fall-off),
the whole detector is rendered, and :func:`~rigsim.render.frame.digitise` applies the detector. Per
pose only the rectangle's ``to_world`` changes (no recompile). The sidecar's truth holds every target
point's exact projection (:func:`rigsim.optics.targets.project_target`).
"""

from __future__ import annotations

import math
import time

import numpy as np

from rigsim.detector.config import DetectorConfig
from rigsim.errors import CliError
from rigsim.optics.aiming import aiming_camera
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.targets import PlanarTarget, project_target, target_to_camera
from rigsim.render.budget import check_memory
from rigsim.render.frame import Frame, digitise
from rigsim.render.scene import Element, PinholeSensor, Scene, mitsuba_seed

__all__ = ["TARGET_CAMERAS", "TargetScene", "true_camera"]

TARGET_CAMERAS = ("sun-sensor", "aiming-camera", "star-sensor")
"""Cameras a target can be rendered through (the autocollimator is focused at infinity: not a pinhole)."""


def true_camera(rig, camera: str | None = None) -> tuple[str, PinholeBrown, DetectorConfig]:
    """(name, true pinhole + Brown model, detector) of ``rig``'s ``camera`` (default its main one)."""
    if hasattr(rig, "sensor") and hasattr(rig.sensor, "camera"):  # star rigs
        have = {"star-sensor": (rig.sensor.camera(), rig.sensor.detector)}
    elif hasattr(rig, "sun_sensor"):  # cube-mirror rigs
        have = {"sun-sensor": (rig.sun_sensor.camera(), rig.sun_sensor.detector)}
        if getattr(rig, "aiming_camera", None) is not None:
            ac = rig.aiming_camera
            have["aiming-camera"] = (aiming_camera(ac, np.zeros(3)).intrinsics, ac.detector)
    else:
        raise CliError(f"rig {getattr(rig, 'name', '?')}: no area camera with a pinhole model (its line cameras "
                       f"cannot image a target); use a cube-mirror or star rig")
    name = camera or next(iter(have))
    if name not in have:
        why = " (focused at infinity, not a pinhole camera)" if name == "autocollimator" else ""
        raise CliError(f"--camera = {name!r}{why}: this rig ({rig.name}) has {', '.join(have)}")
    cam, det = have[name]
    return name, cam, det


def _check_spp(spp) -> int:
    if int(spp) != spp or spp < 1 or spp > 65536 or (int(spp) & (int(spp) - 1)) or (int(spp).bit_length() - 1) % 2:
        raise CliError(f"--spp = {spp!r}: expected a power of 4 from 1 to 65536 (the ldsampler's)")
    return int(spp)


class TargetScene:
    """Frames of ``target`` through ``camera`` (true model) and ``detector`` at target poses.

    Build once (loads the scene), then :meth:`render` per pose (OpenCV rvec in degrees, tvec in mm).
    """

    def __init__(self, camera: PinholeBrown, target: PlanarTarget, detector: DetectorConfig, *, spp: int = 64,
                 white_fraction: float = 0.6, black_reflectance: float = 0.05, sampler: str = "ldsampler"):
        if not (0.0 < white_fraction <= 1.0):
            raise CliError(f"--white-fraction = {white_fraction}: allowed > 0 to 1")
        if not (0.0 <= black_reflectance < 1.0):
            raise CliError(f"black_reflectance = {black_reflectance}: allowed 0 to < 1")
        self.camera, self.target, self.detector = camera, target, detector
        check_memory((camera.width, camera.height), "the camera's resolution_px")
        self.spp, self.sampler = _check_spp(spp), sampler
        usable_e = min(detector.full_well_e, (detector.max_dn - detector.offset_dn) / detector.gain_dn_per_e)
        self.white_photons = float(white_fraction * usable_e / detector.quantum_efficiency)
        self.black_reflectance = float(black_reflectance)
        self.white_fraction = float(white_fraction)
        self.scene = self._build()

    def _local_to_target(self) -> np.ndarray:
        x0, y0, x1, y1 = self.target.extent_mm
        M = np.eye(4)  # rectangle [-1, 1]² → the printed extent; its normal (+z local) → −z_target (right-handed)
        M[:3, :3] = np.diag([(x1 - x0) / 2, -(y1 - y0) / 2, -1.0])
        M[:3, 3] = [(x0 + x1) / 2, (y0 + y1) / 2, 0.0]
        return M

    def _to_world(self, rvec_deg, tvec_mm) -> np.ndarray:
        R, t = target_to_camera(rvec_deg, tvec_mm)
        P = np.eye(4)
        P[:3, :3], P[:3, 3] = R, t
        return P @ self._local_to_target()

    def _build(self) -> Scene:
        from rigsim.render.backend import ensure_variant

        ensure_variant()
        import mitsuba as mi

        refl = self.target.bitmap()
        rad = self.white_photons * (self.black_reflectance + (1.0 - self.black_reflectance) * refl)
        # Mitsuba's texel row 0 sits at the rectangle's local y = −1, i.e. the target's bottom edge
        bm = mi.Bitmap(np.ascontiguousarray(np.flipud(rad)[..., None], dtype=np.float32))
        tex = {"type": "bitmap", "bitmap": bm, "raw": True, "filter_type": self.target.filter, "wrap_mode": "clamp"}

        def place(state) -> dict:
            return {"target.to_world": mi.Transform4f(self._to_world(*state["pose"]))} if "pose" in state else {}

        board = Element("target", {"type": "rectangle", "to_world": mi.ScalarTransform4f(self._to_world((0, 0, 0), (0, 0, 1000.0))),
                                   "emitter": {"type": "area", "radiance": tex}}, place)
        c = self.camera
        sensor = PinholeSensor(c, width=c.width, height=c.height, spp=self.spp, sampler=self.sampler)
        return Scene({"type": "path", "max_depth": 1}, [sensor, board])

    def settings(self) -> dict:
        return {"primitive": "planar_target", "variant": self.scene.variant, "integrator": "path(max_depth=1)",
                "sampler": self.sampler, "spp": self.spp, "response": "flux", "target": self.target.spec,
                "texture_filter": self.target.filter, "white_photons": self.white_photons,
                "white_fraction": self.white_fraction, "black_reflectance": self.black_reflectance,
                "camera": self.camera.as_dict()}

    def points(self, rvec_deg, tvec_mm) -> dict[str, np.ndarray]:
        """Exact pixels of every target point at the pose: x_mm, y_mm, u_px, v_px, visible."""
        uv, vis = project_target(self.camera, self.target.points_mm, rvec_deg, tvec_mm)
        R, t = target_to_camera(rvec_deg, tvec_mm)
        p = self.target.points_mm @ R[:, :2].T + t
        inside = (p[:, 2] > 0) & ((p[:, 0] / p[:, 2]) ** 2 + (p[:, 1] / p[:, 2]) ** 2 < self.camera.r2_max)
        uv = np.where(inside[:, None], uv, np.nan)
        return {"x_mm": self.target.points_mm[:, 0], "y_mm": self.target.points_mm[:, 1], "u_px": uv[:, 0],
                "v_px": uv[:, 1], "visible": vis}

    def render(self, rvec_deg, tvec_mm, *, seed: int = 0, noiseless: bool = False, frame: str | None = None) -> Frame:
        """One frame of the target at a pose; ``frame.truth["points"]`` holds the exact point pixels."""
        t0 = time.perf_counter()
        rv, tv = np.asarray(rvec_deg, float).reshape(3), np.asarray(tvec_mm, float).reshape(3)
        photons = self.scene.render({"pose": (rv, tv), "window_origin": (0, 0)}, seed=mitsuba_seed(seed), spp=self.spp)
        pts = self.points(rv, tv)
        R, _ = target_to_camera(rv, tv)
        truth = {"target": self.target.spec, "kind": self.target.kind,
                 "pattern_size": list(self.target.pattern_size) if self.target.pattern_size else None,
                 "points": {k: v.tolist() for k, v in pts.items()},
                 "corners_mm": self.target.corners_mm().tolist(), "camera_true": self.camera.as_dict(),
                 "rvec_deg": rv.tolist(), "tvec_mm": tv.tolist(), "R_cam_from_target": R.tolist(),
                 "convention": "p_cam = R(rvec) p_target + tvec (cv2.projectPoints); pixel (0,0) centre at (0,0)"}
        n_off = int((~pts["visible"]).sum())
        return digitise(photons, self.detector, seed=int(seed), noiseless=noiseless, truth=truth,
                        render={**self.settings(), "noiseless": noiseless},
                        geometry_flags={"points_not_visible": n_off},
                        pose={"frame": frame, "rvec_deg": rv.tolist(), "tvec_mm": tv.tolist(),
                              "rotation_angle_deg": float(math.degrees(np.linalg.norm(np.radians(rv))))},
                        seconds=time.perf_counter() - t0)
