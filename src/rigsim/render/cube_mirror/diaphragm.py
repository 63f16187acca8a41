"""Seed 000 diaphragm screen: beam → hole → cube face → diffuse screen, seen by the aiming camera.

Geometry comes from :mod:`rigsim.truth.cube_mirror.placement` (the same code that writes the truth), in
millimetres, with the lab (rot) frame shifted so that the scene origin is the measured cube
face's centre at its exact null pose (``DiaphragmGeometry.shift_mm``: ``p_scene = p_lab - shift``).
Near the mirror, Mitsuba's ray offset ((1 + |p|)·9e-5 scene units) is then ~0.2 µm along the
face normal, which moves the returned spot by far less than a nanometre.

Scene content (:func:`build_diaphragm_scene_dict`):

* **cube**: the trimesh cube (``meshes.cube_mesh``) with every measured face turned to its
  *true* normal (``real.face_normals_mount``: non-orthogonality included) about its ideal centre,
  a perfect mirror (``conductor``, ``material = "none"``), ``face_normals = True``, at
  ``placement.cube_pose`` (true turntable kinematics) for the turntable pose.
* **screen**: a 150×150 mm (rig) rectangle with a circular hole of ``hole_diameter_mm``, Lambert
  ``diffuse`` (``screen_reflectance``), front face (normal −Z') towards the cube. The hole is a
  256-gon *circumscribing* the circle, so the circle itself (beam, glow) is never clipped;
  the slivers between the polygon and the circle are 0.094 µm deep.
* **beam**: ``directionalarea`` emitter(s) on a disk of the hole's diameter emitting along
  −d_sun, with a ``null`` BSDF. ``return_into_hole="absorb"`` (physical, default): the disk sits
  10 µm behind the hole (simulator side), so light that returns into the hole passes into the
  void (the simulator is not modelled: black), as on the real screen.
  ``return_into_hole="diffuse"`` (fidelity mode): the screen has no hole and the disk floats
  ``beam_standoff_mm`` in front of the screen on the beam axis, so the whole returned disk lands
  on diffuse screen at any tilt, including 0 (with a real hole the collimated spot disappears
  into the hole at the null). Mitsuba's shadow rays are blocked by ``null`` surfaces (measured),
  so the standoff keeps the disk out of the camera's sight lines; a flag reports when it is not.
* **hole glow** (``content="hole"`` or ``"both"``): a Lambertian ``area`` emitter filling the hole
  in the screen plane (``null`` BSDF). The paper says the light leaving the hole is about as
  bright as the reflected spot (§3, Figs 2–3), so its radiance defaults to the spot's.
* **sensor**: the built-in ``perspective`` sensor (plain ``mitsuba`` renders an exported XML),
  ``fov`` and ``principal_point_offset`` from ``focal_length_mm``, ``pixel_pitch_um``,
  ``resolution_px``; box pixel filter. It sits ``working_distance_mm`` from the hole,
  ``view_angle_deg`` off the screen normal on the cube side of the screen (the reflected beam
  lands on the screen's front face, which faces the cube; the simulator side is only 20 mm deep),
  displaced towards ``view_azimuth_deg`` (0: +X'), aimed at the hole (the hole images on the
  principal point). Image "up" is +Y' as far as the view allows.
* **integrator**: ``ptracer`` (the path is a caustic: ``path`` returns exactly zero).

Sun-simulator divergence (``beam``): ``"collimated"`` (default) is a single parallel pencil —
what the fidelity test needs. ``"divergent"`` models the simulator's full angle (rig: 32′) as a
point-symmetric sunflower quadrature of ``divergence_directions`` parallel pencils, each through
the hole, of equal power (one ``directionalarea`` disk each; the spot is their sum, lumpy for few
directions). Over the 1.3 m return path 32′ spreads the spot to ~12 mm more than the hole
(~14.6 mm in all), larger than the default aiming camera's 12.7 × 8.6 mm field on the screen,
which the flags then report.

The camera (:class:`rigsim.optics.aiming.PosedCamera`) and the screen homography are written
independently of Mitsuba; the truth in every sidecar is the exact placement trace projected
through it.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rigsim.errors import GeometryWarning, SaturationWarning
from rigsim.optics.cube_ghosts import normal_reflectance, slab_reflectance
from rigsim.optics.meshes import figured_cube_mesh, screen_with_hole_mesh, tilt_cube_faces
from rigsim.render.frame import Frame, digitise
from rigsim.render.scene import Scene
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.truth.cube_mirror.diaphragm import (
    _EZ,
    DiaphragmGeometry,
    DiaphragmTruth,
    _perp_basis,
    _unit,
    diaphragm_geometry,
    true_cube_mesh,
)
from rigsim.truth.cube_mirror.placement import cube_pose
from rigsim.truth.cube_mirror.realization import Realization, realization_from_rig

__all__ = ["GeometryWarning", "DiaphragmGeometry", "DiaphragmTruth", "DiaphragmFrames", "DiaphragmRenderer",
           "diaphragm_geometry", "build_diaphragm_scene_dict", "screen_with_hole_mesh", "true_cube_mesh",
           "SaturationWarning", "preview_png", "export_diaphragm", "DEMO_TILT_ARCSEC", "spot_radiance",
           "cube_to_scene_matrix"]

BEAM_BEHIND_HOLE_MM = 0.01


# ------------------------------------------------------------------------------------------
# numpy geometry (no mitsuba)
# ------------------------------------------------------------------------------------------


# ------------------------------------------------------------------------------------------
# meshes
# ------------------------------------------------------------------------------------------


# ------------------------------------------------------------------------------------------
# Mitsuba scene dict
# ------------------------------------------------------------------------------------------

CONTENTS = ("spot", "hole", "both")


def _disk_matrix(centre, normal, radius: float) -> np.ndarray:
    """Mitsuba ``disk`` (unit disk in local xy, normal +z) → world, right-handed."""
    n = _unit(normal)
    e1, e2 = _perp_basis(n)
    M = np.eye(4)
    M[:3, 0] = radius * e1
    M[:3, 1] = radius * e2
    M[:3, 2] = n
    M[:3, 3] = centre
    return M


def perspective_to_world(cam) -> np.ndarray:
    """``to_world`` of Mitsuba's built-in ``perspective`` sensor for a :class:`~rigsim.optics.aiming.PosedCamera`:
    Mitsuba's camera-local frame is x left, y up, z forward, so x and y flip (det stays +1)."""
    M = np.eye(4)
    M[:3, 0] = -cam.R_world_from_cam[:, 0]
    M[:3, 1] = -cam.R_world_from_cam[:, 1]
    M[:3, 2] = cam.R_world_from_cam[:, 2]
    M[:3, 3] = cam.centre
    return M


