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
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from rigsim.errors import GeometryWarning, SaturationWarning
from rigsim.render.budget import check_memory
from rigsim.render.cube_mirror.diaphragm import _WARN_FLAGS, DiaphragmFrames, DiaphragmRenderer, _derived_seed
from rigsim.render.cube_mirror.pencil_chunks import PencilChunks, chunk_count
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
    finer than the 15 µm object pixel). ``workers`` processes (this one included) render the
    pencil's fixed sample chunks (:mod:`rigsim.render.cube_mirror.pencil_chunks`): the frames are
    bit-identical for any ``workers``; ``workers > 1`` starts ``workers - 1`` processes, stopped by
    :meth:`close`, with the renderer or at exit.

    ``spp`` is the pencil's light paths per camera pixel. They are traced onto a film binned
    ``film_binning`` × ``film_binning`` (default: the coarsest of 4, 2, 1 that divides the camera's
    width and height; ``spp·b²`` multijittered samples per film pixel, per chunk
    rounded up to a count the sampler stratifies): the
    pencil is blurred by a disk of ~400 px radius next, so the coarser film costs nothing in the
    spot, and the larger stratified sample sets cut the spot centre's Monte-Carlo noise
    (docs/campaign.md). The hole glow is rendered at full resolution with ``hole_spp`` (default
    ``max(4, spp)``), once per face and seed.
    """

    def __init__(self, rig: CubeMirrorRig, real: Realization | None = None, face_index: int = 0, *, spp: int = 2,
                 divergence_full_angle_arcmin: float | None = None, grid_mm: float = 0.01,
                 spot_photons_per_px: float | None = None, hole_glow_ratio: float = 1.0,
                 deterministic: bool = True, detector=None, workers: int = 1, film_binning: int | None = None,
                 hole_spp: int | None = None):
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
        if film_binning is None:  # the coarsest of 4, 2, 1 that divides the camera's pixels
            w, h = (int(x) for x in rig.aiming_camera.resolution_px)
            film_binning = next(k for k in (4, 2, 1) if w % k == 0 and h % k == 0)
        b = int(film_binning)
        if b != film_binning or b < 1:
            raise ValueError(f"film_binning = {film_binning!r}: must be an integer >= 1")
        if int(spp) != spp or spp < 1:
            raise ValueError(f"spp = {spp!r}: must be an integer >= 1")
        self.spp = int(spp)
        self.hole_spp = max(4, self.spp) if hole_spp is None else int(hole_spp)
        if self.hole_spp < 1:
            raise ValueError(f"hole_spp = {hole_spp!r}: must be an integer >= 1")
        # spp light paths per camera pixel = spp·b² per pixel of the b × b binned pencil film, per
        # chunk rounded up to a count the multijitter sampler stratifies (as Mitsuba would round it)
        n = chunk_count(self.spp * b * b)
        per_chunk = _multijitter_count(self.spp * b * b // n)
        pencil_kw = {"spp": n * per_chunk, "sampler_count": per_chunk, "beam": "collimated", "return_into_hole": "diffuse",
                     "hole_glow_ratio": hole_glow_ratio, "spot_photons_per_px": self.spot_photons_per_px,
                     "detector": det, "deterministic": deterministic, "warmup": False,
                     "spot_film_binning": b}
        self.pencil = DiaphragmRenderer(rig, self.real, face_index, **pencil_kw)
        # the pencil's samples in fixed chunks: the same image for any number of worker processes
        self._chunks = PencilChunks(self.pencil, workers, init=(rig, self.real, int(face_index), pencil_kw))
        self.workers = self._chunks.workers
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
        self._surface = None  # the screen_material / ambient_light maps, made on first use
        self.exposure_scale = 1.0  # < 1 with [effects.ambient_light] (surface_maps)

    # -- the screen's surface effects ([effects.screen_material], [effects.ambient_light]) ---------
    def surface_maps(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """(relative albedo per camera pixel, room-light photons per camera pixel), each None when its
        effect is off. Fixed for the rig (the screen and the camera do not move): made once."""
        eff = self.rig.effects
        mat, amb = eff.screen_material, eff.ambient_light
        if not (mat.enabled or amb.enabled):
            return None, None
        if self._surface is None:
            self._surface = _surface_maps(self, mat, amb)
            if amb.enabled:  # the operator shortens the exposure so that spot + room light peak where the spot did
                peak = float(np.max(self._surface[1]))
                self.exposure_scale = self.spot_photons_per_px / (self.spot_photons_per_px + peak)
        return self._surface

    # -- the screen-plane convolution --------------------------------------------------------
    def _setup_grid(self, gs: float) -> None:
        """The screen-plane grid (step ``gs`` mm) covering the camera's field, and the divergence
        disk on it. The image ↔ grid maps are computed per frame on the lit window only."""
        g = self.geometry
        W, H = g.camera.width, g.camera.height
        corners = g.uv_to_screen(np.array([[-0.5, -0.5], [W - 0.5, -0.5], [-0.5, H - 0.5], [W - 0.5, H - 0.5]]))
        lo, hi = corners.min(axis=0) - gs, corners.max(axis=0) + gs
        self._grid_lo = lo
        self._grid_shape = (math.ceil((hi[1] - lo[1]) / gs) + 1, math.ceil((hi[0] - lo[0]) / gs) + 1)
        self._H = np.asarray(g.H_screen_to_uv, float)
        self._Hi = np.linalg.inv(self._H)
        self._kernel = _disk_kernel(self.R_div_mm / gs)
        self._kernel_fft: dict[tuple[int, int], np.ndarray] = {}
        self.grid_mm = gs

    def _kernel_spectrum(self, shape: tuple[int, int]) -> np.ndarray:
        """rfft2 of the divergence disk (float32) zero-padded to ``shape``, cached per shape."""
        from scipy import fft

        F = self._kernel_fft.get(shape)
        if F is None:
            if len(self._kernel_fft) >= 8:
                self._kernel_fft.clear()
            F = fft.rfft2(self._kernel.astype(np.float32), s=shape, workers=1)
            self._kernel_fft[shape] = F
        return F

    def diverge(self, pencil_img: np.ndarray, binning: int = 1) -> np.ndarray:
        """Blur a collimated-pencil image by the divergence disk on the screen plane, then drop the
        light that falls into the hole. Units are kept (the plateau scales by (r/R)²).

        Only the lit part is processed: the grid window around the pencil's nonzero pixels, its
        full linear convolution with the disk (float32 FFT, the disk's spectrum cached per size),
        and the image pixels that window covers; the rest of the frame is exactly zero.

        ``binning`` = b: ``pencil_img`` is a film of b × b camera pixels per pixel (the pencil's
        binned render); it is sampled at the grid points' camera positions all the same."""
        import cv2
        from scipy import fft

        img = np.asarray(pencil_img)
        b = int(binning)
        Hh, Ww = img.shape[0] * b, img.shape[1] * b
        out = np.zeros((Hh, Ww))
        rows = np.flatnonzero(np.any(img != 0, axis=1))
        if rows.size == 0:
            return out
        cols = np.flatnonzero(np.any(img[rows[0]:rows[-1] + 1] != 0, axis=0))
        gs = self.grid_mm
        lo = self._grid_lo
        nt, ns = self._grid_shape
        # grid window: every grid point whose bilinear sample touches a lit pixel (camera pixels)
        u_lo, u_hi = b * cols[0] - 0.5 * (b + 1), b * cols[-1] + 0.5 * (3 * b - 1)
        v_lo, v_hi = b * rows[0] - 0.5 * (b + 1), b * rows[-1] + 0.5 * (3 * b - 1)
        st = _homography(self._Hi, np.array([u_lo, u_hi, u_lo, u_hi]), np.array([v_lo, v_lo, v_hi, v_hi]))
        j0 = max(0, math.floor((st[0].min() - lo[0]) / gs) - 1)
        j1 = min(ns, math.ceil((st[0].max() - lo[0]) / gs) + 2)
        i0 = max(0, math.floor((st[1].min() - lo[1]) / gs) - 1)
        i1 = min(nt, math.ceil((st[1].max() - lo[1]) / gs) + 2)
        if j1 <= j0 or i1 <= i0:
            return out
        s = lo[0] + gs * np.arange(j0, j1)
        t = lo[1] + gs * np.arange(i0, i1)
        uv = _homography(self._H, s[None, :], t[:, None])
        if b > 1:  # camera pixel (u, v) → binned film pixel ((u + 0.5)/b − 0.5, …)
            uv = tuple((x + 0.5) / b - 0.5 for x in uv)
        f = cv2.remap(np.asarray(img, np.float32), uv[0].astype(np.float32), uv[1].astype(np.float32),
                      cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        # full linear convolution: grid rows i0 - k … i1 - 1 + k, columns likewise
        K = self._kernel.shape[0]
        k = K // 2
        full = (f.shape[0] + K - 1, f.shape[1] + K - 1)
        shape = tuple(fft.next_fast_len(64 * -(-n // 64), real=True) for n in full)
        fc = fft.irfft2(fft.rfft2(f, s=shape, workers=1) * self._kernel_spectrum(shape), s=shape, workers=1)
        # crop to the grid (as a "same" convolution over the whole grid would)
        g0, g1 = max(0, i0 - k), min(nt, i1 - 1 + k + 1)
        h0, h1 = max(0, j0 - k), min(ns, j1 - 1 + k + 1)
        fc = np.ascontiguousarray(fc[g0 - (i0 - k):g1 - (i0 - k), h0 - (j0 - k):h1 - (j0 - k)], dtype=np.float32)
        # image pixels covered by that grid window
        sb = lo[0] + gs * np.array([h0 - 1, h1, h0 - 1, h1])
        tb = lo[1] + gs * np.array([g0 - 1, g0 - 1, g1, g1])
        uvb = _homography(self._H, sb, tb)
        a0 = max(0, math.floor(uvb[0].min()) - 1)
        a1 = min(Ww, math.ceil(uvb[0].max()) + 2)
        b0 = max(0, math.floor(uvb[1].min()) - 1)
        b1 = min(Hh, math.ceil(uvb[1].max()) + 2)
        if a1 <= a0 or b1 <= b0:
            return out
        stp = _homography(self._Hi, np.arange(a0, a1, dtype=float)[None, :], np.arange(b0, b1, dtype=float)[:, None])
        mx = ((stp[0] - lo[0]) / gs - h0).astype(np.float32)
        my = ((stp[1] - lo[1]) / gs - g0).astype(np.float32)
        win = cv2.remap(fc, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        out[b0:b1, a0:a1] = np.clip(win.astype(np.float64), 0.0, None) * (1.0 - self.hole_coverage[b0:b1, a0:a1])
        return out

    # -- frames ---------------------------------------------------------------------------
    def hole_photons(self, seed: int = 0) -> np.ndarray:
        """The glowing hole alone (rendered once per seed: the hole does not move)."""
        if seed not in self._hole_cache:
            self._hole_cache[seed] = self.pencil._render(self.pencil._hole_scene, _derived_seed(seed, 2), self.hole_spp) \
                if self.pencil._hole_scene is not None else np.zeros((self.geometry.camera.height,
                                                                      self.geometry.camera.width))
        return self._hole_cache[seed]

    def flat_photons(self) -> np.ndarray:
        """The screen lit evenly by a lamp, the simulator shuttered (no glow, no spot): half the full
        well on a uniform screen, times the screen's albedo grain; the hole, which the lamp does not
        light, is dark. The room light, when on, is there too, as in the hole frame."""
        albedo, ambient = self.surface_maps()
        level = 0.5 * self.detector.full_well_e / self.detector.quantum_efficiency
        flat = np.full((self.geometry.camera.height, self.geometry.camera.width), level) * (1.0 - self.hole_coverage)
        if albedo is not None:
            flat = flat * albedo
        return flat if ambient is None else flat + ambient * self.exposure_scale

    def render_flats(self, n: int, seed: int = 0, *, noiseless: bool = False):
        """``n`` digitised flat frames (:meth:`flat_photons`), each with its own detector noise from
        ``seed``, one at a time (a generator: a campaign keeps their running sum, not the frames)."""
        photons = self.flat_photons()
        for k in range(int(n)):
            yield digitise(photons, self.detector, seed=_derived_seed(seed, 100 + k), noiseless=noiseless,
                           frame_seed=int(seed), truth={"frame": f"flat {k}"}, render={**self.settings(), "flat": True})

    def spot_photons(self, pose_rad: dict, seed: int = 0) -> np.ndarray:
        pencil = self._chunks.render(pose_rad, _derived_seed(seed, 1))
        spot = self.diverge(pencil, self.pencil.spot_film_binning) * self._gain
        albedo, ambient = self.surface_maps()
        if albedo is not None:
            spot = spot * albedo
        return spot if ambient is None else spot * self.exposure_scale

    def close(self) -> None:
        """Stop the worker processes (``workers > 1``); they also stop with the renderer or at exit."""
        self._chunks.close()

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
        _, ambient = self.surface_maps()
        if ambient is not None:  # room light on the screen, in both frames; the exposure shortened for it
            hole = (hole + ambient) * self.exposure_scale
        sec["hole_render"] = time.perf_counter() - t0
        rendered = bool(spot) and not (flags.get("spot_not_returned") or flags.get("beam_misses_face"))
        render = {**self.settings(), "noiseless": bool(noiseless), "spot_rendered": rendered}

        def frame(name: str, photons: np.ndarray, stream: int):
            return digitise(photons, self.detector, seed=_derived_seed(seed, stream), noiseless=noiseless,
                            frame_seed=int(seed), truth={**tr.as_dict(), "frame": name}, truth_object=tr, render=render,
                            geometry_flags=flags, pose={"true_angles_rad": dict(pose_rad), "face": self.geometry.face},
                            sidecar_extra={"hole_seed": int(hole_seed), "detector_seed": _derived_seed(seed, stream)})

        t1 = time.perf_counter()
        # the hole frame's detector pass (its own seed) runs while Mitsuba, which releases the GIL,
        # renders the spot: the same frames as one after the other
        with ThreadPoolExecutor(1) as ex:
            hole_frame = ex.submit(frame, "hole", hole, 3)
            spot = self.spot_photons(pose_rad, seed) if rendered else np.zeros_like(hole)
            sec["spot_render"] = time.perf_counter() - t1
            t2 = time.perf_counter()
            frames = {"hole": hole_frame.result()}
        frames["spot"] = frame("spot", spot + hole, 4)
        sec["detector"] = time.perf_counter() - t2  # the spot frame's (the hole frame's overlaps the render)
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
                  "grid_mm": self.grid_mm, "spot_photons_per_px": self.spot_photons_per_px,
                  "pencil_chunks": chunk_count(self.pencil.spp), "spp_per_camera_pixel": self.spp,
                  "hole_spp": self.hole_spp})
        return s


def _surface_maps(cr: ConcentricityRenderer, mat, amb) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The albedo grain sampled per camera pixel (a fixed screen-plane field, averaged over 4 × 4
    sub-samples of each pixel's footprint) and the room light's photons per pixel: ρ·E/π relative to
    the spot plateau's ρ·E_plateau/π, where E_plateau = E_beam · (cube reflectance) · (r/R)²."""
    from rigsim.optics.screen_surface import ambient_illuminance, grain_field, pixel_albedo
    from rigsim.render.cube_mirror.diaphragm import cube_reflectance

    g = cr.geometry
    W, H = g.camera.width, g.camera.height
    albedo = None
    if mat.enabled:
        corners = g.uv_to_screen(np.array([[-0.5, -0.5], [W - 0.5, -0.5], [-0.5, H - 0.5], [W - 0.5, H - 0.5]]))
        step = min(0.01, 1e-3 * mat.grain_um / 6.0)
        lo = corners.min(axis=0) - 2 * step
        shape = tuple(math.ceil(x) + 3 for x in ((corners.max(axis=0) - lo) / step)[::-1])
        albedo = pixel_albedo(grain_field(shape, step, mat.grain_um, mat.contrast, mat.seed), lo, step,
                              g.uv_to_screen, W, H)
    ambient = None
    if amb.enabled:
        uu, vv = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
        st = g.uv_to_screen(np.stack([uu, vv], axis=-1).reshape(-1, 2)).reshape(H, W, 2)
        e_plateau = amb.beam_illuminance_lux * cube_reflectance(cr.rig) / cr._gain
        ambient = cr.spot_photons_per_px / e_plateau * ambient_illuminance(
            st, amb.illuminance_lux, amb.gradient_per_100mm, amb.direction_deg) * (1.0 - cr.hole_coverage)
        if albedo is not None:
            ambient = ambient * albedo
    return albedo, ambient


def _multijitter_count(n: int) -> int:
    """The sample count Mitsuba's ``multijitter`` sampler uses for ``n`` (⌊√n⌋ × ⌈n/⌊√n⌋⌉ strata)."""
    rx = math.isqrt(n)
    return rx * -(-n // rx)


def _homography(H: np.ndarray, x, y) -> tuple[np.ndarray, np.ndarray]:
    """Image (x', y') of the points (x, y) (broadcast together) under the 3×3 homography ``H``."""
    x, y = np.broadcast_arrays(x, y)
    w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    return (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w, (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w


def _disk_kernel(R: float, sub: int = 4) -> np.ndarray:
    """Normalised uniform disk of radius ``R`` grid steps, anti-aliased by ``sub × sub`` sub-samples
    per cell (only the rim cells are sub-sampled: the others are wholly in or out)."""
    k = math.ceil(R) + 1
    ky, kx = np.mgrid[-k:k + 1, -k:k + 1].astype(float)
    d = np.hypot(kx, ky)
    acc = np.where(d < R, float(sub * sub), 0.0)
    rim = np.abs(d - R) < 1.0  # a cell's sub-samples lie within 0.75·√2 < 1 of its centre
    xr, yr = kx[rim], ky[rim]
    cnt = np.zeros(xr.shape)
    for a in range(sub):
        for b in range(sub):
            cnt += np.hypot(xr + (a + 0.5) / sub - 0.5, yr + (b + 0.5) / sub - 0.5) < R
    acc[rim] = cnt
    return acc / acc.sum()
