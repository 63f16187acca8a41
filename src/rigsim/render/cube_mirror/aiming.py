"""Seed 000 aiming-camera frames with the sun simulator's divergence: the concentricity search's eyes.

Why a second diaphragm renderer: with a collimated 2.5 mm pencil the returned spot falls back
into the 2.5 mm hole at the null and vanishes (docs/render_diaphragm.md, findings), so the
paper's "concentric within 1 px" judgement needs the simulator's divergence: every point of the
hole sends a cone of full angle α (rig: 32′, the sun's disk) to the cube, and the returned spot
on the screen is the pencil's disk blurred by a uniform disk of radius R = path·tan(α/2)
(path = hole → face → screen ≈ 1.3 m: R ≈ 6 mm), minus the light that falls back into the hole.

How it is rendered (``docs/campaign.md`` has the measurements behind each choice):

1. Mitsuba renders the *collimated* pencil on a hole-less screen (:class:`DiaphragmRenderer` in its
   ``"diffuse"`` fidelity mode: the true cube face, true turntable kinematics, the aiming camera's
   perspective), to 0.1 µm on the screen.
2. The image is resampled onto a screen-plane grid (the camera's homography), convolved with the
   divergence disk (FFT) and resampled back: a uniform cone is shift-invariant on the screen to
   ~1e-4 relative over the field, so this equals Mitsuba with the divergence sampled by
   hundreds of pencils, without its Monte-Carlo noise — a 256-pencil ptracer render measured
   2–3 µm of centroid noise at the same cost, this path 0.1 µm.
3. The light that lands inside the hole is lost: the image is multiplied by (1 − the hole's exact
   pixel coverage).
4. The hole frame (the paper's first image, spot blocked) is the glowing hole alone, rendered once
   per face (the hole does not move); the spot frame holds the spot plus the glow, as on the real
   screen. Both go through the aiming camera's detector model.

Brightness: the divergent spot's plateau is ``spot_photons_per_px`` (default half the full well),
the glow's is ``hole_glow_ratio`` times that (paper: about equal).
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from rigsim.errors import GeometryWarning, SaturationWarning
from rigsim.render.budget import check_memory
from rigsim.render.cube_mirror.diaphragm import _WARN_FLAGS, DiaphragmFrames, DiaphragmRenderer, _derived_seed
from rigsim.render.frame import digitise
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.truth.cube_mirror.diaphragm import DiaphragmTruth, diaphragm_geometry, rasterise_screen_disk
from rigsim.truth.cube_mirror.realization import Realization, realization_from_rig

__all__ = ["ConcentricityRenderer", "divergence_radius_mm"]


def divergence_radius_mm(rig: CubeMirrorRig, full_angle_rad: float) -> float:
    """Radius of the blur disk on the screen: (hole → face → screen) × tan(α/2)."""
    return 2.0 * rig.diaphragm_screen.distance_to_cube_mm * math.tan(0.5 * full_angle_rad)


class ConcentricityRenderer:
    """Aiming-camera frames (hole, spot) of one face at turntable poses, divergent beam.

    ``divergence_full_angle_arcmin`` defaults to the rig's sun-simulator collimation angle.
    ``grid_mm`` is the screen-plane resampling step of the convolution (default 0.01 mm,
    finer than the 15 µm object pixel).
    """

    def __init__(self, rig: CubeMirrorRig, real: Realization | None = None, face_index: int = 0, *, spp: int = 4,
                 divergence_full_angle_arcmin: float | None = None, grid_mm: float = 0.01,
                 spot_photons_per_px: float | None = None, hole_glow_ratio: float = 1.0,
                 deterministic: bool = True, detector=None):
        self.rig = rig
        self.real = real if real is not None else realization_from_rig(rig)
        arcmin = rig.sun_simulator.collimation_full_angle_arcmin if divergence_full_angle_arcmin is None \
            else float(divergence_full_angle_arcmin)
        if not (0.0 < arcmin < 600.0):
            raise ValueError(f"divergence_full_angle_arcmin = {arcmin!r}: must be in (0, 600)")
        if not (0.001 <= grid_mm <= 0.1):
            raise ValueError(f"grid_mm = {grid_mm!r}: must be in [0.001, 0.1]")
        self.divergence_rad = math.radians(arcmin / 60.0)
        det = detector if detector is not None else rig.aiming_camera.detector
        check_memory(rig.aiming_camera.resolution_px, "aiming_camera.resolution_px")
        if spot_photons_per_px is None:
            spot_photons_per_px = 0.5 * det.full_well_e / det.quantum_efficiency
        self.spot_photons_per_px = float(spot_photons_per_px)
        self.pencil = DiaphragmRenderer(rig, self.real, face_index, spp=spp, beam="collimated",
                                        return_into_hole="diffuse", hole_glow_ratio=hole_glow_ratio,
                                        spot_photons_per_px=self.spot_photons_per_px, detector=det,
                                        deterministic=deterministic, warmup=False)
        self.detector = det
        self.geometry = self.pencil.geometry  # camera, homography (no beam-mode dependence)
        # truth and flags of the divergent spot on the real (holed) screen
        self.truth_geometry = diaphragm_geometry(rig, self.real, face_index, beam="divergent",
                                                 divergence_full_angle_arcmin=arcmin, return_into_hole="absorb")
        g = self.geometry
        r = g.hole_radius_mm
        self.R_div_mm = divergence_radius_mm(rig, self.divergence_rad)
        # brightness: the blurred plateau is (r/R)² of the pencil's when R > r
        self._gain = max(1.0, (self.R_div_mm / r) ** 2)
        self._setup_grid(float(grid_mm))
        self.hole_coverage = rasterise_screen_disk(g, (0.0, 0.0), r)
        self._hole_cache: dict[int, np.ndarray] = {}

    # -- the screen-plane convolution --------------------------------------------------------
    def _setup_grid(self, gs: float) -> None:
        g = self.geometry
        W, H = g.camera.width, g.camera.height
        corners = g.uv_to_screen(np.array([[-0.5, -0.5], [W - 0.5, -0.5], [-0.5, H - 0.5], [W - 0.5, H - 0.5]]))
        lo, hi = corners.min(axis=0) - gs, corners.max(axis=0) + gs
        ns = int(math.ceil((hi[0] - lo[0]) / gs)) + 1
        nt = int(math.ceil((hi[1] - lo[1]) / gs)) + 1
        s = lo[0] + gs * np.arange(ns)
        t = lo[1] + gs * np.arange(nt)
        S, T = np.meshgrid(s, t)
        uv = g.screen_to_uv(np.stack([S.ravel(), T.ravel()], axis=1))
        self._to_grid = (uv[:, 0].reshape(nt, ns).astype(np.float32), uv[:, 1].reshape(nt, ns).astype(np.float32))
        vv, uu = np.mgrid[0:H, 0:W]
        st = g.uv_to_screen(np.stack([uu.ravel(), vv.ravel()], axis=1).astype(float))
        self._from_grid = (((st[:, 0] - lo[0]) / gs).reshape(H, W).astype(np.float32),
                           ((st[:, 1] - lo[1]) / gs).reshape(H, W).astype(np.float32))
        R = self.R_div_mm / gs
        k = int(math.ceil(R)) + 1
        ky, kx = np.mgrid[-k:k + 1, -k:k + 1].astype(float)
        sub = 4  # anti-aliased disk
        acc = np.zeros_like(kx)
        for a in range(sub):
            for b in range(sub):
                acc += np.hypot(kx + (a + 0.5) / sub - 0.5, ky + (b + 0.5) / sub - 0.5) < R
        self._kernel = acc / acc.sum()
        self.grid_mm = gs

    def diverge(self, pencil_img: np.ndarray) -> np.ndarray:
        """Blur a collimated-pencil image by the divergence disk on the screen plane, then drop the
        light that falls into the hole. Units are kept (the plateau scales by (r/R)²)."""
        import cv2
        from scipy.signal import fftconvolve

        f = cv2.remap(np.asarray(pencil_img, np.float32), *self._to_grid, cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        fc = fftconvolve(f.astype(np.float64), self._kernel, mode="same").astype(np.float32)
        out = cv2.remap(fc, *self._from_grid, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        return np.clip(out.astype(np.float64), 0.0, None) * (1.0 - self.hole_coverage)

    # -- frames ---------------------------------------------------------------------------
    def hole_photons(self, seed: int = 0) -> np.ndarray:
        """The glowing hole alone (rendered once per seed: the hole does not move)."""
        if seed not in self._hole_cache:
            self._hole_cache[seed] = self.pencil._render(self.pencil._hole_scene, _derived_seed(seed, 2)) \
                if self.pencil._hole_scene is not None else np.zeros((self.geometry.camera.height,
                                                                      self.geometry.camera.width))
        return self._hole_cache[seed]

    def spot_photons(self, pose_rad: dict, seed: int = 0) -> np.ndarray:
        self.pencil.set_pose(pose_rad)
        pencil = self.pencil._render(self.pencil._spot_scene, _derived_seed(seed, 1))
        return self.diverge(pencil) * self._gain

    def truth(self, pose_rad: dict) -> DiaphragmTruth:
        return self.truth_geometry.trace(pose_rad)

    def render(self, pose_rad: dict, seed: int = 0, *, hole_seed: int = 0, noiseless: bool = False,
               warn: bool = True, spot: bool = True) -> DiaphragmFrames:
        """Hole frame (glow; detector noise from ``seed``) and spot frame at ``pose_rad`` (true
        angles). Geometry problems are flags (and warnings when ``warn``); nothing is rendered
        when the spot does not come back to the screen. ``spot=False`` skips the spot's render
        (only the hole frame is wanted: the spot frame then shows the hole alone)."""
        if int(seed) != seed or seed < 0:
            raise ValueError(f"seed = {seed!r}: must be an integer >= 0")
        sec = {}
        t0 = time.perf_counter()
        tr = self.truth(pose_rad)
        flags = dict(tr.flags)
        if warn:
            for k, msg in _WARN_FLAGS.items():
                if flags.get(k) and k != "beam_source_in_view":
                    warnings.warn(msg.format(face=self.geometry.face), GeometryWarning, stacklevel=2)
        hole = self.hole_photons(hole_seed)
        sec["hole_render"] = time.perf_counter() - t0
        t1 = time.perf_counter()
        rendered = bool(spot) and not (flags.get("spot_not_returned") or flags.get("beam_misses_face"))
        if not rendered:
            spot = np.zeros_like(hole)
        else:
            spot = self.spot_photons(pose_rad, seed)
        sec["spot_render"] = time.perf_counter() - t1
        t2 = time.perf_counter()
        render = {**self.settings(), "noiseless": bool(noiseless), "spot_rendered": rendered}
        frames = {name: digitise(photons, self.detector, seed=_derived_seed(seed, stream), noiseless=noiseless,
                                 frame_seed=int(seed), truth={**tr.as_dict(), "frame": name}, truth_object=tr, render=render,
                                 geometry_flags=flags, pose={"true_angles_rad": dict(pose_rad), "face": self.geometry.face},
                                 sidecar_extra={"hole_seed": int(hole_seed), "detector_seed": _derived_seed(seed, stream)})
                  for name, photons, stream in (("hole", hole, 3), ("spot", spot + hole, 4))}
        sec["detector"] = time.perf_counter() - t2
        flags["saturated_pixels"] = {k: f.detector.saturated_pixels for k, f in frames.items()}
        flags["saturated"] = bool(any(flags["saturated_pixels"].values()))
        if flags["saturated"] and warn:
            warnings.warn(f"aiming camera: saturated pixels {flags['saturated_pixels']}", SaturationWarning,
                          stacklevel=2)
        sec["total"] = time.perf_counter() - t0
        return DiaphragmFrames(dict(pose_rad), int(seed), hole, spot, frames["hole"], frames["spot"], tr, flags, sec)

    def settings(self) -> dict:
        s = self.pencil.settings()
        s.update({"beam": "divergent (screen-plane convolution of the rendered pencil)",
                  "divergence_full_angle_rad": self.divergence_rad, "divergence_radius_mm": self.R_div_mm,
                  "grid_mm": self.grid_mm, "spot_photons_per_px": self.spot_photons_per_px})
        return s
