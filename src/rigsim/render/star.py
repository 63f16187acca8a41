"""Star-field frames: truth → expected photons (analytic or Mitsuba) → detector DN.

Rendering only: nothing here extracts, identifies or estimates; each :class:`~rigsim.render.frame.Frame`
carries the 16-bit frame and the :class:`~rigsim.truth.star.StarField` it was rendered from.
Two renderers: :func:`render_stars` (pixel-integrated Gaussians in numpy, exact) and
:class:`MitsubaStarRenderer` (a sky patch with the PSF baked in, seen through the distorted
``rigsim_pinhole`` sensor; Mitsuba imported lazily). Both are described, with their measured
agreement, in docs/star_calibration.md ("Star-field frames").
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.special import erf

from rigsim.render.budget import check_memory
from rigsim.render.frame import Frame, digitise
from rigsim.render.scene import Element, PinholeSensor, Scene
from rigsim.render.star_effects import star_frame_effects, traced_margin_px, traced_star_psfs
from rigsim.truth.star import StarSky

__all__ = ['render_frame', 'render_sequence', 'frame_seed', 'render_stars', 'render_stars_psf', 'pixel_fractions_1d',
           'MitsubaStarRenderer']

def _window_seed(seed: int, k: int) -> int:
    """The sampler seed of window k of a frame (the earlier seed·100003 + k while it fits 32 bits)."""
    from rigsim.render.scene import mitsuba_seed

    x = int(seed) * 100003 + int(k)
    return x if 0 <= x < 2**32 else mitsuba_seed(seed, k)


def frame_seed(seed: int, k: int) -> int:
    """Detector-noise seed of frame k of a run with ``seed`` (independent streams per frame)."""
    return int(np.random.SeedSequence([int(seed), 0x57A4, int(k)]).generate_state(1, np.uint32)[0])


def render_frame(sky: StarSky, R_cam_from_icrs, *, seed: int, index: int = 0, time_s: float = 0.0,
                 omega_cam_rad_s=None, substeps: int = 1, renderer: str = "analytic",
                 noiseless: bool = False, keep_photons: bool = False, mitsuba=None, fits_header: bool = True) -> Frame:
    """One frame (its truth: the :class:`~rigsim.truth.star.StarField`). ``renderer``: 'analytic'
    (default) or 'mitsuba' (pass a :class:`MitsubaStarRenderer` as ``mitsuba``). ``fits_header``: also
    fit the frame's FITS cards (``extra["fits_header"]``, a TAN-SIP WCS fit) for writing it as a file."""
    s = sky.rig.sensor
    sigma = s.psf_sigma_px
    traced = sky.rig.effects.traced_psf.enabled
    margin = -math.ceil(5.0 * sigma)  # stars just off the detector still put their wings on it
    if traced:
        margin = min(margin, -traced_margin_px(sky.rig))
    truth = sky.field(R_cam_from_icrs, omega_cam_rad_s=omega_cam_rad_s, substeps=substeps, margin_px=margin)
    traced_truth = None
    if traced:
        if renderer != "analytic":
            raise ValueError("effects.traced_psf: the traced PSF is rendered by the analytic renderer only "
                             f"(renderer = {renderer!r})")
        psfs, shift, table = traced_star_psfs(sky.rig, truth)
        photons = render_stars_psf(truth.uv_substeps, truth.photons, truth.shape_hw, psfs, table.radius_px,
                                   table.oversample, background=truth.background_photons_per_px)
        settings = {"renderer": "analytic", "psf": "traced lens (effects.traced_psf)", "substeps": int(substeps),
                    "psf_radius_px": table.radius_px, "psf_oversample": table.oversample}
        traced_truth = {"centroid_shift_px": shift.tolist(),
                        "truth_uv": "uv is the geometric image point (the rig's pinhole + Brown camera); the "
                                    "rendered PSF's centroid lies at uv + centroid_shift_px"}
    elif renderer == "analytic":
        photons = render_stars(truth.uv_substeps, truth.photons, truth.shape_hw, sigma,
                               background=truth.background_photons_per_px)
        settings = {"renderer": "analytic", "psf": "pixel-integrated gaussian", "sigma_px": sigma,
                    "substeps": int(substeps)}
    elif renderer == "mitsuba":
        if mitsuba is None:
            raise ValueError("renderer='mitsuba' needs a MitsubaStarRenderer (mitsuba=...)")
        photons = mitsuba.render(truth, seed=seed)
        settings = {"renderer": "mitsuba", **mitsuba.settings()}
    else:
        raise ValueError(f"renderer = {renderer!r}: allowed 'analytic' or 'mitsuba'")
    fx = star_frame_effects(sky, seed=int(seed), noiseless=noiseless)
    if fx.photons is not None:
        photons = photons + fx.photons
    if fx.stars_uv is not None and len(fx.stars_uv):  # stars beyond the catalogue, with the catalogue stars' PSF
        photons = photons + render_stars(fx.stars_uv, fx.stars_photons, truth.shape_hw, sigma)
    if fx.illumination is not None:
        photons = photons * fx.illumination
    if traced_truth is not None:
        fx.truth["traced_psf"] = traced_truth
    truth_dict = truth.as_dict()
    if fx.illumination is not None and len(truth):  # the share of each star's light that reaches the detector
        H, W = truth.shape_hw
        iu = np.clip(np.rint(truth.uv[:, 0]).astype(int), 0, W - 1)
        iv = np.clip(np.rint(truth.uv[:, 1]).astype(int), 0, H - 1)
        fx.truth["vignetting"]["star_illumination"] = fx.illumination[iv, iu].tolist()
    if fx.truth:
        truth_dict["effects"] = fx.truth
    fr = digitise(photons, s.detector, seed=int(seed), noiseless=noiseless, truth=truth_dict, truth_object=truth,
                  render=settings, index=int(index), time_s=float(time_s), added_e=fx.electrons)
    if fits_header:
        fr.extra["fits_header"] = star_fits_cards(sky.rig, truth.R_cam_from_icrs, seed=int(seed), time_s=float(time_s))
    if not keep_photons:
        fr.photons = None
    return fr