def perspective_props(cam) -> dict:
    """``fov`` (deg, along x) and ``principal_point_offset_x/y`` (fractions of the film size; measured:
    +offset moves the principal point towards −u / −v) of the built-in ``perspective`` sensor."""
    return {
        "fov": math.degrees(2.0 * math.atan(cam.width / (2.0 * cam.f_px))),
        "fov_axis": "x",
        "principal_point_offset_x": (cam.width / 2.0 - 0.5 - cam.cx) / cam.width,
        "principal_point_offset_y": (cam.height / 2.0 - 0.5 - cam.cy) / cam.height,
    }


def cube_to_scene_matrix(geom: DiaphragmGeometry, pose_rad: dict) -> np.ndarray:
    """Ideal cube frame → scene (mm) at turntable pose ``pose_rad`` (true kinematics)."""
    cp = cube_pose(geom.rig, geom.real, pose_rad)
    M = cp.matrix4()
    M[:3, 3] = M[:3, 3] - geom.shift_mm
    return M


def scene_cube_mesh(rig: CubeMirrorRig, real: Realization):
    """The cube mesh the renderers use: the true cube (measured faces at their true normals), and
    with ``[effects.cube_ghosts]`` on, the faces opposite them at their true tilts too."""
    m = true_cube_mesh(rig, real)
    g = rig.effects.cube_ghosts
    if g.enabled:
        m = tilt_cube_faces(m, rig.cube.edge_mm, g.back_face_tilt_arcsec)
    fig = rig.effects.surface_figure
    if fig.enabled:
        m = figured_cube_mesh(m, rig.cube.edge_mm, {f: figure_coefficients(rig) for f in rig.procedure.faces},
                              grid=fig.grid)
    return m


def figure_coefficients(rig: CubeMirrorRig) -> tuple[float, float, float]:
    """(c, a, angle) of ``[effects.surface_figure]``'s h = −c(x² + y²) − a(x'² − y'²) (1/mm, rad): power
    PV s over the inscribed circle (radius ρ = edge/2) gives c = s/ρ² (sphere radius 1/(2c) = D²/(8s)),
    astigmatism PV p gives a = p/(2ρ²)."""
    fig = rig.effects.surface_figure
    rho2 = (0.5 * rig.cube.edge_mm) ** 2
    lam = 1e-6 * fig.wavelength_nm
    return (fig.power_pv_waves * lam / rho2, fig.astigmatism_pv_waves * lam / (2.0 * rho2),
            math.radians(fig.astigmatism_angle_deg))


def cube_reflectance(rig: CubeMirrorRig) -> float:
    """Power the cube returns at normal incidence: 1 (ideal mirror), or with ``[effects.cube_ghosts]``
    the bare glass cube's direct and internal reflections (:func:`slab_reflectance`). The renderers
    divide by it: the aiming camera's exposure is set on what comes back."""
    g = rig.effects.cube_ghosts
    if not g.enabled:
        return 1.0
    return slab_reflectance(normal_reflectance(g.refractive_index), g.internal_reflections)


def ghost_spot(geom: DiaphragmGeometry, pose_rad: dict, order: int) -> tuple[np.ndarray, float]:
    """Exact trace (Snell, Fresnel) of the beam's central ray through the glass cube of
    ``[effects.cube_ghosts]`` at ``pose_rad``: where its ``order``-th ghost (0: the direct reflection)
    lands on the screen, (s, t) mm from the hole, and the share of the beam's power it carries."""
    from scipy.spatial.transform import Rotation

    from rigsim.optics.cube import FACE_NORMALS
    from rigsim.optics.cube_ghosts import ghost_ray

    rig, real = geom.rig, geom.real
    g = rig.effects.cube_ghosts
    M = cube_to_scene_matrix(geom, pose_rad)
    R, t = M[:3, :3], M[:3, 3]
    face = geom.face
    n0 = np.asarray(FACE_NORMALS[face], float)
    back = {"+": "-", "-": "+"}[face[0]] + face[1]
    half = 0.5 * rig.cube.edge_mm
    nf = R @ _unit(real.R_cube_from_mount @ real.face_normals_mount[face])
    tb = np.radians(np.asarray(g.back_face_tilt_arcsec.get(back, [0.0, 0.0, 0.0]), float) / 3600.0)
    nb = R @ (Rotation.from_rotvec(tb).as_matrix() @ -n0)
    d = -geom.d_sun_rot
    p, dout, power = ghost_ray(geom.hole_scene - 100.0 * d, d, (R @ (half * n0) + t, nf),
                               (R @ (-half * n0) + t, nb), g.refractive_index, order)
    s = (geom.hole_scene[2] - p[2]) / dout[2]
    return (p + s * dout)[:2] - geom.hole_scene[:2], power


