"""The sun simulator seen by the rig's sun sensor at a turntable pose (seeds 000 step 1, 001 step B).

Everything comes from the same Rig and Realization as the analytic campaign: the sun direction
in the sensor frame is ``R_sun_from_mount · R_rot_from_mount(θ)ᵀ · d_sun`` with the *true*
turntable kinematics, the camera is the rig's true intrinsics and Brown distortion, and the
simulator is a uniform disk of ``collimation_full_angle_arcmin``. Rendering is done by
:class:`rigsim.render.sunspot.SunSpotRenderer` (fixed crop window, mi.traverse updates), the
detector by :func:`rigsim.detector.apply_detector`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from rigsim.detector import apply_detector
from rigsim.optics.camera import PinholeBrown
from rigsim.render.camera import PinholeCamera
from rigsim.render.frameio import build_sidecar, write_frame
from rigsim.render.sunspot import SunSpotRenderer, SpotWindow
from rigsim.rig.schema import Rig
from rigsim.truth import Realization, realization_from_rig


@dataclass
class SunSensorFrame:
    dn: np.ndarray  # (H, W) uint16 — or only the crop window when rendered with full_frame=False
    photons_window: SpotWindow
    sidecar: dict
    seconds: float
    dn_origin_uv: tuple[int, int] = (0, 0)  # detector pixel of dn[0, 0]

    def write(self, path) -> tuple:
        return write_frame(path, self.dn, self.sidecar)


def default_spot_photons(rig: Rig) -> float:
    """Photons per spot that put the on-axis peak pixel near half the full well."""
    ss = rig.sun_sensor
    det = ss.detector
    d_px = 2 * math.tan(math.radians(rig.sun_simulator.collimation_full_angle_arcmin / 60) / 2) * ss.fx_px
    area_px = max(1.0, math.pi * d_px**2 / 4)
    return 0.5 * det.full_well_e / det.quantum_efficiency * area_px


class SunSensorScene:
    """Render sun-sensor frames of a rig at turntable poses.

    ``real``: the rig instance (default: the rig file's true errors). Poses are ``{label: rad}``
    (true turntable angles; the sidecar records them as the truth).
    """

    def __init__(self, rig: Rig, real: Realization | None = None, *, window_px: int = 32, spp: int = 1024,
                 spot_photons: float | None = None):
        self.rig = rig
        self.real = real if real is not None else realization_from_rig(rig)
        self.analytic_camera = PinholeBrown.from_sun_sensor(rig.sun_sensor)
        self.camera = PinholeCamera.from_intrinsics(self.analytic_camera)
        self.full_angle_rad = math.radians(rig.sun_simulator.collimation_full_angle_arcmin / 60.0)
        self.spot_photons = float(spot_photons) if spot_photons is not None else default_spot_photons(rig)
        self.renderer = SunSpotRenderer(self.camera, full_angle_rad=self.full_angle_rad, window_px=window_px,
                                        spp=spp, spot_photons=self.spot_photons)

    def sun_dir_cam(self, pose_rad: dict) -> np.ndarray:
        R = self.real.turntable.R_rot_from_mount(pose_rad)
        s = self.real.R_sun_from_mount @ (R.T @ self.real.d_sun_rot)
        return s / np.linalg.norm(s)

    def render(self, pose_rad: dict, seed: int = 0, *, noiseless: bool = False, truth_points: int = 400_000,
               full_frame: bool = True) -> SunSensorFrame:
        """Render one frame. ``full_frame=False`` digitises only the crop window (same pixels, same
        fixed pattern, same noise statistics as the full frame; 10× faster for sweeps)."""
        t0 = time.perf_counter()
        s = self.sun_dir_cam(pose_rad)
        ss = self.rig.sun_sensor
        if full_frame:
            photons, win = self.renderer.render_frame(s, seed=seed)
            det = apply_detector(photons, ss.detector, seed=seed, noiseless=noiseless)
            origin = (0, 0)
        else:
            win = self.renderer.render(s, seed=seed)
            origin = tuple(win.origin_uv)
            det = apply_detector(win.image, ss.detector, seed=seed, noiseless=noiseless, origin_uv=origin,
                                 detector_shape=(ss.resolution_px[1], ss.resolution_px[0]))
        truth = self.renderer.truth(s, n=truth_points) if not (win.flags.get("spot_off_detector") or win.flags.get("spot_outside_model")) else {"valid": False}
        flags = dict(win.flags)
        sidecar = build_sidecar(
            truth={
                "rig": self.rig.name,
                "sun_dir_cam": s.tolist(),
                "spot": truth,
                "camera_true": self.camera.as_dict(),
                "R_sun_from_mount": self.real.R_sun_from_mount.tolist(),
            },
            render={**win.settings, "noiseless": noiseless, "window_origin_uv": list(win.origin_uv)},
            detector_frame=det,
            geometry_flags=flags,
            pose={k: math.degrees(v) for k, v in pose_rad.items()},
            seed=seed,
        )
        return SunSensorFrame(det.dn, win, sidecar, time.perf_counter() - t0, origin)


def sun_sensor_export_dict(scene: SunSensorScene, pose_rad: dict, spp: int = 64) -> tuple[dict, list[str]]:
    """Built-in-plugins-only scene dict of the sun-sensor view (for XML export).

    The plain ``mitsuba`` command cannot load the distorted ``rigsim_pinhole`` sensor, so the
    export uses the built-in ``perspective`` sensor with the same fx and principal point and no
    distortion (and square pixels): its spot sits at the *undistorted* projection.
    """
    from rigsim.render.scenes.export import cv_to_mitsuba_camera, perspective_from_intrinsics

    cam = scene.camera
    s = scene.sun_dir_cam(pose_rad)
    sensor = perspective_from_intrinsics(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height)
    sensor.update({
        "to_world": cv_to_mitsuba_camera(np.eye(3), np.zeros(3)),
        "film": {"type": "hdrfilm", "width": cam.width, "height": cam.height, "pixel_format": "luminance",
                 "rfilter": {"type": "box"}},
        "sampler": {"type": "independent", "sample_count": int(spp)},
    })
    r = scene.renderer
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 1},
        "sensor": sensor,
        "sun": {"type": "disk", "to_world": r._disk_matrix(s),
                "emitter": {"type": "area", "radiance": {"type": "uniform", "value": r._radiance()}}},
    }
    x = (s[0] / s[2], s[1] / s[2])
    notes = [
        f"rigsim export: sun-sensor view of rig '{scene.rig.name}' at pose (deg) "
        + ", ".join(f"{k}={math.degrees(v):.4f}" for k, v in pose_rad.items()),
        "units: millimetres; camera frame = world frame (OpenCV axes: x right, y down, z forward)",
        "the built-in perspective sensor replaces rigsim's distorted pinhole: NO Brown distortion here",
        f"expected spot centre (undistorted projection, OpenCV pixel convention): "
        f"u={cam.fx * x[0] + cam.cx:.4f}, v={cam.fy * x[1] + cam.cy:.4f}",
    ]
    return d, notes