def star_fits_cards(rig, R_cam_from_icrs, *, seed: int, time_s: float = 0.0, camera=None, wcs_name: str = "") -> list:
    """The FITS header cards of a star frame of ``rig`` at an attitude: the WCS (TAN-SIP) of ``camera`` (default the
    true camera), the exposure, gain, observation time (the rig's epoch plus ``time_s``), units, seed and detector
    model; ``wcs_name`` (WCSNAME) says where the WCS comes from."""
    import astropy.units as u
    from astropy.time import Time

    from rigsim.optics.wcs import star_frame_header

    s = rig.sensor
    d = s.detector
    t = Time(rig.sky.epoch_year, format="jyear", scale="tt") + time_s * u.s
    model = f"QE {d.quantum_efficiency:g} K {d.gain_dn_per_e:g}/e read {d.read_noise_e:g}e {d.adc_bits}b"
    if d.container_bits is not None:
        model += f" in {d.container_bits}b"
    cards = [list(c) for c in star_frame_header(s.camera() if camera is None else camera, R_cam_from_icrs,
                                                 exposure_s=d.exposure_s, gain_e_per_dn=1.0 / (d.gain_dn_per_e * d.code_step_dn),
                                                 date_obs=t.utc.isot, seed=seed, detector=model)]
    if wcs_name:
        cards.append(["WCSNAME", wcs_name[:68], "where the WCS comes from"])
    return cards


def render_sequence(sky: StarSky, seq, *, seed: int, renderer: str = "analytic", noiseless: bool = False,
                    keep_photons: bool = False, mitsuba=None, substeps: int | None = None, progress=None,
                    fits_header: bool = True):
    """Render every frame of an :class:`rigsim.truth.star.AttitudeSequence` (a generator); ``fits_header`` as in
    :func:`render_frame`."""
    K = sky.rig.sequence.smear_substeps if substeps is None else int(substeps)
    for k in range(len(seq)):
        fr = render_frame(sky, seq.R_cam_from_icrs[k], seed=frame_seed(seed, k), index=k,
                          time_s=float(seq.times_s[k]), omega_cam_rad_s=seq.omega_cam_rad_s[k], substeps=K,
                          renderer=renderer, noiseless=noiseless, keep_photons=keep_photons, mitsuba=mitsuba,
                          fits_header=fits_header)
        if progress is not None:
            progress.update(1)
        yield fr