def figured_spot(geom: DiaphragmGeometry, pose_rad: dict) -> tuple[np.ndarray, np.ndarray]:
    """Exact trace of the beam's central ray off the ``[effects.surface_figure]`` face (its analytic
    normal where the ray meets it) to the screen: (s, t) mm from the hole; and the closed-form semi-axes
    (mm) of the returned pencil: r·(1 + 2L·κ±) with κ± = 2(c ± a) the principal curvatures, L the
    face → screen path (power alone: r·(1 + 2L/R), R = D²/(8s))."""
    from rigsim.optics.cube import FACE_NORMALS
    from rigsim.optics.meshes import face_basis

    rig, real = geom.rig, geom.real
    c, a, ang = figure_coefficients(rig)
    M = cube_to_scene_matrix(geom, pose_rad)
    R, t = M[:3, :3], M[:3, 3]
    n0 = np.asarray(FACE_NORMALS[geom.face], float)
    n_c = _unit(real.R_cube_from_mount @ real.face_normals_mount[geom.face])
    e1, e2 = face_basis(n_c, n0)
    centre = R @ (0.5 * rig.cube.edge_mm * n0) + t
    n, e1, e2 = R @ n_c, R @ e1, R @ e2
    d = -geom.d_sun_rot
    o = geom.hole_scene
    p = o + float((centre - o) @ n) / float(d @ n) * d
    x, y = (p - centre) @ e1, (p - centre) @ e2
    ca, sa = math.cos(ang), math.sin(ang)
    xp, yp = ca * x + sa * y, -sa * x + ca * y
    hx = -2 * c * x - 2 * a * (xp * ca + yp * sa)
    hy = -2 * c * y - 2 * a * (xp * sa - yp * ca)
    nl = _unit(n - hx * e1 - hy * e2)
    dr = d - 2.0 * (d @ nl) * nl
    L = (o[2] - p[2]) / dr[2]
    hit = p + L * dr
    r = geom.hole_radius_mm
    return hit[:2] - o[:2], np.array([r * (1 + 2 * L * 2 * (c + a)), r * (1 + 2 * L * 2 * (c - a))])


def spot_radiance(screen_reflectance: float, beam_irradiance: float) -> float:
    """Radiance of the screen where the (collimated, normally incident) beam lands: ρE/π."""
    return screen_reflectance * beam_irradiance / math.pi


