"""Many sun spots in one Mitsuba launch: the sweep's renderer.

:class:`SunSpotBatch` renders the windows of many sun directions side by side on one film (a grid
of ``tile_px`` × ``tile_px`` tiles). The sensor ``rigsim_pinhole_tiles`` is the distorted pinhole
of :mod:`rigsim.render.plugins` with two per-tile parameters read by a gather on the tile index:
the window's place on the detector (tile pixel (i, j) is detector pixel (u0 + i, v0 + j)) and a
rotation camera → world that turns that tile's sun direction onto the world's +z axis, where the
one disk of :class:`~rigsim.render.cube_mirror.sun_sensor.SunSpotRenderer` sits. A uniform disk
seen from a pinhole depends only on the angle between the ray and the sun, so each tile sees
exactly the image the per-frame renderer draws in its window; only the sampler's random
numbers differ. Nothing but the disk emits, so pixels outside a tile are exactly zero.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from rigsim.optics.sun_disk import _unit
from rigsim.render.backend import ensure_variant
from rigsim.render.scene import Element, Scene, mitsuba_seed

__all__ = ["TILED_PLUGIN", "SunSpotBatch", "spot_tile_px", "tile_groups", "tile_px_for", "tile_rotations"]

TILED_PLUGIN = "rigsim_pinhole_tiles"
MAX_LAUNCH_SAMPLES = 2**28
"""Light paths per launch: a sweep with more is cut into equal launches of this many at most."""

_registered: set = set()


def _frames(sun_dirs) -> np.ndarray:
    """(K, 3, 3) rows (e1, e2, s) per sun direction: :func:`rigsim.optics.sun_disk._basis`, vectorised."""
    S = np.asarray(sun_dirs, dtype=np.float64).reshape(-1, 3)
    norm = np.linalg.norm(S, axis=1)
    if not np.all(np.isfinite(norm) & (norm > 0)):
        raise ValueError("sun directions must be finite non-zero 3-vectors")
    S = S / norm[:, None]
    a = np.where((np.abs(S[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    e1 = np.cross(S, a)
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    return np.stack([e1, np.cross(S, e1), S], axis=1)


def tile_rotations(sun_dirs: np.ndarray, axes: np.ndarray | None = None) -> np.ndarray:
    """(K, 3, 3) rotations camera → world with rows (e1, e2, s): each sun direction s goes to +z.
    ``axes``: per direction, a camera-frame direction across it that must go to world −x, the local
    x (φ = 0) of the disk's texture (a non-uniform disk's gradient)."""
    if axes is None:
        return _frames(sun_dirs)
    S = _frames(sun_dirs)[:, 2]
    A = np.asarray(axes, dtype=np.float64).reshape(-1, 3)
    A = A - np.einsum("ki,ki->k", A, S)[:, None] * S
    n = np.linalg.norm(A, axis=1)
    if not np.all(np.isfinite(n) & (n > 1e-9)):
        raise ValueError("axes must be finite directions across their sun directions")
    e1 = -A / n[:, None]
    return np.stack([e1, np.cross(S, e1), S], axis=1)


def spot_tile_px(camera, sun_dirs: np.ndarray, full_angle_rad: float, *, margin_px: float = 1.0,
                 minimum: int = 4) -> np.ndarray:
    """Per sun direction, the smallest even tile holding its spot with the projected rim at least
    ``margin_px`` inside the tile's edge, the tile centred as in
    :meth:`SunSpotRenderer.window_origin_for` (origin = rounded centre − tile // 2); 0 for a spot
    outside the camera model (the per-frame renderer draws nothing there either)."""
    S = np.asarray(sun_dirs, dtype=np.float64).reshape(-1, 3)
    if len(S) == 0:
        return np.zeros(0, dtype=int)
    psi = np.linspace(0.0, 2.0 * math.pi, 90, endpoint=False)
    h = full_angle_rad / 2.0
    B = _frames(S)  # rows e1, e2, s per direction
    ring = np.column_stack([math.sin(h) * np.cos(psi), math.sin(h) * np.sin(psi), np.full(len(psi), math.cos(h))])
    rims = np.einsum("pk,nkj->npj", ring, B)  # the rim of spot_outline, every direction at once
    uv, ok = camera.project_valid(rims.reshape(-1, 3))
    uv = uv.reshape(len(S), len(psi), 2)
    c, c_ok = camera.project_valid(S)
    valid = ok.reshape(len(S), len(psi)).all(axis=1) & c_ok
    rc = np.floor(np.where(valid[:, None], c, 0.0) + 0.5)
    uv = np.where(valid[:, None, None], uv, rc[:, None, :])
    half = np.maximum(rc - uv.min(axis=1) - 0.5, uv.max(axis=1) - rc + 0.5).max(axis=1) + margin_px
    return np.where(valid, np.maximum(int(minimum), 2 * np.ceil(half).astype(int)), 0)


def tile_px_for(camera, sun_dirs: np.ndarray, full_angle_rad: float, *, margin_px: float = 1.0,
                minimum: int = 4) -> int:
    """One tile for every spot of ``sun_dirs``: the largest of :func:`spot_tile_px`."""
    t = spot_tile_px(camera, sun_dirs, full_angle_rad, margin_px=margin_px, minimum=minimum)
    return int(t.max()) if len(t) and t.max() > 0 else int(minimum + minimum % 2)


def tile_groups(sizes: np.ndarray, max_groups: int = 3) -> list[tuple[int, np.ndarray]]:
    """Split spots needing tiles of ``sizes`` px into at most ``max_groups`` launches, each with one
    tile (its largest spot's), choosing the cuts that render the fewest pixels. Returns
    [(tile_px, indices)], smallest tile first; spots of size 0 (nothing to render) are in none."""
    sizes = np.asarray(sizes, dtype=int)
    levels = np.unique(sizes[sizes > 0])
    if len(levels) == 0:
        return []
    best = None
    from itertools import combinations

    for k in range(min(max_groups, len(levels))):
        for cuts in combinations(levels[:-1], k):
            tops = [*cuts, levels[-1]]
            lo = 0
            cost = 0
            for t in tops:
                cost += int(((sizes > lo) & (sizes <= t)).sum()) * t * t
                lo = t
            if best is None or cost < best[0]:
                best = (cost, tops)
    groups, lo = [], 0
    for t in best[1]:
        idx = np.flatnonzero((sizes > lo) & (sizes <= t))
        if len(idx):
            groups.append((int(t), idx))
        lo = t
    return groups


def _register() -> None:
    variant = ensure_variant()
    if variant in _registered:
        return
    import drjit as dr
    import mitsuba as mi

    from rigsim.render.plugins import register_sensors

    pinhole, _ = register_sensors()

    class TiledPinholeSensor(pinhole):
        """The distorted pinhole, one window and one camera rotation per film tile."""

        def __init__(self, props):
            # the cover glass (optics.cover_glass): ghost = "direct" (the direct image through the
            # glass) or "ghost" (its ghost alone); thickness over focal length in px (per unit of
            # 2 tan θ′), index, coating reflectance (< 0: Fresnel)
            self.ghost = str(props["ghost"]) if "ghost" in props else ""
            # a thick pinhole (optics.pinhole): mask thickness over diameter, < 0 for none
            self.vignette = float(props["vignette_ratio"]) if "vignette_ratio" in props else -1.0
            if self.ghost:
                self.g_tu, self.g_tv = float(props["ghost_tu"]), float(props["ghost_tv"])
                self.g_n, self.g_coat = float(props["ghost_n"]), float(props["ghost_coating"])
            self.tile_px = int(props["tile_px"])
            self.tiles_x = int(props["tiles_x"])
            self.n_tiles = int(props["n_tiles"])
            self.tiles = mi.Float(np.zeros(12 * self.n_tiles, dtype=np.float32))  # u0 v0 active R(9), per tile
            super().__init__(props)

        def traverse(self, cb):
            super().traverse(cb)
            cb.put("tiles", self.tiles, mi.ParamFlags.NonDifferentiable)

        def _update(self):
            super()._update()
            dr.make_opaque(self.tiles)

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            wav, wav_weight = self.sample_wavelengths(dr.zeros(mi.SurfaceInteraction3f), sample1, active)
            w, h = self._film_px
            fx, fy = sample2.x * w, sample2.y * h
            t = float(self.tile_px)
            tx, ty = dr.floor(fx / t), dr.floor(fy / t)
            k = dr.minimum(mi.UInt32(ty) * self.tiles_x + mi.UInt32(tx), self.n_tiles - 1) * 12

            def tile(i):
                return dr.gather(mi.Float, self.tiles, k + i)

            u = fx - tx * t + tile(0) - 0.5
            v = fy - ty * t + tile(1) - 0.5
            if self.ghost == "ghost":
                d, wt, valid = self._ghost_ray(u, v)
            elif self.ghost == "direct":
                d, wt, valid = self._pixel_ray(u, v)
                wt = wt * self._glass(d)[0]
            else:
                d, wt, valid = self._pixel_ray(u, v)
            if self.vignette >= 0.0:
                c = dr.minimum(self.vignette * dr.sqrt(dr.fma(d.x, d.x, d.y * d.y)) / d.z, 1.0)  # (k: the tile)
                wt = wt * (2.0 / dr.pi) * (dr.acos(c) - c * dr.sqrt(dr.maximum(1.0 - c * c, 0.0)))
            valid &= tile(2) > 0.5
            world = mi.Vector3f(dr.fma(tile(3), d.x, dr.fma(tile(4), d.y, tile(5) * d.z)),
                                dr.fma(tile(6), d.x, dr.fma(tile(7), d.y, tile(8) * d.z)),
                                dr.fma(tile(9), d.x, dr.fma(tile(10), d.y, tile(11) * d.z)))
            ray = mi.Ray3f(mi.Point3f(0.0, 0.0, 0.0), world, time, wav)
            return ray, wav_weight * dr.select(valid & active, wt, 0.0)

        def _glass(self, d):
            """(direct transmittance, ghost share, 2/√(n² − sin²θ)) of unit ray ``d`` through the glass."""
            n = self.g_n
            s2 = dr.fma(d.x, d.x, d.y * d.y)
            k = 2.0 * dr.rsqrt(dr.maximum(n * n - s2, 1e-12))
            if self.g_coat >= 0.0:
                rs = rp = mi.Float(self.g_coat)
            else:
                c = d.z
                ct = dr.sqrt(dr.maximum(1.0 - s2 / (n * n), 0.0))
                a = (c - n * ct) / (c + n * ct)
                b = (n * c - ct) / (n * c + ct)
                rs, rp = a * a, b * b
            ts, tp = 1.0 - rs, 1.0 - rp
            return 0.5 * (ts * ts + tp * tp), 0.5 * (ts * ts * rs * rs + tp * tp * rp * rp), k

        def _ghost_ray(self, u, v):
            """Pixel (u, v) sees in the ghost what the direct image shows at p, p + offset(p) = (u, v):
            Newton in the direct ray's undistorted coordinates x, G(x) = pixel(distort(x)) +
            2 (t_u x, t_v y)/√(n² + (n² − 1)|x|²) = (u, v); weighted by the ghost's share and
            det(∂p/∂x)/det(∂G/∂x) (the ghost image is stretched)."""
            n2 = self.g_n * self.g_n
            x, y = (u - self.cx) / self.fx, (v - self.cy) / self.fy
            for _ in range(6):
                xd, yd, a, b, d, r2 = self._distort(x, y)
                q = dr.fma(n2 - 1.0, r2, n2)
                iq = dr.rsqrt(q)
                iq3 = iq * iq * iq
                gu = dr.fma(self.fx, xd, self.cx) + 2.0 * self.g_tu * x * iq - u
                gv = dr.fma(self.fy, yd, self.cy) + 2.0 * self.g_tv * y * iq - v
                j11 = self.fx * a + 2.0 * self.g_tu * (q - (n2 - 1.0) * x * x) * iq3
                j12 = self.fx * b - 2.0 * self.g_tu * (n2 - 1.0) * x * y * iq3
                j21 = self.fy * b - 2.0 * self.g_tv * (n2 - 1.0) * x * y * iq3
                j22 = self.fy * d + 2.0 * self.g_tv * (q - (n2 - 1.0) * y * y) * iq3
                inv = dr.rcp(j11 * j22 - j12 * j21)
                x = x - (j22 * gu - j12 * gv) * inv
                y = y - (j11 * gv - j21 * gu) * inv
            xd, yd, a, b, d, r2 = self._distort(x, y)
            q = dr.fma(n2 - 1.0, r2, n2)
            iq = dr.rsqrt(q)
            iq3 = iq * iq * iq
            resid = (dr.abs(dr.fma(self.fx, xd, self.cx) + 2.0 * self.g_tu * x * iq - u)
                     + dr.abs(dr.fma(self.fy, yd, self.cy) + 2.0 * self.g_tv * y * iq - v))
            j11 = self.fx * a + 2.0 * self.g_tu * (q - (n2 - 1.0) * x * x) * iq3
            j12 = self.fx * b - 2.0 * self.g_tu * (n2 - 1.0) * x * y * iq3
            j21 = self.fy * b - 2.0 * self.g_tv * (n2 - 1.0) * x * y * iq3
            j22 = self.fy * d + 2.0 * self.g_tv * (q - (n2 - 1.0) * y * y) * iq3
            det_g = j11 * j22 - j12 * j21
            det_p = self.fx * self.fy * (a * d - b * b)
            dg = dr.normalize(mi.Vector3f(x, y, 1.0))
            _, ghost, _ = self._glass(dg)
            if self.response == "flux":
                ct2 = dg.z * dg.z
                w = ct2 * ct2 * self.fx * self.fy / det_g  # cos⁴θ / det(distortion) × det_p / det_g
            else:
                w = det_p / det_g
            valid = (r2 < self.r2_max) & (det_g > 0) & (det_p > 0) & (resid < 1e-3) & self._on_detector(u, v)
            return dg, w * ghost, valid

    mi.register_sensor(TILED_PLUGIN, lambda props: TiledPinholeSensor(props))
    _registered.add(variant)


class SunSpotBatch:
    """Render the windows of many sun directions with a :class:`SunSpotRenderer`'s disk, camera,
    sampler and response, ``tile_px`` wide, a grid of up to ``tiles_per_launch`` tiles per launch.

    ``render(sun_dirs, origins, seed)`` returns (K, tile_px, tile_px) expected photons; window k's
    pixel (i, j) is detector pixel ``origins[k] + (i, j)``. The scalar fallback variant renders
    window by window with the renderer itself."""

    def __init__(self, renderer, tile_px: int, tiles_per_launch: int, *, glass: str = "direct"):
        self.renderer = renderer
        self.tile_px = int(tile_px)
        if self.tile_px < 4:
            raise ValueError(f"tile_px = {tile_px!r}: must be >= 4")
        # with the cover glass: this batch draws the direct image through it ("direct") or the ghost
        # alone ("ghost", in its own launch: no sample shared). The ghost lies outside a spot's tight
        # tile: a direct batch returns whole readout windows and adds the ghost, drawn by a ghost
        # batch in window-sized tiles, to the spots whose ghost reaches their window.
        self.glass = glass
        # with the pinhole's diffraction: the tile is drawn at ``supersampling``× the resolution (the
        # same samples per pixel), convolved with the PSF into the readout window and binned
        self.diffraction = renderer.diffraction
        self.sub = renderer.supersampling if self.diffraction is not None else 1
        spread = renderer.ghost is not None or self.diffraction is not None
        self.out_px = max(self.tile_px, renderer.window_px) if spread else self.tile_px
        self._ghost_batches: dict[int, SunSpotBatch] = {}
        self.n_tiles = max(1, min(int(tiles_per_launch), MAX_LAUNCH_SAMPLES // (self.tile_px**2 * renderer.spp)))
        self.tiles_x = math.ceil(math.sqrt(self.n_tiles))
        self.tiles_y = math.ceil(self.n_tiles / self.tiles_x)
        self.variant = ensure_variant()
        self.batched = self.variant.startswith("llvm")
        r = renderer
        if r.tiled_only and not self.batched:
            raise ValueError("the cover glass's ghost and the pinhole's vignetting and diffraction need an llvm "
                             "variant of Mitsuba")
        self._scene = self._build(glass) if self.batched else r._build(self.tile_px, self.tile_px, r.spp)

    @property
    def samples_per_launch(self) -> int:
        return self.tiles_x * self.tiles_y * self.tile_px**2 * self.renderer.spp

    def _build(self, glass: str = "direct") -> Scene:
        """The tiled scene; with a cover glass, ``glass`` = "direct" (the direct image through it) or
        "ghost" (the ghost alone)."""
        import mitsuba as mi

        _register()
        r, cam, t = self.renderer, self.renderer.camera, self.tile_px
        m, spp = self.sub, r.spp // self.sub**2
        if m > 1:  # sub-pixel J = m i + j of pixel i: U = m u + (m − 1)/2
            cam = replace(cam, fx=cam.fx * m, fy=cam.fy * m, cx=cam.cx * m + (m - 1) / 2, cy=cam.cy * m + (m - 1) / 2,
                          width=cam.width * m, height=cam.height * m)
            t = t * m
        sensor = {
            "type": TILED_PLUGIN, "tile_px": t, "tiles_x": self.tiles_x, "n_tiles": self.n_tiles,
            "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy,
            "k1": cam.k1, "k2": cam.k2, "k3": cam.k3, "p1": cam.p1, "p2": cam.p2,
            "detector_width": cam.width, "detector_height": cam.height, "response": r.response,
            "film": {"type": "hdrfilm", "width": self.tiles_x * t, "height": self.tiles_y * t,
                     "rfilter": {"type": "box"}, "pixel_format": "luminance"},
            "sampler": {"type": r.sampler, "sample_count": spp},
        }
        if r.ghost is not None:
            g = r.ghost
            sensor.update({"ghost": glass, "ghost_tu": g.thickness_mm / g.focal_length_mm * cam.fx,
                           "ghost_tv": g.thickness_mm / g.focal_length_mm * cam.fy, "ghost_n": g.refractive_index,
                           "ghost_coating": -1.0 if g.coating_reflectance is None else g.coating_reflectance})
        if r.pinhole is not None:
            sensor["vignette_ratio"] = r.pinhole.ratio
        sun = {"type": "disk", "to_world": mi.ScalarTransform4f(r._disk_matrix(np.array([0.0, 0.0, 1.0]))),
               "emitter": r.emitter()}

        def set_tiles(state) -> dict:
            return {"sensor.tiles": mi.Float(state["tiles"])} if "tiles" in state else {}

        return Scene({"type": "path", "max_depth": 1}, [Element("sensor", sensor, set_tiles), Element("sun", sun)])

    def render(self, sun_dirs, origins, seed: int = 0, *, axes=None, scales=None) -> np.ndarray:
        """``axes`` (K, 3): per direction, the camera-frame direction of a non-uniform disk's
        gradient (needed when ``renderer.needs_axis``); ``scales`` (K,): the simulator's irradiance
        at each pose relative to its mean (spatial non-uniformity), multiplied into each tile.
        Returns (K, out_px, out_px): with the cover glass's ghost, whole readout windows centred
        where the tiles are."""
        sun_dirs = np.asarray(sun_dirs, dtype=np.float64).reshape(-1, 3)
        origins = np.asarray(origins, dtype=np.int64).reshape(-1, 2)
        K = len(sun_dirs)
        if self.renderer.needs_axis and axes is None:
            raise ValueError("the sun disk has a gradient (simulator_nonuniformity, angular): render needs its axes")
        out = self._render(sun_dirs, origins, seed, axes)
        if self.renderer.ghost is not None and self.glass == "direct":
            out = self._add_ghosts(out, sun_dirs, origins, seed, axes)
        if scales is not None:
            out *= np.asarray(scales, dtype=np.float64).reshape(K, 1, 1)
        return out

    def _add_ghosts(self, out, sun_dirs, origins, seed, axes) -> np.ndarray:
        """The direct tiles in readout windows, plus the ghost of each spot whose ghost reaches its
        window (offset within the window's half width plus the tile's)."""
        t, W = self.tile_px, self.out_px
        a = W // 2 - t // 2
        if out.shape[1] == W:  # already readout windows (the pinhole's diffraction)
            big = out
        else:
            big = np.zeros((len(out), W, W))
            big[:, a:a + t, a:a + t] = out
        cam = self.renderer.camera
        off = self.renderer.ghost.offset_px(sun_dirs, cam.fx, cam.fy)
        need = np.flatnonzero(np.all(np.abs(off) < W / 2 + t / 2 + 1, axis=1))
        if len(need):
            n = len(need)
            if n not in self._ghost_batches:
                self._ghost_batches[n] = SunSpotBatch(self.renderer, W, n, glass="ghost")
            big[need] += self._ghost_batches[n]._render(
                sun_dirs[need], origins[need] - a, mitsuba_seed(seed, 0x6057),
                None if axes is None else np.asarray(axes)[need])
        return big

    def _render(self, sun_dirs, origins, seed, axes) -> np.ndarray:
        K, t = len(sun_dirs), self.tile_px
        if self.diffraction is not None:
            self.window_fractions = np.ones(K)
        if not self.batched:
            def state(k, s, o):
                st = {"sun_dir": _unit(s), "window_origin": tuple(int(x) for x in o)}
                return st if axes is None else {**st, "axis": np.asarray(axes[k], dtype=np.float64)}

            return np.array([self._scene.render(state(k, s, o), seed=mitsuba_seed(seed, k), spp=self.renderer.spp)
                             for k, (s, o) in enumerate(zip(sun_dirs, origins))]).reshape(K, t, t)
        rot = tile_rotations(sun_dirs, axes)
        out = np.empty((K, t, t)) if self.diffraction is None else np.empty((K, self.out_px, self.out_px))
        for launch, a in enumerate(range(0, K, self.n_tiles)):
            b = min(K, a + self.n_tiles)
            data = np.zeros((self.n_tiles, 12))
            data[:b - a, 0:2] = origins[a:b]
            data[:b - a, 2] = 1.0
            data[:b - a, 3:] = rot[a:b].reshape(-1, 9)
            data[:b - a, 0:2] *= self.sub
            img = self._scene.render({"tiles": data.ravel().astype(np.float32)}, seed=mitsuba_seed(seed, launch),
                                     spp=self.renderer.spp // self.sub**2)
            T = t * self.sub
            grid = img.reshape(self.tiles_y, T, self.tiles_x, T).transpose(0, 2, 1, 3).reshape(-1, T, T)
            if self.diffraction is None:
                out[a:b] = grid[:b - a]
            else:
                for k in range(a, b):
                    out[k], self.window_fractions[k] = self._diffract(grid[k - a], sun_dirs[k])
        return out

    def _diffract(self, sub: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, float]:
        """The sub-pixel geometric tile ``sub`` placed in its readout window, convolved with the
        diffraction PSF at ``s``'s field angle (one PSF per spot: it is a few px wide) and binned to
        pixels. Returns the window and the share of the tile's light it keeps."""
        from scipy.signal import fftconvolve

        m, t, W, cam = self.sub, self.tile_px, self.out_px, self.renderer.camera
        a = (W // 2 - t // 2) * m
        win = np.zeros((W * m, W * m))
        win[a:a + t * m, a:a + t * m] = sub
        K = self.diffraction.kernel(s, cam.fx, cam.fy, W / 2, 1.0 / m)
        conv = fftconvolve(win, K, mode="same")
        out = conv.reshape(W, m, W, m).mean(axis=(1, 3))
        total = sub.sum() / m**2
        return out, float(out.sum() / total) if total > 0 else 1.0