# ------------------------------------------------------------------------------------------ (from analytic.py)
def pixel_fractions_1d(centres: np.ndarray, lo: np.ndarray, n: int, sigma_px: float) -> np.ndarray:
    """(M, n) fractions of a unit Gaussian (centre c) in pixels lo, lo+1, …, lo+n−1."""
    edges = lo[:, None] + np.arange(n + 1)[None, :] - 0.5
    c = erf((edges - centres[:, None]) * (1.0 / (math.sqrt(2.0) * sigma_px)))
    return 0.5 * np.diff(c, axis=1)


def render_stars(uv, photons, shape_hw: tuple[int, int], sigma_px: float, *, background: float = 0.0,
                 nsigma: float = 5.0) -> np.ndarray:
    """Expected photons per pixel of a star field.

    ``uv``: (N, 2) or (N, K, 2) centres (K sub-exposures sharing each star's photons equally);
    ``photons``: (N,) photons per star over the exposure; ``background``: photons per pixel.
    """
    H, W = int(shape_hw[0]), int(shape_hw[1])
    if not (sigma_px > 0 and math.isfinite(sigma_px)):
        raise ValueError(f"sigma_px = {sigma_px!r}: must be a finite number > 0")
    uv = np.asarray(uv, dtype=float)
    if uv.ndim == 2:
        uv = uv[:, None, :]
    ph = np.asarray(photons, dtype=float)
    if uv.ndim != 3 or uv.shape[2] != 2 or ph.shape != uv.shape[:1]:
        raise ValueError(f"uv must be (N, 2) or (N, K, 2) and photons (N,), got {uv.shape} and {ph.shape}")
    N, K = uv.shape[:2]
    img = np.full(H * W, float(background))
    if N == 0:
        return img.reshape(H, W)
    uv = uv.reshape(N * K, 2)
    ph = np.repeat(ph / K, K)
    ok = np.all(np.isfinite(uv), axis=1) & (ph > 0)
    uv, ph = uv[ok], ph[ok]
    r = int(math.ceil(nsigma * sigma_px))
    n = 2 * r + 1
    lo = np.floor(uv + 0.5).astype(np.int64) - r  # (M, 2): first pixel of each star's box
    fu = pixel_fractions_1d(uv[:, 0], lo[:, 0], n, sigma_px)
    fv = pixel_fractions_1d(uv[:, 1], lo[:, 1], n, sigma_px)
    vals = (ph[:, None, None] * fv[:, :, None] * fu[:, None, :]).ravel()
    cols = lo[:, 0, None, None] + np.arange(n)[None, None, :]
    rows = lo[:, 1, None, None] + np.arange(n)[None, :, None]
    cols, rows = np.broadcast_arrays(cols, rows)
    cols, rows = cols.ravel(), rows.ravel()
    inside = (cols >= 0) & (cols < W) & (rows >= 0) & (rows < H)
    if not inside.all():
        vals, cols, rows = vals[inside], cols[inside], rows[inside]
    img += np.bincount(rows * W + cols, weights=vals, minlength=H * W)
    return img.reshape(H, W)