def build_diaphragm_scene_dict(rig: CubeMirrorRig, real: Realization | None, pose_rad: dict, face_index: int = 0, *,
                               spp: int, mesh_dir=None, content: str = "spot", beam: str = "collimated",
                               divergence_full_angle_arcmin: float | None = None,
                               divergence_directions: int = 64, return_into_hole: str = "absorb",
                               beam_standoff_mm: float = 50.0, screen_reflectance: float = 0.9,
                               beam_irradiance: float = 1.0, hole_glow_ratio: float = 1.0,
                               view_azimuth_deg: float = 0.0, principal_point_px=None,
                               sampler: str = "independent", max_depth: int | None = None,
                               geometry: DiaphragmGeometry | None = None, film_binning: int = 1) -> dict:
    """Mitsuba scene dict (millimetres, origin at the face centre's null position) of the diaphragm
    rig at turntable pose ``pose_rad`` (true angles, ``{label: rad}``).

    ``content``: ``"spot"`` (beam, cube, screen: the reflected-spot image), ``"hole"`` (the hole
    glow alone: the paper's first image, spot blocked), ``"both"`` (for export/preview). Units of
    the rendered image: radiance, with the beam's irradiance ``beam_irradiance`` (on a plane
    normal to the beam); the spot's radiance is ρE/π (:func:`spot_radiance`), the hole glow's
    ``hole_glow_ratio`` times that. The dict only uses built-in plugins.

    ``film_binning`` = b > 1 renders onto a film of (width/b) × (height/b) pixels with the same field
    of view and principal point: each film pixel is a b × b block of camera pixels (same radiance
    units, b² times the light paths per film pixel for the same ``spp``).
    """
    from rigsim.render.backend import ensure_variant

    ensure_variant()
    import mitsuba as mi

    from rigsim.render.meshes import mesh_ply

    if content not in CONTENTS:
        raise ValueError(f"content = {content!r}: must be one of {CONTENTS}")
    if int(spp) != spp or spp < 1:
        raise ValueError(f"spp = {spp!r}: must be an integer >= 1")
    b = int(film_binning)
    if b != film_binning or b < 1:
        raise ValueError(f"film_binning = {film_binning!r}: must be an integer >= 1")
    if not (0.0 < screen_reflectance <= 1.0):
        raise ValueError(f"screen_reflectance = {screen_reflectance!r}: must be in (0, 1]")
    if not (beam_irradiance > 0 and math.isfinite(beam_irradiance)):
        raise ValueError(f"beam_irradiance = {beam_irradiance!r}: must be finite and > 0")
    if not (hole_glow_ratio >= 0 and math.isfinite(hole_glow_ratio)):
        raise ValueError(f"hole_glow_ratio = {hole_glow_ratio!r}: must be finite and >= 0")
    if int(divergence_directions) != divergence_directions or not (1 <= divergence_directions <= 4096):
        raise ValueError(f"divergence_directions = {divergence_directions!r}: must be an integer in [1, 4096]")
    if content == "both" and return_into_hole == "diffuse":
        raise ValueError("content='both' needs the real hole (return_into_hole='absorb'): the "
                         "'diffuse' fidelity mode has no hole to glow")
    geom = geometry if geometry is not None else diaphragm_geometry(
        rig, real, face_index, view_azimuth_deg=view_azimuth_deg, principal_point_px=principal_point_px,
        beam=beam, divergence_full_angle_arcmin=divergence_full_angle_arcmin,
        return_into_hole=return_into_hole, beam_standoff_mm=beam_standoff_mm)
    rig, real = geom.rig, geom.real
    ds = rig.diaphragm_screen
    T = mi.ScalarTransform4f
    cam = geom.camera
    if cam.width % b or cam.height % b:
        raise ValueError(f"film_binning = {b}: must divide the camera's {cam.width} × {cam.height} pixels")
    # the perspective sensor's fov and principal-point fractions are the same for the binned film
    film = {"type": "hdrfilm", "width": cam.width // b, "height": cam.height // b, "rfilter": {"type": "box"},
            "pixel_format": "luminance", "component_format": "float32"}
    sensor = {"type": "perspective", **perspective_props(cam), "near_clip": 1.0, "far_clip": 1.0e5,
              "to_world": T(perspective_to_world(cam)), "film": film,
              "sampler": {"type": sampler, "sample_count": int(spp)}}
    has_hole = geom.return_into_hole == "absorb" or content != "spot"
    screen_mesh = screen_with_hole_mesh(ds.width_mm, ds.height_mm, geom.hole_radius_mm if has_hole else None)
    screen_path = mesh_ply(screen_mesh, "diaphragm_screen", mesh_dir)
    S = np.eye(4)
    S[:3, 3] = geom.hole_scene  # local x, y = lab X', Y'; z = Z'; the mesh's front normal is −Z'
    L_spot = spot_radiance(screen_reflectance, beam_irradiance)
    ghosts = rig.effects.cube_ghosts
    n_beam = 1 if geom.beam == "collimated" else 2 * ((int(divergence_directions) + 1) // 2)
    if max_depth is None:
        # emitter → mirror → screen (connected to the sensor there): 3 vertices; every null beam
        # disk crossed on the way adds one (a pencil may cross the other n_beam − 1 disks when it
        # leaves, and in 'diffuse' mode the returning light crosses all n_beam disks); deeper
        # paths (screen → cube → screen, ~1e-4 of the spot, spread over centimetres) are not rendered
        max_depth = 3 + (n_beam - 1) + (n_beam if geom.return_into_hole == "diffuse" else 0)
        if ghosts.enabled:  # each internal reflection adds two vertices (back face, front face)
            max_depth += 2 * ghosts.internal_reflections
    d = {
        "type": "scene",
        "integrator": {"type": "ptracer", "max_depth": int(max_depth), "rr_depth": int(max_depth) + 1,
                       "hide_emitters": False},
        "sensor": sensor,
        "screen": {"type": "ply", "filename": str(screen_path), "face_normals": True, "to_world": T(S),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "uniform", "value": float(screen_reflectance)}}},
    }
    if content in ("spot", "both"):
        figured = rig.effects.surface_figure.enabled
        if ghosts.enabled or figured:
            cube_path = mesh_ply(scene_cube_mesh(rig, real), f"cube_effects_{rig.cube.edge_mm:g}mm", mesh_dir)
        else:
            cube_path = mesh_ply(true_cube_mesh(rig, real), f"cube_true_{rig.cube.edge_mm:g}mm", mesh_dir)
        if ghosts.enabled:  # a bare glass cube prism: Fresnel reflection, ghosts from the opposite face
            cube_bsdf = {"type": "dielectric", "int_ior": float(ghosts.refractive_index), "ext_ior": 1.0}
        else:
            cube_bsdf = {"type": "conductor", "material": "none"}
        # a figured face reflects along its analytic vertex normals (the flat faces' carry their planes')
        d["cube"] = {"type": "ply", "filename": str(cube_path), "face_normals": not figured,
                     "to_world": T(cube_to_scene_matrix(geom, pose_rad)), "bsdf": cube_bsdf}
        dirs, w = geom.beam_directions(n_beam)
        for k, (dk, wk) in enumerate(zip(dirs, w)):
            if geom.return_into_hole == "absorb":
                c = geom.hole_scene + BEAM_BEHIND_HOLE_MM * dk / dk[2]
            else:
                c = geom.hole_scene - geom.beam_standoff_mm * dk / dk[2]
            name = "beam" if n_beam == 1 else f"beam_{k:04d}"
            # null BSDF: light returning through the hole passes into the void (the simulator
            # is not modelled: black), and divergent pencils never block one another
            # nested keys become XML ids on export: keep them unique (not just "emitter")
            d[name] = {"type": "disk", "to_world": T(_disk_matrix(c, -dk, geom.hole_radius_mm)),
                       f"{name}_emitter": {"type": "directionalarea",
                                   "radiance": {"type": "uniform", "value": float(beam_irradiance * wk)}},
                       "bsdf": {"type": "null"}}
    if ghosts.enabled:  # the glow is as bright as the spot the cube actually returns (paper: about equal)
        L_spot *= cube_reflectance(rig)
    if content in ("hole", "both") and hole_glow_ratio > 0:
        d["hole_glow"] = {"type": "disk", "to_world": T(_disk_matrix(geom.hole_scene, -_EZ, geom.hole_radius_mm)),
                          "hole_glow_emitter": {"type": "area", "radiance": {"type": "uniform",
                                                                   "value": float(hole_glow_ratio * L_spot)}},
                          "bsdf": {"type": "null"}}
    return d


