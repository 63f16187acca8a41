"""Seed 001: the photoelectric autocollimator, rendered with Mitsuba (light tracing).

Scene (millimetres, world frame = the autocollimator frame A of
:mod:`rigsim.optics.autocollimator`: origin at the objective's centre, +z towards the mirror):

* ``reticle``    -- a ``spot`` emitter (a point: a pinhole reticle) at the best-collimation
  point of the objective, uniform over a cone that slightly overfills the stop;
* ``objective``  -- a plano-convex N-BK7 singlet, a PLY mesh with analytic vertex normals,
  ``dielectric`` BSDF. Fresnel *reflections* are discarded (``specular_reflectance = 0``; no
  ghosts, as with AR coatings and baffles), Fresnel *transmission* is kept;
* ``stop``       -- a black annulus in front of the convex vertex (the clear aperture);
* ``mirror``     -- the cube (all six faces ``conductor``, ``face_normals``) or the plane mirror
  (a 512-gon), in a ``shapegroup`` placed by an ``instance`` whose transform is a pure
  translation to the target's centre at the reference pose. The mesh's own vertices are given
  relative to that point (small numbers), so float32 keeps the face normal to ~1e-10 rad; the
  turntable pose changes the vertices through ``mi.traverse`` (no rebuild, no recompile);
* ``detector``   -- a Lambertian (reflectance 1) rectangle covering exactly the detector area,
  in the detector plane; what lands on it is the image;
* ``sensor``     -- a built-in ``perspective`` camera ``CAMERA_STANDOFF_MM`` in front of the
  detector plane, looking at it square-on, whose field is exactly ``window_px`` detector pixels
  (by default derived from the geometric spot: :func:`~rigsim.optics.autocollimator.render_window_px`).
  The render window is moved by moving this camera (``sensor.to_world``), never the film crop.
  The camera sees the detector from the lens side, so the film is mirrored in u: window pixel
  (i, j) is ``film[j, window_px - 1 - i]``;
* ``beam_splitter_s1/s2`` -- with ``[effects.beam_splitter]`` only: the plate's two faces; the
  reticle is then folded (mirrored in S1) and the detector and the camera follow the plate's
  displaced, refocused axis (docs/effects-autocollimator.md);
* ``integrator`` -- ``ptracer`` (the beam → mirror → lens → detector path is a caustic),
  ``hide_emitters``, ``max_depth`` = the length of the main path (so light scattered back off the
  detector is not re-imaged).

Why the objective sits at the origin (and not the mirror): Mitsuba offsets every new ray by
``(1 + max|p|)·8.9e-5`` scene units along the surface normal. At a refracting surface 500 mm
from the origin that is 0.045 mm: it acts like moving the lens and changing its radii, a
~1.6e-4 scale error of the spot offset (0.1 px at the edge of the range). At the origin it is
2e-3 mm at the rim. The mirror only needs an exact normal (offsets along it only shift the
collimated return beam sideways), which the instance translation gives.

Every plugin is built in: ``mi.xml.dict_to_xml`` exports a scene dict that the plain
``mitsuba`` command renders (meshes are PLY files under ``mesh_dir``).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import trimesh

from rigsim.errors import GeometryWarning
from rigsim.frames import ARCSEC_PER_RAD
from rigsim.optics.autocollimator import (
    AutocollimatorOptics,
    MirrorTarget,
    SpotTruth,
    peak_over_noise,
    render_window_px,
)
from rigsim.optics.autocollimator import diffraction_half_px as _kernel_half_px
from rigsim.optics.beam_splitter import BeamSplitter
from rigsim.optics.meshes import lens_mesh, stop_mesh
from rigsim.optics.reticle import ReticleDrawing, reticle_drawing
from rigsim.render.backend import ensure_variant
from rigsim.render.budget import check_memory
from rigsim.render.frame import Frame, digitise, write_frame
from rigsim.render.meshes import mesh_ply
from rigsim.render.scene import Scene
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.effects_autocollimator import beam_splitter_of
from rigsim.truth.cube_mirror.autocollimator import (
    AutocollimatorLayout,
    autocollimator_layout,
    mirror_mesh_A,
    mirror_target,
)
from rigsim.truth.cube_mirror.realization import Realization, realization_from_rig

__all__ = [
    "CAMERA_STANDOFF_MM",
    "DEFAULT_SOURCE_PHOTONS",
    "AutocollimatorScene",
    "AutocollimatorWindow",
    "AutocollimatorRenderer",
    "build_autocollimator_scene_dict",
    "autocollimator_scene",
    "lens_mesh",
    "stop_mesh",
    "mirror_mesh_A",
    "GeometryWarning",
]

CAMERA_STANDOFF_MM = 50.0
DEFAULT_SOURCE_PHOTONS = 1.8e6
"""Photons the reticle emits per exposure (scene dicts). With the seed-001 rig (50 mm beam on a
25 mm cube face, the rig's default detector) the brightest pixel of the nulled *geometric* spot
gets about half the full well (the diffraction blur lowers the peak ~2.5×); the renderer sets its
own from ``peak_fraction`` (diffraction included) unless told."""

MAIN_PATH_DEPTH = 7  # Mitsuba counts the emitter vertex: reticle, flat, convex, mirror, convex, flat, detector


# ------------------------------------------------------------------------------ effects
def fresnel_normal(n: float) -> float:
    """Reflectance of a bare dielectric surface of index ``n`` (in air) at normal incidence."""
    return ((n - 1.0) / (n + 1.0)) ** 2


@dataclass(frozen=True)
class AutocollimatorEffectSettings:
    """What the rig's enabled ``[effects]`` change in the autocollimator's scene (all None/off:
    the ideal scene, built exactly as without effects)."""

    reticle: ReticleDrawing | None = None
    face_bsdf: str | None = None          # None: perfect conductor; "dielectric"; "conductor"
    face_index: float = 1.5168
    face_reflectance: float = 1.0         # the coated face's (conductor)
    lens_ghost_scale: float | None = None  # None: no lens ghosts from the effects; else specular_reflectance
    beam_splitter: BeamSplitter | None = None

    @property
    def extra_depth(self) -> int:
        # the uncoated cube's opposite face (in, reflect, out) and the double-pass lens ghosts
        # (mirror, lens surface, mirror) each add two vertices to the longest path kept; the beam
        # splitter three to the main path (S1 on the way out, S1 and S2 back) and two to its ghosts
        return (2 * (self.face_bsdf == "dielectric") + 2 * (self.lens_ghost_scale is not None)
                + 5 * (self.beam_splitter is not None))

    def as_dict(self) -> dict:
        d = {}
        if self.reticle is not None:
            d["reticle"] = self.reticle.as_dict()
        if self.face_bsdf is not None:
            d["face_reflectance"] = ({"bsdf": "dielectric", "glass_index": self.face_index,
                                      "front_reflectance_normal": fresnel_normal(self.face_index)}
                                     if self.face_bsdf == "dielectric"
                                     else {"bsdf": "conductor", "reflectance": self.face_reflectance})
        if self.lens_ghost_scale is not None:
            d["ghosts"] = {"specular_reflectance_scale": self.lens_ghost_scale}
        if self.beam_splitter is not None:
            d["beam_splitter"] = self.beam_splitter.as_dict()
        return d


def effect_settings(rig: CubeMirrorRig, target: str, lens_n: float) -> AutocollimatorEffectSettings:
    """The scene changes of ``rig.effects`` (the TRUE rig's) for ``target`` (the face reflectance
    applies to the cube's faces only, not to the plane mirror of step A)."""
    eff = getattr(rig, "effects", None)
    if eff is None or not hasattr(eff, "reticle"):
        return AutocollimatorEffectSettings()
    kw: dict = {}
    if eff.reticle.enabled:
        r = eff.reticle
        kw["reticle"] = reticle_drawing(r.pattern, r.line_width_um * 1e-3, r.arm_length_mm, r.ring_radius_mm)
    if eff.face_reflectance.enabled and target == "face":
        f = eff.face_reflectance
        if f.coating == "uncoated":
            kw.update(face_bsdf="dielectric", face_index=float(f.glass_index))
        else:
            kw.update(face_bsdf="conductor", face_reflectance=float(
                f.protected_al_reflectance if f.coating == "protected_al" else f.enhanced_al_reflectance))
    if eff.ghosts.enabled:
        g = eff.ghosts.surface_reflectance
        kw["lens_ghost_scale"] = 1.0 if g is None else float(g) / fresnel_normal(lens_n)
    kw["beam_splitter"] = beam_splitter_of(rig, lens_n)
    return AutocollimatorEffectSettings(**kw)


def plate_fold_matrix(bs: BeamSplitter) -> np.ndarray:
    """4×4 reflection in the plane of the plate's first surface S1 (the fold of the reticle)."""
    n = bs.normal
    c = bs.placement.point
    M = np.eye(4)
    M[:3, :3] -= 2.0 * np.outer(n, n)
    M[:3, 3] = 2.0 * (c @ n) * n
    return M


MITSUBA_RAY_EPSILON = 1500.0 * 2.0 ** -24
"""Mitsuba offsets every new ray's origin by ``(1 + max|p|)·MITSUBA_RAY_EPSILON`` scene units along
the surface's geometric normal, on the side of the new direction (``SurfaceInteraction.spawn_ray``)."""


def plate_spawn_bias_mm(bs: BeamSplitter, optics: AutocollimatorOptics, n_rays: int = 20000) -> np.ndarray:
    """Where Mitsuba's ray offsets at the plate's three crossings of the main path move the spot
    (x_A, y_A, mm): the reticle's light leaving S1 by reflection (a parallel shift n1·ε of each
    outgoing ray: the source seen ε·n1⊥ aside, its image −ε·n1⊥ away, point-inverted) and the return
    entering S1 and leaving S2 (traced with and without the offsets). Rays: the reticle's cone at
    the null (the return crosses the plate on the outgoing footprint); weights: R1·T1·T2."""
    from rigsim.optics.autocollimator import cone_directions

    n1 = bs.normal
    c1 = bs.placement.point
    c2 = c1 - bs.thickness_mm * n1
    d = cone_directions(n_rays, optics.cone_half_angle_rad)
    S = optics.source_position
    H = S + (((c1 - S) @ n1) / (d @ n1))[:, None] * d          # the unfolded reticle rays on S1
    eps = lambda P: MITSUBA_RAY_EPSILON * (1.0 + np.max(np.abs(P), axis=1))
    ci = d @ n1
    w = bs.weights(ci, 1)[0] * bs.weights(ci, 1)[1] * bs.weights(ci, 2)[1]
    shift_src = eps(H)[:, None] * (n1[None, :] - ci[:, None] * d)   # ⊥ the ray
    b_out = -(w[:, None] * shift_src[:, :2]).sum(0) / w.sum()

    def back(offsets: bool):
        r = -d
        g = bs.n ** -1 * r + ((ci / bs.n) - np.sqrt(1.0 - (1.0 - ci * ci) / bs.n ** 2))[:, None] * n1  # Snell into glass
        O1 = H - (eps(H)[:, None] * n1 if offsets else 0.0)
        H2 = O1 + (((c2 - O1) @ n1) / (g @ n1))[:, None] * g
        O2 = H2 - (eps(H2)[:, None] * n1 if offsets else 0.0)
        # out of S2 the ray is parallel to r again (a plane-parallel plate)
        s = (optics.z_detector - O2[:, 2]) / r[:, 2]
        return O2[:, :2] + s[:, None] * r[:, :2]

    b_ret = (w[:, None] * (back(True) - back(False))).sum(0) / w.sum()
    return b_out + b_ret


def plate_shapes(bs: BeamSplitter, optics: AutocollimatorOptics) -> dict:
    """The plate's two faces: rectangles (sides left out: no kept path reaches them) with
    ``dielectric`` BSDFs whose reflection and transmission weights give each surface its
    reflectance at the plate's angle (:func:`rigsim.optics.beam_splitter.surface_weights`);
    outward normals, S2 ``thickness`` behind S1."""
    import mitsuba as mi

    n1 = bs.normal
    u = np.array([math.cos(bs.theta), 0.0, -math.sin(bs.theta)])
    y = np.array([0.0, 1.0, 0.0])
    r = 1.1 * optics.objective.stop_radius_mm * optics.overfill
    a = r / math.cos(bs.theta) + 2.0 * bs.ghost_separation_mm
    b = r + 1.0
    F0 = bs.fresnel_at_tilt
    out = {}
    for k, (R, sign) in enumerate(((bs.r1, 1.0), (bs.r2, -1.0)), start=1):
        M = np.eye(4)
        M[:3, 0] = sign * a * u
        M[:3, 1] = b * y
        M[:3, 2] = sign * n1
        M[:3, 3] = bs.placement.point - (k - 1) * bs.thickness_mm * n1
        bsdf = {"type": "dielectric", "int_ior": float(bs.n), "ext_ior": 1.0}
        if R is not None:
            bsdf["specular_reflectance"] = float(R / F0)
            bsdf["specular_transmittance"] = float((1.0 - R) / (1.0 - F0))
        out[f"beam_splitter_s{k}"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f(M.tolist()), "bsdf": bsdf}
    return out


# ------------------------------------------------------------------------------ scene
@dataclass
class AutocollimatorScene:
    """A scene dict plus everything needed to interpret what it renders."""

    scene_dict: dict
    optics: AutocollimatorOptics
    layout: AutocollimatorLayout
    mirror: MirrorTarget
    window: tuple[int, int, int, int]
    photons_per_unit: float  # film value (radiance) → photons per detector pixel
    source_photons: float  # reticle photons per exposure the scene's intensity stands for
    anchor_A: np.ndarray
    mesh_files: dict = field(default_factory=dict)
    world_shift_A: np.ndarray = field(default_factory=lambda: np.zeros(3))  # world = A − shift
    render_bias_xy: np.ndarray = field(default_factory=lambda: np.zeros(2))  # detector/camera moved by (mm)


def _camera_matrix(optics: AutocollimatorOptics, window_origin, window_px: int, bias_xy=(0.0, 0.0)) -> np.ndarray:
    """Camera → world (A frame): at the window centre, CAMERA_STANDOFF_MM in front of the
    detector, looking −z; local x = +x_A, local y = −y_A (right-handed)."""
    u0, v0 = window_origin
    xc, yc = optics.uv_to_xy(np.array([u0 + (window_px - 1) / 2.0, v0 + (window_px - 1) / 2.0])) + np.asarray(bias_xy)
    M = np.eye(4)
    M[:3, 0] = [1.0, 0.0, 0.0]
    M[:3, 1] = [0.0, -1.0, 0.0]
    M[:3, 2] = [0.0, 0.0, -1.0]
    M[:3, 3] = [xc, yc, optics.z_detector + CAMERA_STANDOFF_MM]
    return M


def _fov_deg(optics: AutocollimatorOptics, window_px: int) -> float:
    return math.degrees(2.0 * math.atan(0.5 * window_px * optics.pitch_mm / CAMERA_STANDOFF_MM))


def autocollimator_scene(rig: CubeMirrorRig, real: Realization | None, pose_rad: dict, target: str = "face",
                         face: str | None = None, *, spp: int, mesh_dir=None,
                         window_px: int | None = None, window_origin=None,
                         optics: AutocollimatorOptics | None = None, layout: AutocollimatorLayout | None = None,
                         source_photons: float = DEFAULT_SOURCE_PHOTONS, sampler: str = "stratified",
                         lens_ghosts: bool = False, max_depth: int | None = None,
                         mirror_reflectance: float = 1.0,
                         plane_mirror_centre_mount_mm=(0.0, 0.0, 0.0),
                         world_origin: str = "objective",
                         effects: AutocollimatorEffectSettings | None = None) -> AutocollimatorScene:
    """Build the scene (see the module docstring) and return it with its interpretation.

    ``effects`` (default: from ``rig.effects``, :func:`effect_settings`) switches the reticle
    emitter, the face's BSDF and the lens ghosts (docs/effects-autocollimator.md).

    ``window_px`` defaults to :func:`~rigsim.optics.autocollimator.render_window_px` of the
    target's geometric spot at ``pose_rad`` (32 px for the default rig).

    ``world_origin="mirror"`` shifts the whole scene so that the target's centre is the world
    origin (the objective then sits ~500 mm away). It exists to measure why the default is the
    objective (docs/render_autocollimator.md); do not use it for production frames."""
    ensure_variant()
    import mitsuba as mi

    if rig.autocollimator is None:
        raise ValueError("this rig has no autocollimator")
    _check_sampler(spp, sampler)
    if window_px is not None and (int(window_px) != window_px or not (8 <= window_px <= 4096)):
        raise ValueError(f"window_px = {window_px!r}: must be an integer in [8, 4096]")
    if not (source_photons > 0 and math.isfinite(source_photons)):
        raise ValueError(f"source_photons = {source_photons!r}: must be a finite number > 0")
    if not (0.0 < mirror_reflectance <= 1.0):
        raise ValueError(f"mirror_reflectance = {mirror_reflectance!r}: must be in (0, 1]")
    real = real if real is not None else realization_from_rig(rig)
    optics = optics or AutocollimatorOptics(rig.autocollimator, beam_splitter=beam_splitter_of(rig))
    layout = layout or autocollimator_layout(rig, real, target, face, objective_vertex_z_mm=optics.objective.z_vertex,
                                             plane_mirror_centre_mount_mm=plane_mirror_centre_mount_mm)
    obj = optics.objective
    fx = effects if effects is not None else effect_settings(rig, layout.target, obj.n)
    if fx.reticle is not None and world_origin != "objective":
        raise ValueError("the reticle effect needs world_origin = 'objective'")
    if fx.beam_splitter is not None and (world_origin != "objective" or optics.beam_splitter != fx.beam_splitter):
        raise ValueError("the beam splitter effect needs world_origin = 'objective' and optics with the same plate")
    T = mi.ScalarTransform4f
    mirror = mirror_target(rig, real, layout, pose_rad, mirror_reflectance)
    if window_px is None:
        window_px = render_window_px(optics.geometric_spot_px(mirror))
    if window_origin is None:
        window = optics.window_for(optics.paraxial_uv(mirror), window_px)
    else:
        window = (int(window_origin[0]), int(window_origin[1]), int(window_px), int(window_px))
    anchor = layout.anchor_A
    if world_origin not in ("objective", "mirror"):
        raise ValueError(f"world_origin = {world_origin!r}: must be 'objective' or 'mirror'")
    shift = np.zeros(3) if world_origin == "objective" else anchor.copy()

    def placed(M):  # A-frame matrix -> world (translate by -shift)
        M = np.array(M, float)
        M[:3, 3] -= shift
        return T(M.tolist())

    V, F = mirror_mesh_A(rig, real, layout, pose_rad)
    mirror_local = trimesh.Trimesh(V - anchor, F, process=False)
    files = {
        "objective": mesh_ply(lens_mesh(obj), "ac_objective", mesh_dir),
        "stop": mesh_ply(stop_mesh(obj), "ac_stop", mesh_dir),
        "mirror": mesh_ply(mirror_local, "ac_cube" if layout.target == "face" else "ac_plane_mirror", mesh_dir),
    }
    omega = 2.0 * math.pi * (1.0 - math.cos(optics.cone_half_angle_rad))
    intensity = source_photons / omega
    lens_bsdf = {"type": "dielectric", "int_ior": float(obj.n), "ext_ior": 1.0}
    if fx.lens_ghost_scale is not None:
        if fx.lens_ghost_scale != 1.0:
            lens_bsdf["specular_reflectance"] = fx.lens_ghost_scale
    elif not lens_ghosts:
        lens_bsdf["specular_reflectance"] = 0.0
    mirror_bsdf = {"type": "conductor", "material": "none"}
    if mirror_reflectance != 1.0:
        mirror_bsdf["specular_reflectance"] = float(mirror_reflectance)
    if fx.face_bsdf == "dielectric":
        mirror_bsdf = {"type": "dielectric", "int_ior": fx.face_index, "ext_ior": 1.0}
    elif fx.face_bsdf == "conductor":
        mirror_bsdf["specular_reflectance"] = float(mirror_reflectance) * fx.face_reflectance
    W, H = optics.width, optics.height
    det = np.eye(4)
    det[0, 0] = 0.5 * W * optics.pitch_mm
    det[1, 1] = 0.5 * H * optics.pitch_mm
    det[:3, 3] = [(W - 1) / 2.0 - optics.cx, (H - 1) / 2.0 - optics.cy, 0.0]
    det[:2, 3] *= optics.pitch_mm
    det[:2, 3] += optics.detector_xy0
    bias = np.zeros(2)
    if fx.beam_splitter is not None:
        # the detector and the camera are moved by the spot's bias from Mitsuba's ray offsets at the
        # plate (~1.4 px; docs/effects-autocollimator.md): the rendered pixels then mean what the
        # exact model's do
        bias = plate_spawn_bias_mm(fx.beam_splitter, optics)
        det[:2, 3] += bias
    det[2, 3] = optics.z_detector
    reticle = np.eye(4)
    reticle[2, 3] = optics.z_source
    if fx.beam_splitter is not None:  # the reticle on the fold: its mirror image in S1
        reticle = plate_fold_matrix(fx.beam_splitter) @ reticle
        reticle[:3, 0] *= -1.0  # a proper rotation again (the spot's cone is symmetric about its axis)
    cone_deg = math.degrees(optics.cone_half_angle_rad)
    depth = MAIN_PATH_DEPTH + fx.extra_depth if max_depth is None else int(max_depth)
    d = {
        "type": "scene",
        "integrator": {"type": "ptracer", "max_depth": depth, "rr_depth": depth + 100, "hide_emitters": True},
        "sensor": {
            "type": "perspective",
            "fov": _fov_deg(optics, window_px), "fov_axis": "x",
            "near_clip": 1.0, "far_clip": 10.0 * CAMERA_STANDOFF_MM,
            "to_world": placed(_camera_matrix(optics, window[:2], window_px, bias)),
            "film": {"type": "hdrfilm", "width": int(window_px), "height": int(window_px),
                     "rfilter": {"type": "box"}, "pixel_format": "luminance", "component_format": "float32"},
            "sampler": {"type": sampler, "sample_count": int(spp)},
        },
        "reticle": {"type": "spot", "intensity": float(intensity), "cutoff_angle": cone_deg,
                    "beam_width": cone_deg, "to_world": placed(reticle)},
        # the lens in its own shapegroup: a mirror update then rebuilds only the top-level BVH
        "objective_group": {"type": "shapegroup",
                            "objective": {"type": "ply", "filename": str(files["objective"]), "face_normals": False,
                                          "bsdf": lens_bsdf}},
        "objective": {"type": "instance", "shapegroup": {"type": "ref", "id": "objective_group"},
                      "to_world": placed(np.eye(4))},
        "stop": {"type": "ply", "filename": str(files["stop"]), "face_normals": True,
                 "bsdf": {"type": "diffuse", "reflectance": 0.0}},
        "detector": {"type": "rectangle", "to_world": placed(det),
                     "bsdf": {"type": "diffuse", "reflectance": 1.0}},
        "mirror_group": {"type": "shapegroup",
                         "mirror": {"type": "ply", "filename": str(files["mirror"]), "face_normals": True,
                                    "bsdf": mirror_bsdf}},
        "mirror": {"type": "instance", "shapegroup": {"type": "ref", "id": "mirror_group"},
                   "to_world": placed(np.array([[1, 0, 0, anchor[0]], [0, 1, 0, anchor[1]], [0, 0, 1, anchor[2]],
                                                [0, 0, 0, 1]], float))},
    }
    if world_origin == "mirror":
        d["stop"]["to_world"] = placed(np.eye(4))
    if fx.beam_splitter is not None:
        d.update(plate_shapes(fx.beam_splitter, optics))
    if fx.reticle is not None:
        from rigsim.render.cube_mirror.reticle_emitter import RETICLE_PLUGIN, register_reticle_emitter

        register_reticle_emitter()
        d["reticle"] = {"type": RETICLE_PLUGIN, "flux": float(source_photons), "z_mm": float(optics.z_source),
                        "z_stop_mm": float(obj.z_stop), "cutoff_rad": float(optics.cone_half_angle_rad),
                        "drawing": fx.reticle.as_props()}
        if fx.beam_splitter is not None:
            bs = fx.beam_splitter
            d["reticle"]["fold_plane"] = ",".join(repr(float(v)) for v in (*bs.placement.point, *bs.normal))
    # a Lambertian detector of reflectance 1 shows radiance E/π: photons per pixel = π·L·pitch²
    return AutocollimatorScene(d, optics, layout, mirror, window, math.pi * optics.pitch_mm ** 2,
                               float(source_photons), anchor, files, shift, bias)


def build_autocollimator_scene_dict(rig: CubeMirrorRig, real: Realization | None, pose_rad: dict, target: str = "face",
                                    face: str | None = None, *, spp: int, mesh_dir=None, **kwargs) -> dict:
    """The Mitsuba scene dict (millimetres, built-in plugins only) of the autocollimator looking at
    ``target`` (``"face"``: cube face ``face``, default the procedure's first; ``"plane_mirror"``)
    at turntable pose ``pose_rad``. Keyword arguments as :func:`autocollimator_scene`."""
    return autocollimator_scene(rig, real, pose_rad, target, face, spp=spp, mesh_dir=mesh_dir, **kwargs).scene_dict


# ------------------------------------------------------------------------------ renderer
def _centroid(img: np.ndarray, origin) -> np.ndarray:
    s = img.sum()
    if not s > 0:
        return np.array([np.nan, np.nan])
    v, u = np.indices(img.shape)
    return np.array([(img * u).sum() / s + origin[0], (img * v).sum() / s + origin[1]])


@dataclass
class AutocollimatorWindow:
    """One rendered window: ``image[j, i]`` is detector pixel (origin_uv[0] + i, origin_uv[1] + j),
    in expected photons per pixel."""

    image: np.ndarray
    origin_uv: tuple[int, int]
    truth: SpotTruth
    flags: dict
    pose_rad: dict
    spp: int
    seed: int
    seconds: float
    rendered: bool
    image_geometric: np.ndarray | None = None  # Mitsuba's ray-optics window (before diffraction)
    origin_geometric: tuple[int, int] | None = None
    seconds_mitsuba: float = 0.0  # of ``seconds``: parameter update + mi.render only

    def centroid_geometric(self) -> np.ndarray:
        if self.image_geometric is None:
            return self.centroid()
        return _centroid(self.image_geometric, self.origin_geometric)

    def centroid(self) -> np.ndarray:
        """First moment of ``image`` in detector pixel coordinates."""
        return _centroid(self.image, self.origin_uv)

    def paste_into(self, frame: np.ndarray) -> np.ndarray:
        H, W = frame.shape
        u0, v0 = self.origin_uv
        h, w = self.image.shape
        a0, b0, a1, b1 = max(0, u0), max(0, v0), min(W, u0 + w), min(H, v0 + h)
        if a1 > a0 and b1 > b0:
            frame[b0:b1, a0:a1] += self.image[b0 - v0:b1 - v0, a0 - u0:a1 - u0]
        return frame


class AutocollimatorRenderer:
    """Render the autocollimator's detector frame per turntable pose.

    Built once (the mirror at the layout's reference pose); :meth:`warm_up` compiles the
    kernels; every :meth:`render_window` / :meth:`render_frame` then only writes the mirror's
    vertex positions and the camera pose through ``mi.traverse`` (no rebuild, no recompile) and
    renders a fixed ``window_px`` window centred on the exact spot. Exact truth (numpy) for every
    frame comes from :class:`~rigsim.optics.autocollimator.AutocollimatorOptics`.

    ``window_px`` and ``diffraction_half_px`` default to values derived from the target's spot at
    the reference pose (``kernel_extent``: :meth:`AutocollimatorOptics.spot_extent` with k = 1 at
    the brightness ``peak_fraction``): the window holds the ray-optics image
    (:func:`~rigsim.optics.autocollimator.render_window_px`, at least 32 px), the kernel the
    diffraction pattern down to the background noise
    (:func:`~rigsim.optics.autocollimator.diffraction_half_px`). Default rig: 32 px and ±39 px on
    a cube face, 32 px and ±15 px on the plane mirror.
    """

    def __init__(self, rig: CubeMirrorRig, real: Realization | None = None, target: str = "face", face: str | None = None, *,
                 spp: int = 1024, window_px: int | None = None, source_photons: float | None = None,
                 peak_fraction: float = 0.5, sampler: str = "stratified", truth_rays: int = 400_000, mesh_dir=None,
                 lens_ghosts: bool = False,
                 optics: AutocollimatorOptics | None = None, layout: AutocollimatorLayout | None = None,
                 mirror_reflectance: float = 1.0, plane_mirror_centre_mount_mm=(0.0, 0.0, 0.0),
                 max_depth: int | None = None, world_origin: str = "objective", diffraction: bool = True,
                 diffraction_half_px: int | None = None, deterministic: bool = False):
        import mitsuba as _mi  # noqa: F401  (ensure_variant happens in autocollimator_scene)

        check_memory(rig.autocollimator.resolution_px, "autocollimator.resolution_px")
        self.rig = rig
        self.deterministic = bool(deterministic)  # one Dr.Jit thread per render: bit-identical frames (ptracer)
        self.real = real if real is not None else realization_from_rig(rig)
        self.optics = optics or AutocollimatorOptics(rig.autocollimator, beam_splitter=beam_splitter_of(rig))
        self.layout = layout or autocollimator_layout(
            rig, self.real, target, face, objective_vertex_z_mm=self.optics.objective.z_vertex,
            plane_mirror_centre_mount_mm=plane_mirror_centre_mount_mm)
        if int(truth_rays) < 10_000:
            raise ValueError(f"truth_rays = {truth_rays!r}: need at least 10000")
        self.truth_rays = int(truth_rays)
        _check_sampler(spp, sampler)
        self.spp = int(spp)
        self.sampler = sampler
        self.mirror_reflectance = float(mirror_reflectance)
        # the window and the diffraction kernel from the spot at the reference pose (the null):
        # docs/autocollimation.md, "Spot size"
        m_ref = mirror_target(rig, self.real, self.layout, self.layout.reference_pose_rad, self.mirror_reflectance)
        self.kernel_extent = self.optics.spot_extent(m_ref, k_sigma=1.0, peak_over_noise=peak_over_noise(
            rig.autocollimator.detector, peak_fraction))
        self.effects = effect_settings(rig, self.layout.target, self.optics.objective.n)
        image_px = self.kernel_extent.geometric_px
        if self.effects.reticle is not None:  # the window holds the reticle's whole image
            image_px += 2.0 * self.effects.reticle.half_extent_mm / self.optics.pitch_mm
        self.window_px = int(render_window_px(image_px) if window_px is None else window_px)
        self.lens_ghosts = bool(lens_ghosts)
        self.world_origin = world_origin
        self.diffraction = bool(diffraction)
        self.diffraction_half_px = int(_kernel_half_px(self.kernel_extent) if diffraction_half_px is None
                                       else diffraction_half_px)
        if self.diffraction_half_px < 1:
            raise ValueError(f"diffraction_half_px = {diffraction_half_px!r}: must be >= 1")
        if source_photons is None:
            source_photons = self.auto_source_photons(peak_fraction)
        self.source_photons = float(source_photons)
        self.variant = ensure_variant()
        sc = autocollimator_scene(rig, self.real, self.layout.reference_pose_rad, self.layout.target, self.layout.face,
                                  spp=spp, mesh_dir=mesh_dir, window_px=self.window_px, optics=self.optics,
                                  layout=self.layout, source_photons=self.source_photons, sampler=sampler,
                                  lens_ghosts=lens_ghosts, max_depth=max_depth, mirror_reflectance=mirror_reflectance,
                                  world_origin=world_origin, effects=self.effects)
        self.scene_info = sc
        # the render loop's elements: per frame the mirror's vertices follow the turntable pose and
        # the camera moves to the window (rigsim.render.scene)
        self._scene = Scene.from_dict(sc.scene_dict, {"mirror_group": self._mirror_update, "sensor": self._sensor_update})
        self._faces = mirror_mesh_A(rig, self.real, self.layout, self.layout.reference_pose_rad)[1]
        self.max_depth = sc.scene_dict["integrator"]["max_depth"]
        self.warmed_up = False

    # -- per-frame state ---------------------------------------------------------------------
    def _mirror_update(self, state) -> dict:
        import mitsuba as mi

        V, F = mirror_mesh_A(self.rig, self.real, self.layout, state["pose"])
        if F.shape != self._faces.shape or np.any(F != self._faces):
            raise RuntimeError("mirror mesh topology changed")  # cannot happen: same builder
        local = (V - self.scene_info.anchor_A).astype(np.float32)
        return {"mirror_group.mirror.vertex_positions": mi.Float(local.ravel())}

    def _sensor_update(self, state) -> dict:
        import mitsuba as mi

        M = _camera_matrix(self.optics, state["window_origin"], self.window_px, self.scene_info.render_bias_xy)
        M[:3, 3] -= self.scene_info.world_shift_A
        return {"sensor.to_world": mi.ScalarTransform4f(M.tolist())}

    def warm_up(self, seed: int = 0) -> float:
        """Render one window at the reference pose (compiles the kernels). Returns seconds."""
        t0 = time.perf_counter()
        self.render_window(self.layout.reference_pose_rad, seed=seed)
        self.warmed_up = True
        return time.perf_counter() - t0

    def auto_source_photons(self, peak_fraction: float = 0.5) -> float:
        """Reticle photons per exposure that bring the brightest pixel of the spot at the
        reference pose (the null) to ``peak_fraction`` of the detector's full well — an
        autocollimator's brightness/exposure set for its target (the plane mirror returns ~3×
        more light than a 25 mm cube face)."""
        if not (0.0 < peak_fraction <= 1.0):
            raise ValueError(f"peak_fraction = {peak_fraction!r}: must be in (0, 1]")
        m = mirror_target(self.rig, self.real, self.layout, self.layout.reference_pose_rad, self.mirror_reflectance)
        sp = self.optics.spot(m, n_rays=self.truth_rays, emitted_photons=1.0, window_px=self.window_px)
        if not sp.valid:
            raise ValueError("no light comes back at the reference pose; pass source_photons explicitly")
        img = self.optics.binned_image(sp.bundle, sp.window)
        if self.diffraction:
            from scipy.signal import fftconvolve

            img = fftconvolve(img, self.optics.diffraction_kernel(m, half_px=self.diffraction_half_px))
        peak = img.max()
        if self.effects.reticle is not None:
            # the reticle's lines: the returned flux spread uniformly over their image (magnification 1)
            peak = sp.flux_photons * self.optics.pitch_mm ** 2 / float(self.effects.reticle.areas.sum())
        cfg = self.rig.autocollimator.detector
        return float(peak_fraction * cfg.full_well_e / cfg.quantum_efficiency / peak)

    def truth(self, pose_rad: dict, window: tuple[int, int, int, int] | None = None,
              source_photons: float | None = None) -> SpotTruth:
        """Exact spot (numpy) at ``pose_rad``; ``window`` defaults to the renderer's placement."""
        m = mirror_target(self.rig, self.real, self.layout, pose_rad, self.mirror_reflectance)
        return self.optics.spot(m, n_rays=self.truth_rays,
                                emitted_photons=self.source_photons if source_photons is None else source_photons,
                                window=window, window_px=None if window is not None else self.window_px)

    def render_window(self, pose_rad: dict, seed: int = 0, *, window_origin=None,
                      source_photons: float | None = None, spp: int | None = None) -> AutocollimatorWindow:
        """Render the window around the exact spot for turntable pose ``pose_rad`` (true angles,
        rad). ``window_origin`` (u0, v0) overrides the placement (the window is moved by moving
        the camera, so any integer origin maps exactly). Geometry problems become flags and a
        :class:`GeometryWarning`; when no light comes back onto the detector nothing is rendered
        (zeros). Values are expected photons per pixel for ``source_photons`` (default: the
        renderer's). ``spp`` overrides the renderer's (each new value compiles once)."""
        spp = self.spp if spp is None else int(spp)
        _check_sampler(spp, self.sampler)
        t0 = time.perf_counter()
        W = self.window_px
        photons = self.source_photons if source_photons is None else float(source_photons)
        if window_origin is not None:
            win = (int(window_origin[0]), int(window_origin[1]), W, W)
            tr = self.truth(pose_rad, window=win, source_photons=photons)
        else:
            tr = self.truth(pose_rad, source_photons=photons)
        flags = dict(tr.flags)
        if tr.window is not None:
            origin = tr.window[:2]
        else:
            origin = self.optics.window_for(tr.paraxial_uv, W)[:2]
        _warn(flags, tr)
        if flags["beam_misses_face"] or flags["spot_off_detector"] or not tr.valid:
            return AutocollimatorWindow(np.zeros((W, W)), tuple(origin), tr, flags, dict(pose_rad), spp, int(seed),
                                        time.perf_counter() - t0, False, np.zeros((W, W)), tuple(origin))
        t1 = time.perf_counter()
        arr = self._scene.render({"pose": pose_rad, "window_origin": origin}, seed=int(seed), spp=spp,
                                 single_thread=self.deterministic)
        t_mi = time.perf_counter() - t1
        arr = np.ascontiguousarray(arr[:, ::-1]) * (self.scene_info.photons_per_unit * photons
                                                    / self.scene_info.source_photons)
        geo, geo_origin = arr, tuple(origin)
        if self.diffraction:
            from scipy.signal import fftconvolve

            m = mirror_target(self.rig, self.real, self.layout, pose_rad, self.mirror_reflectance)
            K = self.optics.diffraction_kernel(m, half_px=self.diffraction_half_px)
            h = self.diffraction_half_px
            arr = np.clip(fftconvolve(arr, K, mode="full"), 0.0, None)
            origin = (origin[0] - h, origin[1] - h)
            v, u = np.indices(arr.shape)
            off = ((u + origin[0] < 0) | (u + origin[0] >= self.optics.width)
                   | (v + origin[1] < 0) | (v + origin[1] >= self.optics.height))
            arr[off] = 0.0  # light spread beyond the detector's edge is not recorded
        return AutocollimatorWindow(arr, tuple(origin), tr, flags, dict(pose_rad), spp, int(seed),
                                    time.perf_counter() - t0, True, geo, geo_origin, t_mi)

    def render_frame(self, pose_rad: dict, seed: int = 0, *, noiseless: bool = False,
                     source_photons: float | None = None, spp: int | None = None) -> Frame:
        """Full detector frame: the window composited on black (exact: only the reticle emits and
        ``spot_exceeds_window`` says whether light was lost), then the detector model with
        ``rig.autocollimator.detector`` and this ``seed`` (Mitsuba and the detector noise both
        take it); the sidecar holds the truth, ``extra["window"]`` the rendered window."""
        win = self.render_window(pose_rad, seed, source_photons=source_photons, spp=spp)
        H, W = self.optics.height, self.optics.width
        photons = win.paste_into(np.zeros((H, W)))
        fr = digitise(photons, self.rig.autocollimator.detector, seed=int(seed), noiseless=noiseless,
                      truth=self.truth_dict(win.truth),
                      render=self.settings(spp=win.spp, source_photons=source_photons),
                      geometry_flags=win.flags, pose=_pose_dict(pose_rad),
                      sidecar_extra={"window_origin_uv": list(win.origin_uv), "rendered": win.rendered,
                                     "render_seconds": win.seconds,
                                     "window_centroid_uv": win.centroid().tolist(),
                                     "window_centroid_geometric_uv": win.centroid_geometric().tolist()},
                      extra={"window": win}, seconds=win.seconds)
        if fr.detector.saturated_pixels > 0:
            warnings.warn(f"{fr.detector.saturated_pixels} saturated pixels in the autocollimator frame: lower "
                          "source_photons (the centroid is biased)", GeometryWarning, stacklevel=2)
        return fr

    def write(self, path, frame: Frame):
        return write_frame(path, frame.dn, frame.sidecar)

    # -- descriptions ------------------------------------------------------------------------
    def truth_dict(self, tr: SpotTruth) -> dict:
        d = tr.as_dict()
        reading = None
        reading_par = None
        if tr.mean_uv is not None:
            reading = (self.optics.reading(tr.mean_uv) * ARCSEC_PER_RAD).tolist()
            reading_par = (self.optics.reading_paraxial(tr.mean_uv) * ARCSEC_PER_RAD).tolist()
        d.update({
            "target": self.layout.target, "face": self.layout.face,
            "reading_arcsec": reading,
            "reading_paraxial_arcsec": reading_par,
            "reading_error_arcsec": None if reading is None else (np.array(reading) - tr.tilt_rad * ARCSEC_PER_RAD).tolist(),
            "reference_uv": [self.optics.cx, self.optics.cy],
            "layout": self.layout.as_dict(),
            "convention": "A frame: +z_A optical axis towards the mirror, u along +x_A, v along +y_A; "
                          "reading (θx, θy) = (atan2(n_x, -n_z), atan2(n_y, -n_z)) of the mirror normal n",
        })
        fx = self.effects.as_dict()
        if fx:  # the truth of the enabled effects (absent when none is on: ideal sidecars unchanged)
            d["effects"] = fx
        return d

    def settings(self, spp: int | None = None, source_photons: float | None = None) -> dict:
        """Every render setting (for sidecars)."""
        o = self.optics
        return {
            "primitive": "autocollimator",
            "variant": self.variant,
            "integrator": f"ptracer(max_depth={self.max_depth}, hide_emitters)",
            "sampler": self.sampler,
            "spp": self.spp if spp is None else int(spp),
            "window_px": self.window_px,
            "source_photons": self.source_photons if source_photons is None else float(source_photons),
            "mirror_reflectance": self.mirror_reflectance,
            "lens_ghosts": self.lens_ghosts,
            "truth_rays": self.truth_rays,
            "objective": o.objective.as_dict(),
            "focus": o.focus,
            "focus_shift_mm": o.focus_shift_mm,
            "z_source_mm": o.z_source,
            "z_detector_mm": o.z_detector,
            "cone_half_angle_deg": math.degrees(o.cone_half_angle_rad),
            "camera_standoff_mm": CAMERA_STANDOFF_MM,
            "world_origin": self.world_origin,
            "diffraction": (f"window convolved with the pixel-integrated Fraunhofer PSF of the return pupil "
                            f"(±{self.diffraction_half_px} px)") if self.diffraction else "none (ray optics only)",
            "units": "mm",
        }


def _check_sampler(spp, sampler: str) -> None:
    if int(spp) != spp or spp < 1:
        raise ValueError(f"spp = {spp!r}: must be an integer >= 1")
    if sampler not in ("independent", "stratified", "multijitter", "ldsampler", "orthogonal"):
        raise ValueError(f"sampler = {sampler!r}: not a Mitsuba sampler rigsim uses")
    if sampler in ("stratified", "multijitter") and math.isqrt(int(spp)) ** 2 != int(spp):
        raise ValueError(f"spp = {spp!r}: the {sampler} sampler needs a perfect square (e.g. 256, 1024, 4096); "
                         "Mitsuba would silently round it up")
    if sampler == "ldsampler" and int(spp) & (int(spp) - 1):
        raise ValueError(f"spp = {spp!r}: the ldsampler needs a power of two; Mitsuba would round it")


def _pose_dict(pose_rad: dict) -> dict:
    return {"true_rad": {k: float(v) for k, v in pose_rad.items()},
            "true_deg": {k: math.degrees(v) for k, v in pose_rad.items()}}


def _warn(flags: dict, tr: SpotTruth) -> None:
    if flags.get("beam_misses_face"):
        warnings.warn("the autocollimator beam misses the mirror: nothing comes back, nothing rendered",
                      GeometryWarning, stacklevel=3)
        return
    if flags.get("beam_partly_misses_face"):
        warnings.warn("part of the mirror lies outside the autocollimator beam (it is off-centre): the "
                      "effective pupil changes and with it the reading", GeometryWarning, stacklevel=3)
    if flags.get("return_vignetted"):
        warnings.warn("part of the reflected beam misses the objective on the way back (tilt near the "
                      "edge of the measuring range)", GeometryWarning, stacklevel=3)
    if flags.get("spot_off_detector"):
        warnings.warn("the return spot is off the detector (out of the measuring range); nothing rendered",
                      GeometryWarning, stacklevel=3)
    elif flags.get("spot_cut_by_edge"):
        warnings.warn("the return spot is cut by the detector edge (out of the measuring range): its "
                      "centroid is biased", GeometryWarning, stacklevel=3)
    if flags.get("spot_exceeds_window"):
        warnings.warn("the return spot does not fit the render window; flux is lost", GeometryWarning,
                      stacklevel=3)


def export_autocollimator(rig: CubeMirrorRig, real: Realization | None = None, pose_rad: dict | None = None, *,
                          spp: int = 64, mesh_dir=None):
    """(scene dict, XML comments) for ``rigsim scene export``: the autocollimator looking at the
    procedure's first face at ``pose_rad`` (default: that face's exact null pose). ``None`` if the
    rig has no autocollimator."""
    if rig.autocollimator is None:
        return None
    real = real if real is not None else realization_from_rig(rig)
    optics = AutocollimatorOptics(rig.autocollimator, beam_splitter=beam_splitter_of(rig))
    layout = autocollimator_layout(rig, real, "face", None, objective_vertex_z_mm=optics.objective.z_vertex)
    if not pose_rad:
        pose_rad = dict(layout.reference_pose_rad)  # the face's exact null: the spot on the axis
    sc = autocollimator_scene(rig, real, pose_rad, "face", None, spp=spp, mesh_dir=mesh_dir, optics=optics, layout=layout)
    u0, v0, w, _ = sc.window
    notes = [
        f"rigsim autocollimator (seed 001), rig '{rig.name}', target {sc.layout.target}; millimetres; origin at the objective",
        "turntable pose (true angles, deg): " + ", ".join(f"{k}={math.degrees(v):.6f}" for k, v in pose_rad.items()),
        f"the film is a {w}x{w} px window whose pixel (0,0) is detector pixel ({u0}, {v0}); ptracer (caustic path)",
    ]
    return sc.scene_dict, notes