def render_stars_psf(uv, photons, shape_hw: tuple[int, int], psfs, radius_px: int, oversample: int, *,
                     background: float = 0.0) -> np.ndarray:
    """Expected photons per pixel of stars with their own tabulated PSFs: ``psfs`` (N, n, n) on bins of
    1/``oversample`` px (n = 2·radius·oversample, bin k's centre at (k + ½)/oversample − radius from the
    star's ``uv``), constant within a bin and integrated exactly over each pixel. ``uv`` (N, 2) or
    (N, K, 2) as in :func:`render_stars`."""
    H, W = int(shape_hw[0]), int(shape_hw[1])
    uv = np.asarray(uv, dtype=float)
    if uv.ndim == 2:
        uv = uv[:, None, :]
    ph = np.asarray(photons, dtype=float)
    img = np.full(H * W, float(background))
    ok = np.all(np.isfinite(uv), axis=(1, 2)) & (ph > 0)
    if not ok.any():
        return img.reshape(H, W)
    uv, ph, P = uv[ok], ph[ok], np.asarray(psfs, dtype=float)[ok]
    n = P.shape[-1]
    R, os_ = int(radius_px), int(oversample)
    spread = math.ceil(np.abs(uv - uv.mean(axis=1, keepdims=True)).max())
    m = 2 * (R + spread) + 2                                      # pixels of each star's window, per axis
    lo = np.floor(uv.mean(axis=1) + 0.5).astype(np.int64) - R - spread - 1   # (N, 2) first pixel
    e = np.arange(n + 1) / os_ - R                                 # bin edges from the star's position

    def overlap(c, lo_ax):  # (N, K, m, n): share of each bin in each pixel
        pix = lo_ax[:, None, None, None] + np.arange(m)[None, None, :, None]
        a = c[:, :, None, None] + e[None, None, None, :-1]
        b = c[:, :, None, None] + e[None, None, None, 1:]
        return np.clip(np.minimum(pix + 0.5, b) - np.maximum(pix - 0.5, a), 0.0, None) * os_

    Au, Av = overlap(uv[:, :, 0], lo[:, 0]), overlap(uv[:, :, 1], lo[:, 1])
    win = (Av @ P[:, None] @ np.swapaxes(Au, 2, 3)).mean(axis=1) * ph[:, None, None]   # (N, m, m) rows v
    cols = lo[:, 0, None, None] + np.arange(m)[None, None, :]
    rows = lo[:, 1, None, None] + np.arange(m)[None, :, None]
    cols, rows = np.broadcast_arrays(cols, rows)
    vals, cols, rows = win.ravel(), cols.ravel(), rows.ravel()
    inside = (cols >= 0) & (cols < W) & (rows >= 0) & (rows < H)
    img += np.bincount(rows[inside] * W + cols[inside], weights=vals[inside], minlength=H * W)
    return img.reshape(H, W)