# ------------------------------------------------------------------------------------------
# measuring on the screen plane (numpy; used by tests, benchmarks and the pipeline)
# ------------------------------------------------------------------------------------------


# ------------------------------------------------------------------------------------------
# renderer
# ------------------------------------------------------------------------------------------

_WARN_FLAGS = {
    "beam_misses_face": "the beam's central ray misses cube face {face}: no valid return spot",
    "beam_clipped_by_face": "part of the beam misses cube face {face} (edge clipping): the spot is truncated",
    "spot_not_returned": "the beam reflected by face {face} does not come back to the screen",
    "spot_off_detector": "the reflected spot is off the aiming camera's detector",
    "spot_cut_by_edge": "the reflected spot is cut by the edge of the aiming camera's detector",
    "hole_off_detector": "the hole is off the aiming camera's detector",
    "hole_cut_by_edge": "the hole is cut by the edge of the aiming camera's detector",
    "beam_source_in_view": ("the 'diffuse'-mode beam disk is in the aiming camera's view and hides "
                            "part of the screen (increase beam_standoff_mm or view_angle_deg)"),
}


def _derived_seed(seed: int, stream: int) -> int:
    return int(np.random.SeedSequence([int(seed), 0xD1A9, int(stream)]).generate_state(1, dtype=np.uint32)[0])


@dataclass
class DiaphragmFrames:
    """The two aiming-camera images of one turntable pose (paper §3: hole first, spot blocked;
    then the spot). ``*_photons`` are the rendered expected photons per pixel of each source alone;
    ``hole`` / ``spot`` the digitised frames (``spot`` also holds the hole glow when the renderer's
    ``hole_glow_in_spot_frame`` is True, as on the real screen)."""

    pose_rad: dict
    seed: int
    hole_photons: np.ndarray
    spot_photons: np.ndarray
    hole: Frame
    spot: Frame
    truth: DiaphragmTruth
    flags: dict
    seconds: dict

    @property
    def sidecars(self) -> dict:
        return {"hole": self.hole.sidecar, "spot": self.spot.sidecar}

    def write(self, prefix) -> dict:
        """Write ``<prefix>_hole`` and ``<prefix>_spot`` (16-bit PNG + JSON sidecar each)."""
        prefix = Path(prefix)
        return {k: getattr(self, k).write(prefix.with_name(f"{prefix.name}_{k}")) for k in ("hole", "spot")}


