"""The sun simulator seen by the sun sensor (seeds 000 step 1, 001 step B).

:class:`SunSpotRenderer` is the primitive: a uniform Lambertian disk filling the simulator's full
angle, seen by the distorted ``rigsim_pinhole`` sensor in a fixed crop window moved per frame by
``window_origin`` (no recompile). :class:`SunSensorScene` places it for a turntable pose with the
*true* kinematics and intrinsics of the rig and its realization, and applies the detector. The
truth (:func:`rigsim.optics.sun_disk.spot_truth`) is numpy only. Details and measured fidelity:
docs/rendering.md ("Sun spot", "Sun-sensor frames").
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from rigsim.errors import GeometryWarning
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.cover_glass import CoverGlass
from rigsim.optics.pinhole import ThickPinhole
from rigsim.optics.pinhole_diffraction import PinholePSF, kernel_moments
from rigsim.optics.sun_disk import (
    SUN_FULL_ANGLE_RAD,
    _basis,
    _unit,
    spot_geometry_flags,
    spot_truth,
    sun_window_px,
    window_centroid,
)
from rigsim.optics.sun_radiance import DiskRadiance, gradient_across
from rigsim.render.backend import ensure_variant
from rigsim.render.budget import check_memory
from rigsim.render.frame import Frame, digitise
from rigsim.render.plugins import register_sensors
from rigsim.render.scene import Element, PinholeSensor, Scene
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.truth.cube_mirror.realization import Realization, realization_from_rig

__all__ = ["SUN_FULL_ANGLE_RAD", "GeometryWarning", "SpotWindow", "SunSpotRenderer", "spot_truth",
           "spot_geometry_flags", "window_centroid"]


def _check_spp(spp, sampler: str) -> None:
    if int(spp) != spp or spp < 1:
        raise ValueError(f"spp = {spp!r}: must be an integer >= 1")
    spp = int(spp)
    if sampler == "ldsampler" and (spp & (spp - 1) or (spp.bit_length() - 1) % 2):
        raise ValueError(f"spp = {spp!r}: the ldsampler needs a power of 4 (e.g. 256, 1024, "
                         "4096); Mitsuba would silently round it")


@dataclass
class SpotWindow:
    """One rendered crop window. ``image[j, i]`` is detector pixel (origin_uv[0] + i, origin_uv[1] + j)."""

    image: np.ndarray
    origin_uv: tuple[int, int]
    sun_dir_cam: np.ndarray
    center_uv: np.ndarray | None
    flags: dict
    spp: int
    seed: int
    variant: str
    seconds: float
    settings: dict = field(default_factory=dict)

    def paste_into(self, frame: np.ndarray) -> np.ndarray:
        """Add the window into a full detector frame (in place; parts off the detector dropped)."""
        H, W = frame.shape
        u0, v0 = self.origin_uv
        h, w = self.image.shape
        a0, b0 = max(0, u0), max(0, v0)
        a1, b1 = min(W, u0 + w), min(H, v0 + h)
        if a1 > a0 and b1 > b0:
            frame[b0:b1, a0:a1] += self.image[b0 - v0:b1 - v0, a0 - u0:a1 - u0]
        return frame

    def centroid(self) -> np.ndarray:
        return window_centroid(self.image, self.origin_uv)


class SunSpotRenderer:
    """Render a finite sun disk through the distorted pinhole camera, window by window.

    Build once (compiles on the first frame), then call :meth:`render` per sun direction; poses
    change through ``mi.traverse`` only. ``sun_dir_cam`` is the unit vector from the camera
    towards the sun in the camera frame (OpenCV axes: x right, y down, z along the optical axis).
    """

    def __init__(self, camera: PinholeBrown, *, full_angle_rad: float = SUN_FULL_ANGLE_RAD,
                 window_px: int = 32, spp: int = 1024, spot_photons: float = 1.0e6,
                 sampler: str = "ldsampler", response: str = "flux", distance_mm: float = 1000.0,
                 radiance: DiskRadiance | None = None, ghost: CoverGlass | None = None,
                 pinhole: ThickPinhole | None = None, diffraction: PinholePSF | None = None,
                 supersampling: int = 4):
        if not (0.0 < full_angle_rad < math.radians(20.0)):
            raise ValueError(f"full_angle_rad = {full_angle_rad!r}: must be in (0, 0.349) rad")
        if int(window_px) != window_px or not (4 <= window_px <= 4096):
            raise ValueError(f"window_px = {window_px!r}: must be an integer in [4, 4096]")
        _check_spp(spp, sampler)
        if not (spot_photons > 0 and math.isfinite(spot_photons)):
            raise ValueError(f"spot_photons = {spot_photons!r}: must be a finite number > 0")
        if response not in ("flux", "radiance"):
            raise ValueError(f"response = {response!r}: must be 'flux' or 'radiance'")
        self.camera = camera
        self.full_angle_rad = float(full_angle_rad)
        self.window_px = int(window_px)
        self.spp = int(spp)
        self.spot_photons = float(spot_photons)
        self.sampler = sampler
        self.response = response
        self.distance_mm = float(distance_mm)
        # effects (docs/effects-sun.md): a non-uniform disk (texture on the emitter), the cover glass's ghost
        self.radiance = radiance if radiance is not None and not radiance.uniform else None
        self.ghost = ghost
        self.pinhole = pinhole  # a thick pinhole's vignetting
        self.diffraction = diffraction  # the pinhole's diffraction (PSF convolved in sun_batch)
        if diffraction is not None and (int(supersampling) not in (1, 2, 4) or self.spp < int(supersampling) ** 2):
            raise ValueError(f"supersampling = {supersampling!r}: must be 1, 2 or 4, with spp >= its square")
        self.supersampling = int(supersampling)
        self._ghost_batch = None
        self.variant = ensure_variant()
        register_sensors()
        on_axis = 2.0 * math.tan(full_angle_rad / 2.0) * max(camera.fx, camera.fy)
        if on_axis + 2.0 > window_px:
            raise ValueError(f"window_px = {window_px} is too small for a spot of {on_axis:.1f} px "
                             "diameter on axis (need diameter + 2 px margin)")
        self._scene = self._build(window_px, window_px, self.spp)
        self._full = None  # (Scene, spp) for render_full, built on demand
        self._tiles: dict[int, Scene] = {}  # tile_px -> Scene for render(tight=True), built on demand

    # -- scene --------------------------------------------------------------------------------
    def _radiance(self) -> float:
        omega = 2.0 * math.pi * (1.0 - math.cos(self.full_angle_rad / 2.0))
        return self.spot_photons / (self.camera.fx * self.camera.fy * omega)

    @property
    def tiled_only(self) -> bool:
        """Whether only the tiled sensor draws this renderer's effects (the cover glass's ghost, the
        thick pinhole's vignetting, the pinhole's diffraction): the per-frame windows are then drawn
        by a one-tile batch."""
        return self.ghost is not None or self.pinhole is not None or self.diffraction is not None

    @property
    def needs_axis(self) -> bool:
        """Whether a frame needs the direction of the disk's gradient (``axis``)."""
        return self.radiance is not None and self.radiance.g != 0.0

    def emitter(self) -> dict:
        """The disk's area emitter: uniform, or a nearest-filtered (r, φ) texture of the exact cell
        means of :class:`~rigsim.optics.sun_radiance.DiskRadiance` (Mitsuba's disk: uv = (r, φ/2π))."""
        if self.radiance is None:
            return {"type": "area", "radiance": {"type": "uniform", "value": self._radiance()}}
        import mitsuba as mi

        tex = self.radiance.texture() * self._radiance()
        return {"type": "area", "radiance": {
            "type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(tex[:, :, None], dtype=np.float32)),
            "raw": True, "filter_type": "nearest", "wrap_mode": "clamp"}}

    def _build(self, w: int, h: int, spp: int) -> Scene:
        """Elements: the camera's window (moved by ``window_origin``) and the sun disk (placed by
        ``sun_dir``, the unit vector to the sun in the camera frame)."""
        import mitsuba as mi

        def place_disk(state) -> dict:
            if "sun_dir" not in state:
                return {}
            return {"sun.to_world": mi.Transform4f(self._disk_matrix(state["sun_dir"], state.get("axis")))}

        sun = Element("sun", {"type": "disk",
                              "to_world": mi.ScalarTransform4f(self._disk_matrix(np.array([0.0, 0.0, 1.0]))),
                              "emitter": self.emitter()},
                      place_disk)
        sensor = PinholeSensor(self.camera, width=w, height=h, spp=spp, sampler=self.sampler, response=self.response)
        return Scene({"type": "path", "max_depth": 1}, [sensor, sun])

    def _disk_matrix(self, s: np.ndarray, axis=None) -> np.ndarray:
        """Disk (local z-normal, unit radius) -> world: centred at D s, facing the pinhole; ``axis``
        (a non-uniform disk's gradient direction) becomes the disk's local x (φ = 0 of its texture)."""
        if axis is None:
            e1, e2 = _basis(s)
        else:
            e2 = _across(s, axis)
            e1 = np.cross(s, e2)  # local y = e2 × s: right-handed with the normal -s
        rho = self.distance_mm * math.tan(self.full_angle_rad / 2.0)
        M = np.eye(4)
        # columns: local x, y, z (normal); z must point back to the camera (-s), right-handed
        M[:3, 0] = e2 * rho
        M[:3, 1] = e1 * rho
        M[:3, 2] = -s
        M[:3, 3] = s * self.distance_mm
        return M

    def window_origin_for(self, center_uv) -> tuple[int, int]:
        half = self.window_px // 2
        return (int(math.floor(center_uv[0] + 0.5)) - half,
                int(math.floor(center_uv[1] + 0.5)) - half)

    # -- rendering ----------------------------------------------------------------------------
    def render(self, sun_dir_cam, seed: int = 0, *, tight: bool = False, axis=None) -> SpotWindow:
        """Render the crop window around the predicted spot. Geometry problems become flags
        (and a :class:`GeometryWarning`); a spot outside the model/detector is not rendered.

        ``tight``: Mitsuba renders only the smallest even tile holding the spot
        (:func:`~rigsim.render.cube_mirror.sun_batch.spot_tile_px`, centred as the window), at the
        same spp per pixel; the window's other pixels are 0, as they are in expectation (nothing
        but the disk emits). Same expectation, fewer light paths; only the random numbers differ.
        ``axis``: the camera-frame direction of a non-uniform disk's gradient (:attr:`needs_axis`).
        With the cover glass's ghost or the pinhole's vignetting (:attr:`tiled_only`) the window is
        rendered by the tiled sensor (one tile), the only sensor that draws them; ``tight`` is then
        ignored."""
        s = _unit(sun_dir_cam)
        if self.needs_axis and axis is None:
            raise ValueError("the sun disk has a gradient (simulator_nonuniformity, angular): render needs its axis")
        t0 = time.perf_counter()
        c_uv, c_ok = self.camera.project_valid(s[None, :])
        center = c_uv[0] if c_ok[0] else None
        W = self.window_px
        origin = self.window_origin_for(center) if center is not None else (0, 0)
        flags = spot_geometry_flags(self.camera, s, self.full_angle_rad,
                                    window=(origin[0], origin[1], W, W))
        settings = self.settings()
        if flags["spot_outside_model"] or flags["spot_off_detector"]:
            warnings.warn(f"sun direction {s.round(6).tolist()} puts the spot "
                          f"{'outside the camera model' if flags['spot_outside_model'] else 'off the detector'}"
                          "; nothing rendered", GeometryWarning, stacklevel=2)
            return SpotWindow(np.zeros((W, W)), origin, s, center, flags, self.spp, int(seed),
                              self.variant, time.perf_counter() - t0, settings)
        if flags["spot_cut_by_edge"]:
            warnings.warn("the spot is cut by the detector edge; its centroid is biased",
                          GeometryWarning, stacklevel=2)
        if flags["spot_exceeds_window"]:
            warnings.warn(f"the spot ({flags['spot_extent_px']} px) does not fit the "
                          f"{W} px window; flux is lost", GeometryWarning, stacklevel=2)
        t = self._tile_px(s) if tight and not self.tiled_only else W
        state = {"sun_dir": s, "window_origin": origin} if axis is None else {
            "sun_dir": s, "window_origin": origin, "axis": np.asarray(axis, dtype=np.float64)}
        if self.tiled_only:
            if self._ghost_batch is None:
                from rigsim.render.cube_mirror.sun_batch import SunSpotBatch

                self._ghost_batch = SunSpotBatch(self, W, 1)
            arr = self._ghost_batch.render(s[None, :], np.array([origin]), seed=int(seed),
                                           axes=None if axis is None else np.asarray(axis)[None, :])[0]
            if self.diffraction is not None:  # the share of the spot's light the readout window keeps
                settings["diffraction_window_fraction"] = float(self._ghost_batch.window_fractions[0])
        elif not 4 <= t < W:  # the whole window (a spot overflowing it is flagged above)
            arr = self._scene.render(state, seed=int(seed), spp=self.spp)
        else:
            a = W // 2 - t // 2
            arr = np.zeros((W, W))
            arr[a:a + t, a:a + t] = self._tile_scene(t).render(
                {**state, "window_origin": (origin[0] + a, origin[1] + a)}, seed=int(seed), spp=self.spp)
            settings["tile_px"] = t  # what Mitsuba rendered, centred in the window
        return SpotWindow(arr, origin, s, center, flags, self.spp, int(seed), self.variant,
                          time.perf_counter() - t0, settings)

    def _tile_px(self, s: np.ndarray) -> int:
        """The tight tile of :meth:`render` for unit direction ``s`` (even, like the window)."""
        from rigsim.render.cube_mirror.sun_batch import spot_tile_px

        return int(spot_tile_px(self.camera, s[None, :], self.full_angle_rad)[0])

    def _tile_scene(self, t: int) -> Scene:
        if t not in self._tiles:
            self._tiles[t] = self._build(t, t, self.spp)
        return self._tiles[t]

    def window(self, sun_dir_cam, image: np.ndarray, seed: int = 0, seconds: float = 0.0, **settings) -> SpotWindow:
        """A :class:`SpotWindow` (``window_px`` wide, placed as :meth:`render` places it, with its
        geometry flags) holding ``image``: photons rendered elsewhere (e.g. a tile of
        :class:`~rigsim.render.cube_mirror.sun_batch.SunSpotBatch`) centred in it; the rest is 0."""
        s = _unit(sun_dir_cam)
        c_uv, c_ok = self.camera.project_valid(s[None, :])
        center = c_uv[0] if c_ok[0] else None
        W = self.window_px
        origin = self.window_origin_for(center) if center is not None else (0, 0)
        flags = spot_geometry_flags(self.camera, s, self.full_angle_rad, window=(origin[0], origin[1], W, W))
        full = np.zeros((W, W))
        t = image.shape[0]
        a = W // 2 - t // 2
        full[a:a + t, a:a + t] = image
        return SpotWindow(full, origin, s, center, flags, self.spp, int(seed), self.variant, float(seconds),
                          {**self.settings(), **settings})

    def render_frame(self, sun_dir_cam, seed: int = 0) -> tuple[np.ndarray, SpotWindow]:
        """Full detector frame (H, W) of expected photons: the window composited on black.

        Exact for this scene (nothing but the disk emits) as long as the spot fits the window
        (``flags['spot_exceeds_window']`` is False).
        """
        win = self.render(sun_dir_cam, seed)
        frame = np.zeros((self.camera.height, self.camera.width))
        return win.paste_into(frame), win

    def render_full(self, sun_dir_cam, seed: int = 0, spp: int = 16, axis=None) -> np.ndarray:
        """Render the whole detector with Mitsuba (no crop window): for comparison/benchmarks. The
        disk's radiance is drawn (``axis`` as in :meth:`render`); the ghost and the vignetting,
        drawn by the tiled sensor only, are refused."""
        _check_spp(spp, self.sampler)
        if self.tiled_only:
            raise ValueError("render_full draws neither the cover glass's ghost nor the pinhole's vignetting")
        if self.needs_axis and axis is None:
            raise ValueError("the sun disk has a gradient (simulator_nonuniformity, angular): render needs its axis")
        if self._full is None or self._full[1] != spp:
            self._full = (self._build(self.camera.width, self.camera.height, spp), spp)
        state = {"sun_dir": _unit(sun_dir_cam), "window_origin": (0, 0)}
        if axis is not None:
            state["axis"] = np.asarray(axis, dtype=np.float64)
        return self._full[0].render(state, seed=int(seed), spp=spp)

    def truth(self, sun_dir_cam, n: int = 2_000_000) -> dict:
        """The uniform disk's spot (the geometric truth the pipelines are compared with)."""
        return spot_truth(self.camera, sun_dir_cam, self.full_angle_rad, n=n,
                          response=self.response)

    def effects_truth(self, sun_dir_cam, n: int = 2_000_000, axis=None) -> dict:
        """What the effects change in the spot, by quadrature: the non-uniform disk's centroid and its
        shift from the uniform disk's; the vignetted spot's throughput, centroid and shift."""
        out = {}
        if self.pinhole is not None:
            base = self.truth(sun_dir_cam, n)
            t = spot_truth(self.camera, sun_dir_cam, self.full_angle_rad, n=n, response=self.response,
                           direction_weight=self.pinhole.direction_weight)
            if base.get("valid") and t.get("valid"):
                out["vignetting"] = {
                    "throughput": t["relative_flux"] / base["relative_flux"], "mean_uv": t["mean_uv"],
                    "pixel_centroid_uv": t["pixel_centroid_uv"],
                    "shift_px": np.subtract(t["mean_uv"], base["mean_uv"]).tolist()}
        if self.radiance is None:
            return out
        base = self.truth(sun_dir_cam, n)
        t = spot_truth(self.camera, sun_dir_cam, self.full_angle_rad, n=n, response=self.response,
                       radiance=self.radiance, radiance_axis=axis)
        if not (base.get("valid") and t.get("valid")):
            return out
        return {**out, "disk_radiance": {
            "u": self.radiance.u, "g": self.radiance.g, "axis_cam": None if axis is None else list(map(float, axis)),
            "mean_uv": t["mean_uv"], "pixel_centroid_uv": t["pixel_centroid_uv"],
            "shift_px": (np.subtract(t["mean_uv"], base["mean_uv"])).tolist()}}

    def settings(self) -> dict:
        """Every render setting, for frame sidecars."""
        return {
            "primitive": "sun_spot",
            "variant": self.variant,
            "integrator": "path(max_depth=1)",
            "sampler": self.sampler,
            "spp": self.spp,
            "window_px": self.window_px,
            "response": self.response,
            "full_angle_rad": self.full_angle_rad,
            "source_distance_mm": self.distance_mm,
            "spot_photons": self.spot_photons,
            "camera": self.camera.as_dict(),
            **({} if self.radiance is None else {"disk_radiance": {"u": self.radiance.u, "g": self.radiance.g}}),
            **({} if self.ghost is None else {"cover_glass": self.ghost.as_dict()}),
            **({} if self.pinhole is None else {"thick_pinhole": self.pinhole.as_dict()}),
            **({} if self.diffraction is None else {"pinhole_diffraction": {
                **self.diffraction.as_dict(), "supersampling": self.supersampling}}),
        }