# ------------------------------------------------------------------------------------------ (from render_mitsuba.py)
class MitsubaStarRenderer:
    def __init__(self, sensor, *, oversample: int = 2, window_px: int | None = None, spp: int = 256,
                 mode: str = "windows", distance_mm: float = 1000.0, margin_px: int | None = None):
        """``window_px`` (each star's rendered window) defaults to the PSF's: 2·⌈5σ⌉ + 4, at least 16;
        ``margin_px`` (sky texture beyond the detector, for the wings of stars just off it) to ⌈5σ⌉ + 2,
        at least 12."""
        from rigsim.render.backend import ensure_variant
        from rigsim.render.plugins import register_sensors

        if mode not in ("windows", "full"):
            raise ValueError(f"mode = {mode!r}: allowed 'windows' or 'full'")
        if int(oversample) != oversample or not 1 <= oversample <= 8:
            raise ValueError(f"oversample = {oversample!r}: allowed integers 1..8")
        if spp < 1 or (spp & (spp - 1)) or (spp.bit_length() - 1) % 2:
            raise ValueError(f"spp = {spp!r}: must be a power of 4 (ldsampler), e.g. 64, 256, 1024")
        self.sensor = sensor
        self.sigma_px = sensor.psf_sigma_px
        need = 2 * math.ceil(5 * self.sigma_px) + 4
        window_px = max(16, need) if window_px is None else window_px
        margin_px = max(12, math.ceil(5 * self.sigma_px) + 2) if margin_px is None else margin_px
        if not 8 <= window_px <= 256:
            raise ValueError(f"window_px = {window_px!r}: allowed 8..256 (a PSF of σ = {self.sigma_px:.2f} px needs {need})")
        if window_px < 2 * math.ceil(5 * self.sigma_px) + 4:
            raise ValueError(f"window_px = {window_px} is too small for a PSF of σ = {self.sigma_px:.2f} px "
                             f"(need ≥ {2 * math.ceil(5 * self.sigma_px) + 4})")
        self.cam = sensor.camera()
        check_memory(sensor.resolution_px, "sensor.resolution_px")
        self.pcam = self.cam
        self.variant = ensure_variant()
        register_sensors()
        self.oversample = int(oversample)
        self.window_px = int(window_px)
        self.spp = int(spp)
        self.mode = mode
        self.D = float(distance_mm)
        W, H = self.cam.width, self.cam.height
        # undistorted bounding box of the detector (+ margin for PSF wings / off-detector stars)
        edge = np.concatenate([
            np.stack([np.linspace(-0.5, W - 0.5, 65), np.full(65, -0.5)], 1),
            np.stack([np.linspace(-0.5, W - 0.5, 65), np.full(65, H - 0.5)], 1),
            np.stack([np.full(65, -0.5), np.linspace(-0.5, H - 0.5, 65)], 1),
            np.stack([np.full(65, W - 0.5), np.linspace(-0.5, H - 0.5, 65)], 1)])
        xn = self.cam.pixel_to_normalized(edge)
        Uu = xn[:, 0] * self.cam.fx + self.cam.cx
        Vu = xn[:, 1] * self.cam.fy + self.cam.cy
        self.U0 = math.floor(Uu.min()) - margin_px
        self.V0 = math.floor(Vu.min()) - margin_px
        self.tex_w = (math.ceil(Uu.max()) + margin_px - self.U0) * self.oversample
        self.tex_h = (math.ceil(Vu.max()) + margin_px - self.V0) * self.oversample
        self._build()

    # ------------------------------------------------------------------ scene
    def _patch_matrix(self) -> np.ndarray:
        """Rectangle [-1,1]² → world; texel column i ↦ +X, row 0 (after the flip) ↦ smallest Y."""
        s = 1.0 / self.oversample
        U1 = self.U0 + self.tex_w * s
        V1 = self.V0 + self.tex_h * s
        cam = self.cam
        X0, X1 = (self.U0 - cam.cx) / cam.fx * self.D, (U1 - cam.cx) / cam.fx * self.D
        Y0, Y1 = (self.V0 - cam.cy) / cam.fy * self.D, (V1 - cam.cy) / cam.fy * self.D
        M = np.eye(4)
        # 180° about x (keeps det > 0) so that the emitting side (+z local) faces the camera
        M[0, 0] = (X1 - X0) / 2.0
        M[1, 1] = -(Y1 - Y0) / 2.0
        M[2, 2] = -1.0
        M[:3, 3] = [(X0 + X1) / 2.0, (Y0 + Y1) / 2.0, self.D]
        return M

    def _build(self):
        """Elements: the distorted pinhole's window (moved to each star by ``window_origin``) and the
        sky patch whose radiance bitmap is the frame's ``texture``."""
        import mitsuba as mi

        cam = self.cam
        w = self.window_px if self.mode == "windows" else cam.width
        h = self.window_px if self.mode == "windows" else cam.height
        tex = mi.TensorXf(np.zeros((self.tex_h, self.tex_w, 1), dtype=np.float32))

        def upload(state) -> dict:
            if "texture" not in state:
                return {}
            data = np.ascontiguousarray(state["texture"][::-1, :, None], dtype=np.float32)
            return {"sky.emitter.radiance.data": mi.TensorXf(data)}

        sky = Element("sky", {"type": "rectangle", "to_world": mi.ScalarTransform4f(self._patch_matrix()),
                              "emitter": {"type": "area", "radiance": {"type": "bitmap", "data": tex, "raw": True,
                                                                       "filter_type": "bilinear", "wrap_mode": "clamp"}}},
                      upload)
        sensor = PinholeSensor(cam, width=w, height=h, spp=self.spp, sampler="ldsampler", response="radiance")
        self.scene = Scene({"type": "path", "max_depth": 1}, [sensor, sky])

    # ------------------------------------------------------------------ bitmap
    def bake(self, truth) -> np.ndarray:
        """The sky bitmap (tex_h, tex_w) of a :class:`rigsim.truth.star.StarField`, rows from the top."""
        cam = self.cam
        uvs = truth.uv_substeps  # (N, K, 2) distorted
        N, K = uvs.shape[:2]
        tex = np.zeros((self.tex_h, self.tex_w))
        if N == 0:
            return tex
        xn = cam.pixel_to_normalized(uvs.reshape(-1, 2))
        a, b, c, d = self.pcam.distort_jacobian(xn[:, 0], xn[:, 1])
        detJ = a * d - b * c
        ok = np.all(np.isfinite(xn), axis=1) & (detJ > 0)
        U = xn[:, 0] * cam.fx + cam.cx
        V = xn[:, 1] * cam.fy + cam.cy
        amp = np.repeat(truth.photons / K, K) / np.where(ok, detJ, 1.0)
        sig_u = self.sigma_px / np.sqrt(np.where(ok, detJ, 1.0))
        os_ = self.oversample
        # texel (i, j) centre in undistorted px: U0 + (i + ½)/os
        ti = (U - self.U0) * os_ - 0.5
        tj = (V - self.V0) * os_ - 0.5
        r = int(math.ceil(6.0 * self.sigma_px * os_ / np.sqrt(detJ[ok].min() if ok.any() else 1.0))) + 1
        n = 2 * r + 1
        i0 = np.floor(ti).astype(np.int64) - r + 1
        j0 = np.floor(tj).astype(np.int64) - r + 1
        ar = np.arange(n)
        gi = np.exp(-0.5 * ((i0[:, None] + ar[None, :] - ti[:, None]) / (sig_u * os_)[:, None]) ** 2)
        gj = np.exp(-0.5 * ((j0[:, None] + ar[None, :] - tj[:, None]) / (sig_u * os_)[:, None]) ** 2)
        norm = amp * os_ * os_ / (2.0 * math.pi * (sig_u * os_) ** 2)  # texel value = photons per undistorted px²
        vals = (norm[:, None, None] * gj[:, :, None] * gi[:, None, :])[ok].ravel()
        cols = (i0[:, None, None] + ar[None, None, :] + 0 * ar[None, :, None])[ok].ravel()
        rows = (j0[:, None, None] + ar[None, :, None] + 0 * ar[None, None, :])[ok].ravel()
        inside = (cols >= 0) & (cols < self.tex_w) & (rows >= 0) & (rows < self.tex_h)
        tex += np.bincount(rows[inside] * self.tex_w + cols[inside], weights=vals[inside],
                           minlength=self.tex_w * self.tex_h).reshape(self.tex_h, self.tex_w)
        return tex

    # ------------------------------------------------------------------ render
    def render(self, truth, seed: int = 0) -> np.ndarray:
        """Expected photons per pixel (H, W) of one frame (background included)."""
        t0 = time.perf_counter()
        cam = self.cam
        self.scene.update({"texture": self.bake(truth)})
        frame = np.zeros((cam.height, cam.width))
        if self.mode == "full":
            frame = self.scene.render({"window_origin": (0, 0)}, seed=int(seed), spp=self.spp)
        else:
            Wp = self.window_px
            half = Wp // 2
            for k, (u, v) in enumerate(truth.uv):
                u0 = int(math.floor(u + 0.5)) - half
                v0 = int(math.floor(v + 0.5)) - half
                if u0 + Wp <= 0 or v0 + Wp <= 0 or u0 >= cam.width or v0 >= cam.height:
                    continue
                arr = self.scene.render({"window_origin": (u0, v0)}, seed=_window_seed(seed, k), spp=self.spp)
                a0, b0 = max(0, u0), max(0, v0)
                a1, b1 = min(cam.width, u0 + Wp), min(cam.height, v0 + Wp)
                frame[b0:b1, a0:a1] = arr[b0 - v0:b1 - v0, a0 - u0:a1 - u0]
        self.last_seconds = time.perf_counter() - t0
        return frame + truth.background_photons_per_px

    def settings(self) -> dict:
        return {"variant": self.variant, "mode": self.mode, "spp": self.spp, "window_px": self.window_px,
                "oversample": self.oversample, "texture_px": [self.tex_w, self.tex_h], "sampler": "ldsampler",
                "integrator": "path(max_depth=1)", "sensor": "rigsim_pinhole(response=radiance)",
                "sky_patch_distance_mm": self.D}