class DiaphragmRenderer:
    """Aiming-camera frames of the diaphragm screen at turntable poses (seed 000 steps 2-3).

    Builds two Mitsuba scenes once (the spot scene: beam, cube, screen; the hole scene: the hole
    glow), renders a warm-up frame, and per pose only moves the cube: its vertex positions are
    recomputed in float64 and written through ``mi.traverse`` (Mitsuba meshes bake ``to_world``
    into their vertices and expose no ``to_world``); no rebuild, no recompile.

    Image units: photons per pixel over the exposure. ``spot_photons_per_px`` (default: half the
    full well, in photons) is the plateau of a normally lit spot; the hole glow's plateau is
    ``hole_glow_ratio`` times that.

    ``deterministic=True`` renders with one Dr.Jit thread: the ptracer splats into the film with
    float32 atomic adds, whose order (and so the last bit of ~15 % of the lit pixels, ~3e-7
    relative) varies between multi-threaded runs, and a last-bit change can flip a Poisson draw of
    the detector model. With one thread the same seed gives a bit-identical frame (tested); with
    ``False`` the frames agree only to that jitter but render faster on several cores.
    ``hole_glow_in_spot_frame`` (default: True with the real hole,
    False in the hole-less ``"diffuse"`` mode) adds the glow to the spot frame, as on the real
    screen where only the returned beam is blocked for the first image.
    """

    def __init__(self, rig: CubeMirrorRig, real: Realization | None = None, face_index: int = 0, *, spp: int = 16,
                 sampler: str = "multijitter", beam: str = "collimated",
                 divergence_full_angle_arcmin: float | None = None, divergence_directions: int = 64,
                 return_into_hole: str = "absorb", beam_standoff_mm: float = 50.0,
                 screen_reflectance: float = 0.9, spot_photons_per_px: float | None = None,
                 hole_glow_ratio: float = 1.0, hole_glow_in_spot_frame: bool | None = None,
                 view_azimuth_deg: float = 0.0, principal_point_px=None, detector=None, mesh_dir=None,
                 deterministic: bool = True, warmup: bool = True, spot_film_binning: int = 1,
                 sampler_count: int | None = None):
        from rigsim.render.backend import ensure_variant

        self.variant = ensure_variant()

        self.rig = rig
        self.real = real if real is not None else realization_from_rig(rig)
        self.face_index = int(face_index)
        self.geometry = diaphragm_geometry(
            rig, self.real, face_index, view_azimuth_deg=view_azimuth_deg, principal_point_px=principal_point_px,
            beam=beam, divergence_full_angle_arcmin=divergence_full_angle_arcmin,
            return_into_hole=return_into_hole, beam_standoff_mm=beam_standoff_mm)
        if int(spp) != spp or spp < 1:
            raise ValueError(f"spp = {spp!r}: must be an integer >= 1")
        self.spp = int(spp)
        self.sampler = sampler
        self.screen_reflectance = float(screen_reflectance)
        self.detector = detector if detector is not None else rig.aiming_camera.detector
        if spot_photons_per_px is None:
            spot_photons_per_px = 0.5 * self.detector.full_well_e / self.detector.quantum_efficiency
        if not (spot_photons_per_px > 0 and math.isfinite(spot_photons_per_px)):
            raise ValueError(f"spot_photons_per_px = {spot_photons_per_px!r}: must be finite and > 0")
        self.spot_photons_per_px = float(spot_photons_per_px)
        self.hole_glow_ratio = float(hole_glow_ratio)
        self.deterministic = bool(deterministic)
        if hole_glow_in_spot_frame is None:  # the real screen: yes; the hole-less fidelity mode: no
            hole_glow_in_spot_frame = return_into_hole == "absorb"
        self.hole_glow_in_spot_frame = bool(hole_glow_in_spot_frame)
        # point-symmetric quadrature: an even number of pencils
        self.divergence_directions = 2 * ((int(divergence_directions) + 1) // 2) if beam == "divergent" else 1
        # the samplers' built-in sample count (every render passes its own): ``sampler_count``
        self._opts = dict(spp=self.spp if sampler_count is None else int(sampler_count), mesh_dir=mesh_dir, divergence_directions=self.divergence_directions,
                          screen_reflectance=self.screen_reflectance, beam_irradiance=1.0,
                          hole_glow_ratio=self.hole_glow_ratio, sampler=sampler, geometry=self.geometry)
        # photons per pixel per unit rendered radiance
        self.photons_per_radiance = self.spot_photons_per_px / spot_radiance(self.screen_reflectance, 1.0)
        if rig.effects.cube_ghosts.enabled:
            self.photons_per_radiance /= cube_reflectance(rig)
        t0 = time.perf_counter()
        pose0 = dict(self.geometry.layout.null_pose_rad)
        cube = scene_cube_mesh(rig, self.real)
        self._cube_local = np.array(cube.vertices, float)
        self._cube_normals = np.array(cube.vertex_normals, float) if rig.effects.surface_figure.enabled else None
        # the render loop's elements: per frame only the cube moves (its vertices follow the pose)
        self.spot_film_binning = int(spot_film_binning)
        self._spot_scene = Scene.from_dict(self.scene_dict(pose0, "spot", film_binning=self.spot_film_binning),
                                           {"cube": self._cube_update})
        n_loaded = len(self._spot_scene.params["cube.vertex_positions"]) // 3
        if n_loaded != len(self._cube_local):
            raise RuntimeError(f"Mitsuba loaded {n_loaded} cube vertices, expected {len(self._cube_local)}")
        self._hole_scene = None
        if self.hole_glow_ratio > 0:
            self._hole_scene = Scene.from_dict(self.scene_dict(pose0, "hole"))
        self.build_seconds = time.perf_counter() - t0
        self.warmup_seconds = 0.0
        if warmup:
            t0 = time.perf_counter()
            self.render_photons(pose0, seed=0)
            self.warmup_seconds = time.perf_counter() - t0

    # -- scene --------------------------------------------------------------------------------
    def scene_dict(self, pose_rad: dict, content: str = "spot", film_binning: int = 1) -> dict:
        """The Mitsuba scene dict of this renderer at ``pose_rad`` (``content``: spot/hole/both)."""
        return build_diaphragm_scene_dict(self.rig, self.real, pose_rad, self.face_index, content=content,
                                          film_binning=film_binning, **self._opts)

    def _cube_update(self, state) -> dict:
        import mitsuba as mi

        M = cube_to_scene_matrix(self.geometry, state["pose"])
        v = self._cube_local @ M[:3, :3].T + M[:3, 3]
        out = {"cube.vertex_positions": mi.Float(v.astype(np.float32).ravel())}
        if self._cube_normals is not None:  # [effects.surface_figure]: the normals turn with the cube
            out["cube.vertex_normals"] = mi.Float((self._cube_normals @ M[:3, :3].T).astype(np.float32).ravel())
        return out

    def set_pose(self, pose_rad: dict) -> float:
        """Move the cube to turntable pose ``pose_rad`` (mi.traverse). Returns seconds taken."""
        t0 = time.perf_counter()
        self._spot_scene.update({"pose": pose_rad})
        return time.perf_counter() - t0

    # -- rendering ----------------------------------------------------------------------------
    def _render(self, scene: Scene, seed: int, spp: int | None = None) -> np.ndarray:
        arr = scene.render(seed=int(seed), spp=self.spp if spp is None else int(spp), single_thread=self.deterministic)
        return np.maximum(arr, 0.0) * self.photons_per_radiance

    def render_chunk(self, seed: int, spp: int) -> np.ndarray:
        """Photons per camera pixel of the spot scene at its current pose: ``spp`` samples, Mitsuba
        seed ``seed`` (one chunk of :mod:`rigsim.render.cube_mirror.pencil_chunks`), on the spot
        film (``spot_film_binning`` × coarser than the camera when that is > 1)."""
        arr = self._spot_scene.render(seed=int(seed), spp=int(spp), single_thread=self.deterministic)
        return np.maximum(arr, 0.0) * self.photons_per_radiance

    def render_photons(self, pose_rad: dict, seed: int = 0, *, hole: bool = True) -> tuple[np.ndarray, np.ndarray | None, dict]:
        """Expected photons per pixel of the spot alone and of the hole glow alone (Mitsuba
        Monte-Carlo noise included, no detector), and timings."""
        sec = {"update": self.set_pose(pose_rad)}
        t0 = time.perf_counter()
        spot = self._render(self._spot_scene, _derived_seed(seed, 1))
        b = self.spot_film_binning
        if b > 1:  # each binned film pixel's value on its b × b camera pixels
            spot = np.repeat(np.repeat(spot, b, axis=0), b, axis=1)
        sec["render_spot"] = time.perf_counter() - t0
        hole_img = None
        if hole:
            t0 = time.perf_counter()
            if self._hole_scene is not None:
                hole_img = self._render(self._hole_scene, _derived_seed(seed, 2))
            else:
                hole_img = np.zeros_like(spot)
            sec["render_hole"] = time.perf_counter() - t0
        return spot, hole_img, sec

    def render(self, pose_rad: dict, seed: int = 0, *, noiseless: bool = False) -> DiaphragmFrames:
        """Render both frames of ``pose_rad``; geometry problems become sidecar flags and
        :class:`GeometryWarning` s, saturation a flag and a :class:`SaturationWarning`."""
        if int(seed) != seed or seed < 0:
            raise ValueError(f"seed = {seed!r}: must be an integer >= 0")
        t_all = time.perf_counter()
        truth = self.geometry.trace(pose_rad)
        for k, msg in _WARN_FLAGS.items():
            if truth.flags.get(k):
                warnings.warn(msg.format(face=self.geometry.face), GeometryWarning, stacklevel=2)
        spot_ph, hole_ph, sec = self.render_photons(pose_rad, seed)
        t0 = time.perf_counter()
        spot_in = spot_ph + hole_ph if self.hole_glow_in_spot_frame else spot_ph
        settings = self.settings()
        frames = {}
        for name, photons, stream in (("hole", hole_ph, 3), ("spot", spot_in, 4)):
            tdict = truth.as_dict()
            tdict["frame"] = name
            tdict["frame_contains"] = (["hole_glow"] if name == "hole"
                                       else (["spot", "hole_glow"] if self.hole_glow_in_spot_frame else ["spot"]))
            gflags = dict(truth.flags)
            if name == "hole":  # no spot in this frame: spot flags do not apply
                for k in ("spot_off_detector", "spot_cut_by_edge", "spot_overlaps_hole"):
                    gflags[k] = False
            frames[name] = fr = digitise(
                photons, self.detector, seed=_derived_seed(seed, stream), noiseless=noiseless, frame_seed=int(seed),
                truth=tdict, truth_object=truth, render=settings, geometry_flags=gflags,
                pose={"true_angles_rad": dict(pose_rad),
                      "true_angles_deg": {k: math.degrees(v) for k, v in pose_rad.items()},
                      "face": self.geometry.face},
                sidecar_extra={"render_seeds": {"spot": _derived_seed(seed, 1), "hole": _derived_seed(seed, 2)},
                               "detector_seed": _derived_seed(seed, stream)})
            if fr.detector.saturated_pixels:
                warnings.warn(f"{name} frame: {fr.detector.saturated_pixels} saturated pixels (lower "
                              "spot_photons_per_px or the exposure)", SaturationWarning, stacklevel=2)
        sec["detector"] = time.perf_counter() - t0
        sec["total"] = time.perf_counter() - t_all
        flags = dict(truth.flags)
        flags["saturated_pixels"] = {k: f.detector.saturated_pixels for k, f in frames.items()}
        flags["saturated"] = bool(any(flags["saturated_pixels"].values()))
        return DiaphragmFrames(dict(pose_rad), int(seed), hole_ph, spot_ph, frames["hole"], frames["spot"], truth,
                               flags, sec)

    def settings(self) -> dict:
        g = self.geometry
        return {
            "primitive": "diaphragm_screen",
            "variant": self.variant,
            "integrator": "ptracer",
            "sampler": self.sampler,
            "spp": self.spp,
            "deterministic_single_thread": self.deterministic,
            "light_paths_per_frame": self.spp * g.camera.width * g.camera.height // self.spot_film_binning ** 2,
            "spot_film_binning": self.spot_film_binning,
            "sensor": "perspective (built-in)",
            "units": "millimetres; scene origin = measured face centre at its null pose",
            "beam": g.beam,
            "divergence_full_angle_rad": g.divergence_full_angle_rad,
            "divergence_directions": self.divergence_directions,
            "return_into_hole": g.return_into_hole,
            "beam_standoff_mm": g.beam_standoff_mm if g.return_into_hole == "diffuse" else None,
            "screen_reflectance": self.screen_reflectance,
            "spot_photons_per_px": self.spot_photons_per_px,
            "hole_glow_ratio": self.hole_glow_ratio,
            "hole_glow_in_spot_frame": self.hole_glow_in_spot_frame,
            "geometry": g.as_dict(),
        }


def preview_png(dn: np.ndarray, path, *, low_pct: float = 1.0, high_pct: float = 99.9, gamma: float = 0.5) -> Path:
    """8-bit preview of a uint16 frame: percentile stretch and a gamma so that faint and bright
    parts are both visible (for people, never for measurement)."""
    import cv2

    a = np.asarray(dn, float)
    lo, hi = np.percentile(a, [low_pct, high_pct])
    x = np.clip((a - lo) / max(hi - lo, 1e-12), 0.0, 1.0) ** gamma
    from rigsim.files.atomic import atomic_write_bytes

    path = Path(path)
    ok, enc = cv2.imencode(path.suffix or ".png", np.round(255.0 * x).astype(np.uint8))
    if not ok:
        raise OSError(f"OpenCV cannot encode a {path.suffix} preview for {path}")
    return atomic_write_bytes(path, enc.tobytes())


DEMO_TILT_ARCSEC = {"X": -260.0, "Y": 330.0}
"""Offset of the demo pose from face 0's null: the spot lands 2.6 mm from the hole, both whole."""


def export_diaphragm(rig: CubeMirrorRig, real: Realization | None = None, pose_rad: dict | None = None, *,
                     spp: int = 64, face_index: int = 0, mesh_dir=None, beam: str = "divergent",
                     divergence_directions: int = 64):
    """(scene dict, XML comments) for ``rigsim scene export``: beam, cube, screen and hole glow at
    ``pose_rad`` (default: the face's exact null pose + :data:`DEMO_TILT_ARCSEC`, so that the
    spot lies beside the hole). ``None`` if the rig has no diaphragm screen.

    ``beam="divergent"`` (default) is what the campaign renders: the sun simulator's full angle as
    ``divergence_directions`` pencils through the real hole, light returning into the hole lost
    (:class:`~rigsim.render.cube_mirror.aiming.ConcentricityRenderer` renders the same light field as
    a convolution of one pencil). ``"collimated"`` is the single parallel pencil."""
    if rig.diaphragm_screen is None or rig.aiming_camera is None:
        return None
    if beam not in ("divergent", "collimated"):
        raise ValueError(f"beam = {beam!r}: allowed divergent, collimated")
    real = real if real is not None else realization_from_rig(rig)
    geom = diaphragm_geometry(rig, real, face_index, beam=beam)
    demo = pose_rad is None
    if demo:
        pose_rad = dict(geom.layout.null_pose_rad)
        for k, v in DEMO_TILT_ARCSEC.items():
            pose_rad[k] = pose_rad.get(k, 0.0) + math.radians(v / 3600.0)
    d = build_diaphragm_scene_dict(rig, real, pose_rad, face_index, spp=spp, content="both", beam=beam,
                                   divergence_directions=divergence_directions, sampler="multijitter",
                                   mesh_dir=mesh_dir, geometry=geom)
    tr = geom.trace(pose_rad)
    pose_txt = ", ".join(f"{k} = {math.degrees(v):.6f} deg" for k, v in pose_rad.items())
    n_dir = 2 * ((int(divergence_directions) + 1) // 2)
    beam_txt = (f"beam: divergent, the sun simulator's full angle {rig.sun_simulator.collimation_full_angle_arcmin} "
                f"arcmin as {n_dir} parallel pencils through the hole (sunflower quadrature); light returning into "
                "the hole is lost - the campaign's aiming-camera frames are this light field"
                if beam == "divergent" else
                "beam: collimated, one parallel pencil (at the null its return falls back into the hole and vanishes)")
    notes = [
        f"rigsim diaphragm screen (seed 000), face {geom.face}; millimetres; origin = the face centre at "
        f"its exact null pose (lab point {np.round(geom.shift_mm, 6).tolist()} mm)",
        f"turntable pose (true angles) {pose_txt}" + (" = null pose + demo tilt "
                                                       f"{DEMO_TILT_ARCSEC} arcsec" if demo else ""),
        beam_txt,
        f"exact trace: spot offset from the hole {np.round(1e3 * tr.offset_mm, 4).tolist()} um (lab X', Y'); "
        f"hole at pixel {np.round(tr.hole_uv, 4).tolist()}, spot at {np.round(tr.spot_uv, 4).tolist()}",
        "integrator ptracer: the beam -> mirror -> screen path is a caustic (path tracing returns zero)",
        "sensor: the aiming camera (pinhole, no distortion); pixel values are screen radiance; the spot's "
        "radiance is reflectance * irradiance / pi, the hole glow's the same as a collimated spot's (paper: equally bright)",
    ]
    return d, notes