def _across(s: np.ndarray, axis) -> np.ndarray:
    """``axis`` made perpendicular to the unit vector ``s``, unit."""
    a = np.asarray(axis, dtype=np.float64).reshape(3)
    a = a - (a @ s) * s
    n = np.linalg.norm(a)
    if not (np.isfinite(n) and n > 1e-9):
        raise ValueError(f"axis {a!r} must be a finite direction across the sun direction")
    return a / n

# ------------------------------------------------------------------------------------------ (from sun_sensor.py)
def default_spot_photons(rig: CubeMirrorRig) -> float:
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

    def __init__(self, rig: CubeMirrorRig, real: Realization | None = None, *, window_px: int | None = None,
                 spp: int = 1024, spot_photons: float | None = None):
        self.rig = rig
        self.real = real if real is not None else realization_from_rig(rig)
        self.analytic_camera = rig.sun_sensor.camera()
        check_memory(rig.sun_sensor.resolution_px, "sun_sensor.resolution_px")
        self.camera = self.analytic_camera
        self.full_angle_rad = math.radians(rig.sun_simulator.collimation_full_angle_arcmin / 60.0)
        self.spot_photons = float(spot_photons) if spot_photons is not None else default_spot_photons(rig)
        if window_px is None:  # from the geometry: the largest spot on this detector plus a margin
            window_px = sun_window_px(self.camera, self.full_angle_rad)
        eff = rig.effects
        radiance = eff.disk_radiance()
        ghost = eff.cover_glass_ghost
        ghost = CoverGlass(ghost.thickness_mm, ghost.refractive_index, rig.sun_sensor.focal_length_mm,
                           ghost.coating_reflectance) if ghost.enabled else None
        pinhole = eff.thick_pinhole()
        pd = eff.pinhole_diffraction
        diffraction = eff.pinhole_psf(rig.sun_sensor.focal_length_mm)
        self.renderer = SunSpotRenderer(self.camera, full_angle_rad=self.full_angle_rad, window_px=window_px,
                                        spp=spp, spot_photons=self.spot_photons, radiance=radiance, ghost=ghost,
                                        pinhole=pinhole, diffraction=diffraction, supersampling=pd.supersampling)

    def sun_dir_cam(self, pose_rad: dict) -> np.ndarray:
        R = self.real.turntable.R_rot_from_mount(pose_rad)
        s = self.real.R_sun_from_mount @ (R.T @ self.real.d_sun_rot)
        return s / np.linalg.norm(s)

    # -- the simulator's non-uniformity: fixed in the simulator's beam, seen from the turning sensor
    def _gradient_rot(self) -> np.ndarray:
        """The gradient's direction across the beam, in the rot frame (``direction_deg`` from the
        rot axis most nearly across the beam, towards beam × that axis)."""
        return gradient_across(self.real.d_sun_rot, self.rig.effects.simulator_nonuniformity.direction_deg)

    def gradient_axis_cam(self, pose_rad: dict) -> np.ndarray | None:
        """The angular gradient's direction in the camera frame at a pose (None without it)."""
        if not self.renderer.needs_axis:
            return None
        R = self.real.turntable.R_rot_from_mount(pose_rad)
        return self.real.R_sun_from_mount @ (R.T @ self._gradient_rot())

    def irradiance_scale(self, pose_rad: dict) -> float:
        """The simulator's irradiance at the pinhole relative to the beam's mean (spatial
        non-uniformity: 1 + g (p·ĝ)/(aperture/2), p the pinhole across the beam, turntable centre at
        the mount's origin); 1 without it."""
        nu = self.rig.effects.simulator_nonuniformity
        if not (nu.enabled and nu.kind == "spatial"):
            return 1.0
        p = self.real.turntable.R_rot_from_mount(pose_rad) @ np.asarray(nu.pinhole_in_mount_mm, dtype=np.float64)
        return 1.0 + nu.nonuniformity * float(p @ self._gradient_rot()) / (self.rig.sun_simulator.aperture_mm / 2.0)

    def batch_inputs(self, poses_rad: list[dict]) -> dict:
        """What :meth:`SunSpotBatch.render` needs besides the sun directions for these poses:
        ``axes`` and ``scales`` when an effect needs them, else nothing."""
        out = {}
        if self.renderer.needs_axis:
            out["axes"] = np.array([self.gradient_axis_cam(p) for p in poses_rad]).reshape(-1, 3)
        nu = self.rig.effects.simulator_nonuniformity
        if nu.enabled and nu.kind == "spatial":
            out["scales"] = np.array([self.irradiance_scale(p) for p in poses_rad])
        return out

    def render(self, pose_rad: dict, seed: int = 0, *, noiseless: bool = False, truth_points: int = 400_000,
               full_frame: bool = True, tight: bool = False) -> Frame:
        """Render one frame. ``full_frame=False`` digitises only the crop window (same pixels, same
        fixed pattern, same noise statistics as the full frame; 10× faster for sweeps). ``tight``:
        Mitsuba renders only the spot's tile of the window (:meth:`SunSpotRenderer.render`). The
        frame's ``extra["window"]`` is the rendered :class:`SpotWindow`."""
        t0 = time.perf_counter()
        s = self.sun_dir_cam(pose_rad)
        win = self.renderer.render(s, seed=seed, tight=tight, axis=self.gradient_axis_cam(pose_rad))
        scale = self.irradiance_scale(pose_rad)
        if scale != 1.0:
            win.image *= scale
            win.settings["irradiance_scale"] = scale
        return self.frame(pose_rad, win, seed=seed, noiseless=noiseless, truth_points=truth_points,
                          full_frame=full_frame, t0=t0)

    def frame(self, pose_rad: dict, win: SpotWindow, *, seed: int, noiseless: bool = False,
              truth_points: int = 400_000, full_frame: bool = True, t0: float | None = None) -> Frame:
        """The detector stage of :meth:`render` for a rendered window ``win`` (from this scene's
        renderer or from :class:`~rigsim.render.cube_mirror.sun_batch.SunSpotBatch`): the
        digitised frame with its sidecar (truth from ``truth_points`` quadrature points)."""
        t0 = time.perf_counter() if t0 is None else t0
        s = win.sun_dir_cam
        ss = self.rig.sun_sensor
        if full_frame:
            photons = win.paste_into(np.zeros((self.camera.height, self.camera.width)))
            origin, shape = (0, 0), None
        else:
            shape = (ss.resolution_px[1], ss.resolution_px[0])
            photons, origin = detector_part(win.image, win.origin_uv, shape)
        truth = self.renderer.truth(s, n=truth_points) if not (win.flags.get("spot_off_detector") or win.flags.get("spot_outside_model")) else {"valid": False}
        effects = self._effects_truth(pose_rad, s, truth_points) if truth.get("valid") else {}
        return digitise(
            photons, ss.detector, seed=seed, noiseless=noiseless, origin_uv=origin, detector_shape=shape,
            truth={
                "rig": self.rig.name,
                "sun_dir_cam": s.tolist(),
                "spot": truth,
                "camera_true": self.camera.as_dict(),
                "R_sun_from_mount": self.real.R_sun_from_mount.tolist(),
                **({"effects": effects} if effects else {}),
            },
            render={**win.settings, "noiseless": noiseless, "window_origin_uv": list(win.origin_uv)},
            geometry_flags=dict(win.flags),
            pose={k: math.degrees(v) for k, v in pose_rad.items()},
            extra={"window": win}, seconds=time.perf_counter() - t0)


    def _effects_truth(self, pose_rad: dict, s: np.ndarray, n: int) -> dict:
        """The sidecar's truth of the enabled sun-sensor effects (the geometric spot stays the truth)."""
        out = dict(self.renderer.effects_truth(s, n, axis=self.gradient_axis_cam(pose_rad)))
        g = self.renderer.ghost
        if g is not None:
            th = float(CoverGlass.theta(s))
            out["cover_glass_ghost"] = {
                "theta_deg": math.degrees(th), "direct_transmittance": float(g.direct(th)),
                "ghost_ratio": float(g.ghost_ratio(th)),
                "offset_px": g.offset_px(s, self.camera.fx, self.camera.fy).tolist()}
        if self.irradiance_scale(pose_rad) != 1.0:
            out["irradiance_scale"] = self.irradiance_scale(pose_rad)
        if self.renderer.diffraction is not None:
            out["pinhole_diffraction"] = diffraction_truth(self.renderer, s)
        return out


