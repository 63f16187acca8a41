"""Seed 003: Mitsuba scene of one camera's laser loop and the CMOS ROI frames it produces.

One scene per (camera, detector) path, light-traced (``ptracer``: emitter → lens → facet → lens →
detector is a caustic path, which ``path`` cannot render):

* ``laser``    — a ``directionalarea`` disk (the transceiver's emitting core, radius
  ``laser.core_radius_um``) 5 mm in front of the focal plane at the reference point, emitting along
  the optical axis (telecentric). Its BSDF is ``null``: the returning light passes through it (in
  the real transceiver a beam splitter separates them). The spot on the CMOS is the core's image.
* ``lens``     — the camera, an *ideal thin lens* (Python BSDF ``rigsim_ideal_lens``: a ray crossing
  the lens plane at r from the centre C changes its transverse slope by −r/f; exact, in-focus
  imaging of directions onto the focal plane). The camera's real three-mirror optics is replaced by
  this ideal model on purpose: the paper's equations assume a distortion-free camera, and an ideal
  lens makes the rendered truth exact (docs/boresight.md, "Rendering").
* ``facet``    — the prism facet: Python BSDF ``rigsim_normal_mirror`` (a perfect mirror about a
  given normal) on a small carrier rectangle perpendicular to the world z axis.
* ``detector`` — a Lambertian rectangle covering the CMOS in the focal plane.
* ``sensor``   — rigsim's telecentric sensor 2 mm in front of the detector, looking at it, whose
  film is the ROI (``window_px``²) of the CMOS; its v axis is mirrored (the sensor looks at the
  detector's face), which the renderer undoes.

Float32 (docs/boresight.md, "Rendering precision"): 0.02 px at F = 6 m is 3e-8 rad, at the
resolution of float32. So the world frame has the OTA axes (every carrier rectangle is world-
aligned: Mitsuba's local frames are then exact); its origin is the pencil's crossing of the lens
plane, chosen so that the lens centre C is exactly representable; the lens carrier is a small patch
there (hit points precise to 1e-6 mm); the facet normal is passed as a vector, and the truth uses
the float32 values of every rendered parameter. Per frame only the facet normal, the lens (Δf) and
the seed change, through ``mi.traverse`` (no recompilation).

``rig.effects`` (docs/effects-boresight.md), each changing the scene only when enabled: ``gaussian_beam``
(the emitter becomes a patch whose radiance is the Gaussian irradiance), ``prism_glass`` (a
``dielectric`` entrance face in front of each facet, moved per frame with the facet; depth 12 for the
ghosts) and ``objective_aberrations`` (the lens becomes ``rigsim_aberrated_lens``). The truth follows
each (Gaussian ray origins, the exact Snell/Fresnel trace, the Seidel closed forms).
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from rigsim.errors import GeometryWarning
from rigsim.optics.gaussian_beam import beam_radius_mm, gaussian_irradiance, sample_gaussian_disk
from rigsim.optics.line_camera import CameraGeometry, facet_normals_ota, loop_trace
from rigsim.optics.objective_aberrations import centroid_shift_mm, tangential_variance_mm2
from rigsim.optics.prism_glass import GlassFacet, glass_facet
from rigsim.render.aberrated_lens import ABERRATED_LENS_PLUGIN, register_aberrated_lens
from rigsim.render.backend import ensure_variant
from rigsim.render.frame import Frame, digitise
from rigsim.render.plugins import LENS_PLUGIN, MIRROR_PLUGIN, register_plugins
from rigsim.render.scene import Scene
from rigsim.rig.boresight import BoresightRig

__all__ = ["LoopRenderer", "register_plugins", "trace_scene_rays", "GeometryWarning",
           "LENS_PLUGIN", "MIRROR_PLUGIN"]

LASER_STANDOFF_MM = 5.0     # emitter disk in front of the focal plane (telecentric rays: no effect)
SENSOR_STANDOFF_MM = 2.0    # > Mitsuba's ray offset at 6 m (0.54 mm), < LASER_STANDOFF_MM
LENS_PATCH_HALF_MM = 20.0
FACET_HALF_MM = 25.0
TRUTH_CHUNK = 32768         # rays per pass of the truth trace (its arrays stay in cache)
MAX_DEPTH = 6               # emitter, lens, facet, lens, (laser disk, null), detector
MAX_DEPTH_GLASS = 12        # + the prism glass: entrance face twice, the second ghost's two more bounces
GLASS_PATHS = ("main", "ghost1", "ghost2")
BEAM_BITMAP_PX = 256        # the Gaussian emitter's radiance bitmap (bilinear): ~0.02 w per texel


def _f32(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float32).astype(np.float64)


def trace_scene_rays(src_xy: np.ndarray, src_z: float, C: np.ndarray, f_lens: float, N: np.ndarray,
                     facet_point: np.ndarray, z_det: float) -> np.ndarray:
    """Exact float64 trace of telecentric rays (+z) from source points (n, 2) at height ``src_z``
    through an ideal thin lens in the plane z = C_z (centre C, focal ``f_lens``), a plane mirror
    (normal N through ``facet_point``) and back through the lens to the plane z = ``z_det``.
    Returns landing points (n, 2). World frame of the scene (OTA axes)."""
    x = np.asarray(src_xy, float)
    return np.stack(_trace_xy(x[:, 0], x[:, 1], C, f_lens, N, facet_point, z_det), axis=1)


def _trace_xy(hx, hy, C, f_lens, N, facet_point, z_det):
    """:func:`trace_scene_rays` on coordinate arrays (one pass per component, no (n, 3) temporaries)."""
    Cx, Cy, Cz = (float(c) for c in C)
    Nx, Ny, Nz = (float(c) for c in N)
    # source -> lens plane (telecentric: straight up), slope form (qx, qy, 1), normalised
    dx, dy = -(hx - Cx) / f_lens, -(hy - Cy) / f_lens
    inv = 1.0 / np.sqrt(dx * dx + dy * dy + 1.0)
    dx, dy, dz = dx * inv, dy * inv, inv
    dN = dx * Nx + dy * Ny + dz * Nz
    t = ((facet_point[0] - hx) * Nx + (facet_point[1] - hy) * Ny + (facet_point[2] - Cz) * Nz) / dN
    px, py, pz = hx + t * dx, hy + t * dy, Cz + t * dz
    rx, ry, rz = dx - 2.0 * dN * Nx, dy - 2.0 * dN * Ny, dz - 2.0 * dN * Nz
    t2 = (Cz - pz) / rz
    h2x, h2y = px + t2 * rx, py + t2 * ry
    arz = np.abs(rz)
    qx = rx / arz - (h2x - Cx) / f_lens              # slope per unit |z| after the lens
    qy = ry / arz - (h2y - Cy) / f_lens
    return h2x + (Cz - z_det) * qx, h2y + (Cz - z_det) * qy


def _trace_glass(hx, hy, C, f_lens, glass: GlassFacet, z_det, path: str):
    """The trace of :func:`_trace_xy` with the facet a glass element (``path``: "main", "ghost1" or
    "ghost2" of :meth:`~rigsim.optics.prism_glass.GlassFacet.paths`): landing (x, y) and the power share."""
    Cz = float(C[2])
    dx, dy = -(hx - C[0]) / f_lens, -(hy - C[1]) / f_lens
    d = np.stack([dx, dy, np.ones_like(dx)], axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    p = np.stack([hx, hy, np.full_like(hx, Cz)], axis=-1)
    q, r, frac = glass.paths(p, d, only="main" if path == "main" else None)[path]
    t2 = (Cz - q[:, 2]) / r[:, 2]
    h2x, h2y = q[:, 0] + t2 * r[:, 0], q[:, 1] + t2 * r[:, 1]
    arz = np.abs(r[:, 2])
    qx = r[:, 0] / arz - (h2x - C[0]) / f_lens
    qy = r[:, 1] / arz - (h2y - C[1]) / f_lens
    return h2x + (Cz - z_det) * qx, h2y + (Cz - z_det) * qy, np.broadcast_to(frac, hx.shape)


class LoopRenderer:
    """Renders the ROI of one CMOS (``detector`` 0 = M1, 1 = M2) of one camera.

    ``window_px``: ROI size; ``roi_origin``: fixed ROI (default: centred on the reference spot;
    pass ``follow=True`` to centre the ROI on the exact spot of every frame instead).
    """

    def __init__(self, rig: BoresightRig, camera: int | str = 0, detector: int = 0, *, window_px: int | None = None,
                 spp: int | None = None, roi_origin=None, follow: bool = False, sampler: str = "independent",
                 truth_rays: int = 400_000, deterministic: bool = True):
        register_plugins()
        import mitsuba as mi

        # the ptracer splats with float32 atomic adds whose order varies between threads: one Dr.Jit thread
        # makes a frame bit-identical for a seed whatever the machine's or the dataset's worker count
        self.deterministic = bool(deterministic)
        cams = rig.cameras
        self.cam_index = camera if isinstance(camera, int) else [c.name for c in cams].index(camera)
        if not 0 <= self.cam_index < len(cams):
            raise ValueError(f"camera = {camera!r}: this rig has {len(cams)} cameras")
        if detector not in (0, 1):
            raise ValueError(f"detector = {detector!r}: 0 (M1) or 1 (M2)")
        self.rig = rig
        self.j = detector
        self.geom = CameraGeometry.from_rig(cams[self.cam_index])
        self.window_px = int(window_px or rig.orbit.window_px)
        self.spp = int(spp or rig.orbit.spp)
        if not 8 <= self.window_px <= 512:
            raise ValueError(f"window_px = {self.window_px}: allowed 8..512")
        if self.spp < 1:
            raise ValueError(f"spp = {self.spp}: must be >= 1")
        self.follow = bool(follow)
        self.sampler = sampler
        self.truth_rays = int(truth_rays)
        self.variant = ensure_variant()
        g, j = self.geom, self.j
        self.core_radius_mm = rig.laser.core_radius_um * 1e-3
        eff = rig.effects
        self.beam = eff.gaussian_beam if eff.gaussian_beam.enabled else None
        self.glass_cfg = eff.prism_glass if eff.prism_glass.enabled else None
        self.aberr = eff.objective_aberrations if eff.objective_aberrations.enabled else None
        if self.aberr is not None:
            register_aberrated_lens()
        if self.beam is not None:   # the irradiance in the plane conjugate to the CMOS, w(z) from the waist
            b = self.beam
            self.beam_radius_mm = beam_radius_mm(b.waist_radius_um * 1e-3, b.wavelength_nm, b.m_squared, b.waist_offset_mm)
            self.emit_radius_mm = b.truncation * self.beam_radius_mm
        else:
            self.emit_radius_mm = self.core_radius_mm
        e = g.emitter_mm[j]
        # world = OTA + C_W, with the lens centre C_W exactly representable in float32
        self.C_W = _f32([-e[0], -e[1], 0.0])
        c, s = math.cos(g.tilt_rad[j]), math.sin(g.tilt_rad[j])
        self.u_axis = np.array([c, s, 0.0])
        self.v_axis = np.array([-s, c, 0.0])
        self.laser_W = _f32(np.array([e[0], e[1], -g.F + LASER_STANDOFF_MM]) + self.C_W)
        self.det_centre_W = np.array([g.centers_mm[j, 0], g.centers_mm[j, 1], -g.F]) + self.C_W
        self.f0 = facet_normals_ota(g)[j]
        D = g.facet_distance_mm
        u_out = -self.f0
        self.facet_point_W = _f32(np.array([e[0], e[1], 0.0]) + D / u_out[2] * u_out + self.C_W)
        self.mirror0 = self.f0   # the reflecting face's normal at the reference (OTA = world axes)
        self.glass0 = None
        if self.glass_cfg is not None:
            gc = self.glass_cfg
            self.glass0 = glass_facet(u_out, self.facet_point_W, n=gc.refractive_index, thickness_mm=gc.thickness_mm,
                                      wedge_rad=math.radians(gc.wedge_arcsec / 3600.0),
                                      wedge_azimuth_rad=math.radians(gc.wedge_azimuth_deg))
            self.mirror0 = self.glass0.mirror
            self.front_point_W = _f32(self.glass0.front_point)
        # sensor: origin near the detector centre, axes (u, -v, -z): looks at the detector's face
        self.T_s = _f32(self.det_centre_W + SENSOR_STANDOFF_MM * np.array([0, 0, 1.0]))
        Q = self.T_s - SENSOR_STANDOFF_MM * np.array([0, 0, 1.0])
        self.u_T, self.v_T = self._uv_of_world(Q)
        self.ref_uv = g.reference_uv[j]
        if roi_origin is None:  # the nominal ROI: the window centred on the design reference spot
            roi_origin = g.roi_origin(j, self.window_px)
        self.roi_origin = (int(roi_origin[0]), int(roi_origin[1]))
        # the render loop's elements: per frame the facet's normal and the lens (Δf) follow the
        # camera state, and the sensor's window moves to the ROI (rigsim.render.scene)
        updates = {"facet": self._facet_update, "lens": self._lens_update, "sensor": self._sensor_update}
        if self.glass0 is not None:
            updates["prism_front"] = self._front_update
        self._scene = Scene.from_dict(self._scene_dict(), updates)
        M = np.eye(4)
        M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = self.u_axis, -self.v_axis, [0, 0, -1.0], self.T_s
        self._scene.params["sensor.to_world"] = mi.Transform4f(M.astype(np.float32))
        self._scene.params.update()
        self.photons_per_unit = None
        self.det_cfg = rig.detector.model_copy(update={"sensor_seed": rig.detector.sensor_seed + 97 * self.cam_index + 13 * j})

    # -- geometry ------------------------------------------------------------------------------
    def _uv_of_world(self, pW) -> tuple[float, float]:
        g = self.geom
        dpos = np.asarray(pW, float) - self.det_centre_W
        return (float(dpos @ self.u_axis / g.pitch_mm + g.cx), float(dpos @ self.v_axis / g.pitch_mm + g.cy))

    def _scene_dict(self) -> dict:
        import mitsuba as mi

        g = self.geom
        T = mi.ScalarTransform4f

        def M(R, t):
            A = np.eye(4)
            A[:3, :3] = R
            A[:3, 3] = t
            return T(A.tolist())

        W = self.window_px
        rb = self.core_radius_mm
        lens_bsdf = {"type": LENS_PLUGIN, "focal_length": g.F, "centre": self.C_W.tolist()}
        if self.aberr is not None:   # the objective's Seidel wavefront at this CMOS's field point
            lens_bsdf.update(self._aberration_props(), type=ABERRATED_LENS_PLUGIN)
        max_depth = MAX_DEPTH if self.glass0 is None else MAX_DEPTH_GLASS
        if self.beam is None:
            laser = {"type": "disk", "to_world": M(np.diag([rb, rb, 1.0]), self.laser_W), "bsdf": {"type": "null"},
                     "emitter": {"type": "directionalarea", "radiance": 1.0}}
        else:   # a square patch carrying the Gaussian irradiance as its radiance (bilinear bitmap)
            h = self.emit_radius_mm
            img = gaussian_irradiance(BEAM_BITMAP_PX, self.beam.truncation).astype(np.float32)
            laser = {"type": "rectangle", "to_world": M(np.diag([h, h, 1.0]), self.laser_W), "bsdf": {"type": "null"},
                     "emitter": {"type": "directionalarea",
                                 "radiance": {"type": "bitmap", "bitmap": mi.Bitmap(img[:, :, None]), "raw": True,
                                              "filter_type": "bilinear", "wrap_mode": "clamp"}}}
        Rdet = np.column_stack([self.u_axis * 0.5 * g.width_px * g.pitch_mm,
                                self.v_axis * 0.5 * g.height_px * g.pitch_mm, [0, 0, 1.0]])
        return {
            "type": "scene",
            "integrator": {"type": "ptracer", "max_depth": max_depth, "rr_depth": 100, "hide_emitters": True},
            "sensor": {"type": "rigsim_telecentric", "pixel_size_mm": g.pitch_mm,
                       "cx": self.u_T, "cy": (g.height_px - 1) - self.v_T,
                       "detector_width": g.width_px, "detector_height": g.height_px,
                       "window_u0": 0, "window_v0": 0,
                       "film": {"type": "hdrfilm", "width": W, "height": W, "rfilter": {"type": "box"},
                                "pixel_format": "luminance", "component_format": "float32"},
                       "sampler": {"type": self.sampler, "sample_count": self.spp}},
            "laser": laser,
            "lens": {"type": "rectangle", "to_world": M(np.diag([LENS_PATCH_HALF_MM] * 2 + [1.0]), np.zeros(3)),
                     "bsdf": lens_bsdf},
            "facet": {"type": "rectangle", "to_world": M(np.diag([FACET_HALF_MM, -FACET_HALF_MM, -1.0]), self.facet_point_W),
                      "bsdf": {"type": MIRROR_PLUGIN, "normal": self.f0.tolist()}},
            "detector": {"type": "rectangle", "to_world": M(Rdet, self.det_centre_W),
                         "bsdf": {"type": "diffuse", "reflectance": 1.0}},
            **({} if self.glass0 is None else {"prism_front": {
                "type": "rectangle", "to_world": mi.ScalarTransform4f(self._front_matrix(None).tolist()),
                "bsdf": {"type": "dielectric", "int_ior": self.glass0.n, "ext_ior": 1.0}}}),
        }

    def _aberration_props(self) -> dict:
        """The aberrated lens's properties: W131, W222 in mm, the pupil radius, the fill and the field's
        tangential direction (from the optical axis towards this CMOS's field point, in the lens plane)."""
        a = self.aberr
        lam = a.wavelength_nm * 1e-6
        e = self.geom.emitter_mm[self.j]
        t = np.array([e[0], e[1], 0.0]) / math.hypot(e[0], e[1])
        return {"coma_mm": a.coma_waves * lam, "astig_mm": a.astigmatism_waves * lam,
                "pupil_radius_mm": 0.5 * a.aperture_diameter_mm, "fill": a.beam_fill, "tangential": t.tolist()}

    def aberration_truth(self) -> dict:
        """Closed forms of the aberrated spot (:mod:`rigsim.optics.objective_aberrations`): its centroid
        shift (u, v) px and the variance astigmatism adds along the tangential direction, px²."""
        p = self._aberration_props()
        g = self.geom
        fa = g.F / p["pupil_radius_mm"]
        shift = centroid_shift_mm(coma_mm=p["coma_mm"], f_over_a=fa, fill=p["fill"]) * np.array(p["tangential"][:2])
        return {"centroid_shift_px": [float(shift @ self.u_axis[:2] / g.pitch_mm), float(shift @ self.v_axis[:2] / g.pitch_mm)],
                "tangential_uv": [float(np.array(p["tangential"][:2]) @ self.u_axis[:2]),
                                  float(np.array(p["tangential"][:2]) @ self.v_axis[:2])],
                "astigmatism_tangential_variance_px2":
                    tangential_variance_mm2(astig_mm=p["astig_mm"], f_over_a=fa, fill=p["fill"]) / g.pitch_mm**2}

    def _front_matrix(self, E_ota) -> np.ndarray:
        """float32 to_world of the glass's entrance face (a rectangle whose normal is the face's,
        towards the camera) for the camera rotation ``E_ota`` (None: the reference)."""
        nf = self.glass0.front
        a = np.cross(nf, [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(nf, a)
        R = np.column_stack([a * FACET_HALF_MM, b * FACET_HALF_MM, nf])
        if E_ota is not None:
            R = E_ota.T @ R
        A = np.eye(4)
        A[:3, :3], A[:3, 3] = R, self.front_point_W
        return A.astype(np.float32)

    def _glass_now(self, front_matrix: np.ndarray, N: np.ndarray) -> GlassFacet:
        """The glass element the scene renders: the entrance face's normal as Mitsuba derives it from the
        float32 matrix (inverse transpose), the coated face's float32 normal."""
        A = front_matrix.astype(np.float64)
        nf = np.linalg.inv(A[:3, :3]).T @ np.array([0.0, 0.0, 1.0])
        return GlassFacet(nf / np.linalg.norm(nf), N, A[:3, 3], self.facet_point_W, self.glass0.n)

    def _rendered_params(self, E_hrc, delta_f_mm) -> dict:
        """Float32 values of everything the scene gets for this state (the truth uses these)."""
        g = self.geom
        C = g.R_ota_from_hrc
        E = np.eye(3) if E_hrc is None else np.asarray(E_hrc, float)
        N = _f32((C @ E @ C.T).T @ self.mirror0)
        dF = float(delta_f_mm) / g.telecentric_factor
        dz = float(_f32(dF))
        f_lens = float(_f32(g.F + dF))
        out = {"N": N, "lens_z": dz, "f_lens": f_lens, "C": self.C_W + np.array([0.0, 0.0, dz])}
        if self.glass0 is not None:
            out["front"] = self._front_matrix(C @ E @ C.T)
            out["glass"] = self._glass_now(out["front"], N)
        return out

    def _front_update(self, state) -> dict:
        import mitsuba as mi

        return {"prism_front.to_world": mi.Transform4f(state["params"]["front"])}

    def _facet_update(self, state) -> dict:
        import mitsuba as mi

        return {"facet.bsdf.normal": mi.Vector3f(*[float(x) for x in state["params"]["N"]])}

    def _lens_update(self, state) -> dict:
        import mitsuba as mi

        p = state["params"]
        A = np.diag([LENS_PATCH_HALF_MM, LENS_PATCH_HALF_MM, 1.0, 1.0])
        A[2, 3] = p["lens_z"]
        return {"lens.bsdf.focal_length": mi.Float(p["f_lens"]),
                "lens.bsdf.centre": mi.Vector3f(*[float(x) for x in p["C"]]),
                "lens.to_world": mi.Transform4f(A.astype(np.float32))}

    def _sensor_update(self, state) -> dict:
        import mitsuba as mi

        u0, v0 = state["window_origin"]
        return {"sensor.window_origin": mi.Point2f(float(u0), float(self.geom.height_px - self.window_px - v0))}

    def _state(self, E_hrc, delta_f_mm, window_origin) -> dict:
        return {"params": self._rendered_params(E_hrc, delta_f_mm), "window_origin": window_origin}

    # -- truth ---------------------------------------------------------------------------------
    def exact_uv(self, E_hrc=None, delta_f_mm=0.0) -> np.ndarray:
        """Spot centre (image of the core's centre) from the exact forward model, rigsim px."""
        g = self.geom
        if self.glass0 is not None:
            return self.glass_spots_uv(E_hrc, delta_f_mm)["main"][0]
        P = loop_trace(g, E_hrc, delta_f_mm)[self.j]
        return g.xy_to_uv(g.focal_to_xy(np.stack([P, P]))[self.j])

    def glass_spots_uv(self, E_hrc=None, delta_f_mm=0.0) -> dict:
        """With the prism glass on: {path: (centre uv of the image of the core's centre, fraction of the
        power)} for the main return and the two ghosts (exact vector Snell/Fresnel trace of the
        rendered float32 parameters)."""
        p = self._rendered_params(E_hrc, delta_f_mm)
        out = {}
        for path in GLASS_PATHS:
            lx, ly, frac = _trace_glass(np.array([self.laser_W[0]]), np.array([self.laser_W[1]]), p["C"], p["f_lens"],
                                        p["glass"], self.det_centre_W[2], path)
            out[path] = (np.array(self._uv_of_landing(lx, ly))[:, 0], float(frac[0]))
        return out

    def _uv_of_landing(self, lx, ly):
        g = self.geom
        ex, ey = lx - self.det_centre_W[0], ly - self.det_centre_W[1]   # the landing plane is the detector's
        return ((ex * self.u_axis[0] + ey * self.u_axis[1]) / g.pitch_mm + g.cx,
                (ex * self.v_axis[0] + ey * self.v_axis[1]) / g.pitch_mm + g.cy)

    def truth(self, E_hrc=None, delta_f_mm=0.0, window_origin=None, rng_seed: int = 0) -> dict:
        """Exact truth of the rendered scene (float64 trace of its float32 parameters): the spot
        centre, the mean of the core's image and the first moment of its pixel-binned image in the
        ROI (what a perfect renderer gives), plus geometry flags."""
        g = self.geom
        p = self._rendered_params(E_hrc, delta_f_mm)
        sx, sy = self._truth_sources(int(rng_seed))
        n = self.truth_rays
        du, dv = np.empty(n), np.empty(n)
        for a in range(0, n, TRUTH_CHUNK):   # in cache-sized chunks: the trace is many passes over its arrays
            sl = slice(a, a + TRUTH_CHUNK)
            if self.glass0 is None:
                lx, ly = _trace_xy(sx[sl], sy[sl], p["C"], p["f_lens"], p["N"], self.facet_point_W, self.det_centre_W[2])
            else:   # the main return (the ghosts: glass_spots_uv)
                lx, ly, _ = _trace_glass(sx[sl], sy[sl], p["C"], p["f_lens"], p["glass"], self.det_centre_W[2], "main")
            ex, ey = lx - self.det_centre_W[0], ly - self.det_centre_W[1]   # the landing plane is the detector's
            du[sl] = (ex * self.u_axis[0] + ey * self.u_axis[1]) / g.pitch_mm + g.cx
            dv[sl] = (ex * self.v_axis[0] + ey * self.v_axis[1]) / g.pitch_mm + g.cy
        centre = self.exact_uv(E_hrc, delta_f_mm)
        if window_origin is None:
            window_origin = self._window_for(centre)
        u0, v0 = window_origin
        W = self.window_px
        iu, iv = np.floor(du + 0.5), np.floor(dv + 0.5)
        inside = (iu >= u0) & (iu < u0 + W) & (iv >= v0) & (iv < v0 + W) & (iu >= 0) & (iv >= 0) \
            & (iu < g.width_px) & (iv < g.height_px)
        binned = np.array([iu[inside].mean(), iv[inside].mean()]) if inside.any() else np.array([np.nan, np.nan])
        rad_px = self.emit_radius_mm / g.pitch_mm
        flags = {
            "spot_outside_model": False,
            "spot_off_detector": bool(not (-0.5 <= centre[0] <= g.width_px - 0.5 and -0.5 <= centre[1] <= g.height_px - 0.5)),
            "spot_cut_by_edge": bool(centre[0] - rad_px < 0.5 or centre[1] - rad_px < 0.5
                                     or centre[0] + rad_px > g.width_px - 1.5 or centre[1] + rad_px > g.height_px - 1.5),
            "spot_exceeds_window": bool(inside.mean() < 1.0),
        }
        out = {"spot_uv": centre.tolist(), "mean_uv": [float(du.mean()), float(dv.mean())],
               "pixel_centroid_uv": binned.tolist(), "window_origin_uv": [int(u0), int(v0)],
               "fraction_in_window": float(inside.mean()), "flags": flags,
               "facet_normal_ota_f32": p["N"].tolist(), "lens_focal_length_mm_f32": p["f_lens"]}
        if self.aberr is not None:
            ab = self.aberration_truth()
            ab["aberrated_centroid_uv"] = (binned + np.array(ab["centroid_shift_px"])).tolist()
            out["objective_aberrations"] = ab
        if self.beam is not None:
            out["gaussian_beam"] = {"radius_mm": self.beam_radius_mm, "second_moment_px2": (self.beam_radius_mm / g.pitch_mm) ** 2 / 4}
        if self.glass0 is not None:   # every path's centre and power share, and the centroid of all of them
            spots = self.glass_spots_uv(E_hrc, delta_f_mm)
            w = np.array([spots[k][1] for k in GLASS_PATHS])
            uv = np.array([spots[k][0] for k in GLASS_PATHS])
            out["prism_glass"] = {k: {"uv": spots[k][0].tolist(), "fraction": spots[k][1]} for k in GLASS_PATHS}
            out["prism_glass"]["all_paths_centroid_uv"] = (w @ uv / w.sum()).tolist()
        return out

    def _truth_sources(self, rng_seed: int) -> tuple[np.ndarray, np.ndarray]:
        """The truth's ray origins on the core (uniform on the disk, drawn from ``rng_seed``): the same for
        every frame of a seed, so they are drawn once per seed (the last one is kept)."""
        cached = getattr(self, "_sources", None)
        if cached is not None and cached[0] == (rng_seed, self.truth_rays):
            return cached[1], cached[2]
        rng = np.random.default_rng(rng_seed)
        n = self.truth_rays
        if self.beam is not None:   # the Gaussian irradiance, cut where the emitting patch's disk ends
            x, y = sample_gaussian_disk(rng, n, self.beam_radius_mm, self.beam.truncation)
            sx, sy = self.laser_W[0] + x, self.laser_W[1] + y
        else:
            r = self.core_radius_mm * np.sqrt(rng.random(n))
            t = 2 * np.pi * rng.random(n)
            sx, sy = self.laser_W[0] + r * np.cos(t), self.laser_W[1] + r * np.sin(t)
        self._sources = ((rng_seed, self.truth_rays), sx, sy)
        return sx, sy

    def _window_for(self, uv) -> tuple[int, int]:
        if not self.follow:
            return self.roi_origin
        return (int(round(uv[0])) - self.window_px // 2, int(round(uv[1])) - self.window_px // 2)

    # -- rendering -----------------------------------------------------------------------------
    def render_photons(self, E_hrc=None, delta_f_mm=0.0, seed: int = 0, spp: int | None = None,
                       window_origin=None) -> tuple[np.ndarray, tuple[int, int]]:
        """Expected photons per ROI pixel (h, w) and the ROI origin (u0, v0)."""
        if window_origin is None:
            window_origin = self._window_for(self.exact_uv(E_hrc, delta_f_mm))
        img = self._scene.render(self._state(E_hrc, delta_f_mm, window_origin), seed=int(seed), spp=int(spp or self.spp),
                                 single_thread=self.deterministic)
        img = np.ascontiguousarray(img[::-1, :])
        if self.photons_per_unit is None:
            self.photons_per_unit = self._calibrate()
        return img * self.photons_per_unit, tuple(int(x) for x in window_origin)

    def _calibrate(self) -> float:
        """Film units → photons: the whole core lands in the ROI at the reference (checked)."""
        origin = self._window_for(self.ref_uv)
        tr = self.truth(None, 0.0, origin)
        if tr["fraction_in_window"] < 1.0:
            raise ValueError("the reference spot does not fit in the ROI: enlarge window_px")
        img = self._scene.render(self._state(None, 0.0, origin), seed=12345, spp=max(self.spp, 256),
                                 single_thread=self.deterministic)
        total = float(img.sum())
        if not total > 0:
            raise RuntimeError("the laser loop renders nothing at the reference: scene geometry is broken")
        return self.rig.laser.photons_per_frame / total

    def warm_up(self) -> float:
        """Compile the kernels (seconds taken): by the photon calibration's render when it is still to do
        (the first frame would do it anyway), else by a frame that is thrown away."""
        t0 = time.perf_counter()
        if self.photons_per_unit is None:
            self.photons_per_unit = self._calibrate()
        else:
            self.render_photons(None, 0.0, seed=0)
        return time.perf_counter() - t0

    def render(self, E_hrc=None, delta_f_mm=0.0, seed: int = 0, *, noiseless: bool = False,
               spp: int | None = None, with_truth: bool = True) -> Frame:
        """A CMOS ROI frame (uint16 DN, detector model applied) for the camera state (E, Δf)."""
        t0 = time.perf_counter()
        centre = self.exact_uv(E_hrc, delta_f_mm)
        origin = self._window_for(centre)
        tr = self.truth(E_hrc, delta_f_mm, origin) if with_truth else {"spot_uv": centre.tolist(), "flags": {}}
        flags = dict(tr.get("flags", {}))
        if flags.get("spot_off_detector"):
            warnings.warn(f"camera {self.geom.name} M{self.j + 1}: the laser spot is off the CMOS (out of the "
                          "measuring range); nothing rendered", GeometryWarning, stacklevel=2)
        elif flags.get("spot_exceeds_window"):
            warnings.warn(f"camera {self.geom.name} M{self.j + 1}: the laser spot leaves the ROI at {origin} "
                          "(its centroid is biased)", GeometryWarning, stacklevel=2)
        W = self.window_px
        if flags.get("spot_off_detector"):
            photons = np.zeros((W, W))
        else:
            photons, origin = self.render_photons(E_hrc, delta_f_mm, seed, spp, origin)
        fr = digitise(photons, self._roi_cfg(origin), seed=int(seed), noiseless=noiseless, truth=tr,
                      render=self.settings(spp), geometry_flags=flags,
                      sidecar_extra={"roi_origin_uv": list(origin), "camera": self.geom.name, "detector": f"M{self.j + 1}",
                                     "state": {"delta_f_mm": float(delta_f_mm),
                                               "E_hrc": (np.eye(3) if E_hrc is None else np.asarray(E_hrc)).tolist()}})
        fr.origin_uv = tuple(int(x) for x in origin)  # the ROI on the CMOS (its own fixed patterns: _roi_cfg)
        fr.detector_shape = (self.geom.height_px, self.geom.width_px)
        fr.seconds = time.perf_counter() - t0
        if fr.detector.saturated_pixels:
            warnings.warn(f"{fr.detector.saturated_pixels} saturated pixels in the ROI: lower laser.photons_per_frame",
                          GeometryWarning, stacklevel=2)
        return fr

    def _roi_cfg(self, origin):
        """The detector instance of this ROI: the fixed patterns are drawn for the ROI (keyed by
        its position), which is right for fixed ROIs (docs/boresight.md)."""
        key = (self.det_cfg.sensor_seed * 1_000_003 + 7919 * int(origin[0]) + int(origin[1])) % (2**63)
        return self.det_cfg.model_copy(update={"sensor_seed": int(key)})

    def write(self, path, frame: Frame):
        return frame.write(path)

    def settings(self, spp=None) -> dict:
        g = self.geom
        extra = {}
        if self.beam is not None:
            extra["gaussian_beam"] = {"w_at_conjugate_mm": self.beam_radius_mm, **self.beam.model_dump(exclude={"enabled"})}
        if self.aberr is not None:
            extra["objective_aberrations"] = {"model": "Seidel wavefront (coma, astigmatism) ×2 on the return crossing",
                                              **self.aberr.model_dump(exclude={"enabled"})}
        if self.glass0 is not None:
            extra["prism_glass"] = {"integrator_max_depth": MAX_DEPTH_GLASS, "entrance_face": "dielectric rectangle",
                                    **self.glass_cfg.model_dump(exclude={"enabled"})}
        return {**extra, "primitive": "boresight_laser_loop", "variant": self.variant, "camera": g.name,
                "detector": f"M{self.j + 1}", "integrator": f"ptracer(max_depth={MAX_DEPTH}, hide_emitters)",
                "sampler": self.sampler, "spp": int(spp or self.spp), "window_px": self.window_px,
                "lens": "ideal thin lens (rigsim_ideal_lens), in focus", "facet": "rigsim_normal_mirror",
                "core_radius_um": self.core_radius_mm * 1e3, "photons_per_frame": self.rig.laser.photons_per_frame,
                "world_frame": "OTA axes, origin at the pencil's lens crossing (lens centre float32-exact)",
                "units": "mm"}