def diffraction_truth(renderer: SunSpotRenderer, s: np.ndarray) -> dict:
    """The diffraction PSF at the spot's field angle (the sidecar's truth): its rms radius and
    covariance (px, over the readout window), and the share of its light that falls inside the
    window around the spot's centre (the rest is lost to the readout)."""
    psf, cam, W = renderer.diffraction, renderer.camera, renderer.window_px
    c_uv, _ = cam.project_valid(s[None, :])
    o = renderer.window_origin_for(c_uv[0])
    step = 1.0  # the PSF's band ends below 1 cycle/px: its sums and moments on the pixel grid are exact
    K = psf.kernel(s, cam.fx, cam.fy, W, step)
    off = np.arange(-(K.shape[0] // 2), K.shape[0] // 2 + 1) * step
    iu = (off + c_uv[0][0] >= o[0] - 0.5) & (off + c_uv[0][0] < o[0] + W - 0.5)
    iv = (off + c_uv[0][1] >= o[1] - 0.5) & (off + c_uv[0][1] < o[1] + W - 0.5)
    c, h = K.shape[0] // 2, round(W / 2 / step)
    mom = kernel_moments(K[c - h:c + h + 1, c - h:c + h + 1], step)  # over a window's width around the spot
    theta = math.acos(min(1.0, float(s[2])))
    return {"theta_deg": math.degrees(theta), "fresnel_number_550nm_across": psf.fresnel_number(550.0) * math.cos(theta),
            "psf_rms_radius_px": mom["rms_radius_px"], "psf_cov_px2": mom["cov_px2"],
            "flux_fraction_in_window": float(K[np.ix_(iv, iu)].sum())}


def detector_part(image: np.ndarray, origin_uv, shape: tuple[int, int]) -> tuple[np.ndarray, tuple[int, int]]:
    """The detector's part of a window at ``origin_uv`` on a detector of ``shape`` (rows, cols): a
    window reaching past the edge reads out only real pixels. Returns (pixels, their origin)."""
    (u0, v0), (h, w) = origin_uv, image.shape
    a0, b0 = max(0, u0), max(0, v0)
    a1, b1 = max(a0, min(shape[1], u0 + w)), max(b0, min(shape[0], v0 + h))
    return image[b0 - v0:b1 - v0, a0 - u0:a1 - u0], (a0, b0)


def sun_sensor_export_dict(scene: SunSensorScene, pose_rad: dict, spp: int = 64) -> tuple[dict, list[str]]:
    """Built-in-plugins-only scene dict of the sun-sensor view (for XML export).

    The plain ``mitsuba`` command cannot load the distorted ``rigsim_pinhole`` sensor, so the
    export uses the built-in ``perspective`` sensor with the same fx and principal point and no
    distortion (and square pixels): its spot sits at the *undistorted* projection.
    """
    from rigsim.render.export import cv_to_mitsuba_camera, perspective_from_intrinsics

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
