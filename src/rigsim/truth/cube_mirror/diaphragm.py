"""True geometry of the seed-000 diaphragm screen: where the sun beam's disk and its cube-face
return land on the screen, seen by the aiming camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rigsim.errors import GeometryError
from rigsim.optics.aiming import PosedCamera, aiming_camera, screen_homography
from rigsim.optics.cube import FACE_NORMALS
from rigsim.optics.sun_disk import disk_directions
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.truth.cube_mirror.placement import (
    DiaphragmLayout,
    cube_pose,
    diaphragm_layout,
    face_in_rot,
    in_square_face,
    plane_hit,
    trace_return_spot,
)
from rigsim.truth.cube_mirror.realization import Realization, realization_from_rig

BEAM_MODES = ("collimated", "divergent")


RETURN_MODES = ("absorb", "diffuse")


_EZ = np.array([0.0, 0.0, 1.0])


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _perp_basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """e1, e2 with (e1, e2, d) right-handed orthonormal."""
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = _unit(np.cross(a, d))
    return e1, np.cross(d, e1)


@dataclass(frozen=True)
class DiaphragmTruth:
    """Exact trace (placement) of one turntable pose, projected through the aiming camera."""

    pose_rad: dict
    face: str
    tilt_rad: float
    on_face: bool  # central ray hits the face
    beam_on_face_fraction: float  # fraction of the beam's rim rays that hit the face
    returned: bool  # the reflected beam comes back to the screen plane
    spot_lab_mm: np.ndarray | None
    offset_mm: np.ndarray | None  # spot − hole in the screen plane, (X', Y') mm
    closed_form_offset_mm: float | None  # tan(2 tilt) × face→screen path
    spot_radius_mm: float  # outer radius of the returned spot on the screen (divergence included)
    hole_uv: np.ndarray  # projection of the hole centre (px)
    spot_uv: np.ndarray | None  # projection of the traced spot centre (px)
    hole_ellipse_uv: np.ndarray  # centre of the hole's image ellipse (perspective: ≠ hole_uv)
    spot_ellipse_uv: np.ndarray | None
    flags: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {
            "face": self.face, "pose_rad": self.pose_rad,
            "pose_deg": {k: math.degrees(v) for k, v in self.pose_rad.items()},
            "tilt_rad": self.tilt_rad, "tilt_arcsec": math.degrees(self.tilt_rad) * 3600.0,
            "on_face": self.on_face, "beam_on_face_fraction": self.beam_on_face_fraction,
            "returned": self.returned,
            "spot_lab_mm": self.spot_lab_mm, "offset_mm": self.offset_mm,
            "offset_um": None if self.offset_mm is None else 1e3 * np.asarray(self.offset_mm),
            "closed_form_offset_mm": self.closed_form_offset_mm,
            "spot_radius_mm": self.spot_radius_mm,
            "hole_center_uv": self.hole_uv, "spot_center_uv": self.spot_uv,
            "hole_ellipse_center_uv": self.hole_ellipse_uv, "spot_ellipse_center_uv": self.spot_ellipse_uv,
            "note": ("*_center_uv: exact projection of the traced centre; *_ellipse_center_uv: centre "
                     "of the projected outline (a perspective view of a circle is an ellipse whose "
                     "centre is not the projection of the circle's centre)"),
        }


def _conic_centre(Hmat: np.ndarray, centre_st, radius: float) -> np.ndarray:
    """Centre of the image of the circle (centre, radius) of the screen plane under homography H."""
    a, b = float(centre_st[0]), float(centre_st[1])
    C = np.array([[1.0, 0.0, -a], [0.0, 1.0, -b], [-a, -b, a * a + b * b - radius * radius]])
    Hi = np.linalg.inv(Hmat)
    Ci = Hi.T @ C @ Hi
    return -np.linalg.solve(Ci[:2, :2], Ci[:2, 2])


@dataclass(frozen=True)
class DiaphragmGeometry:
    """The diaphragm rig of one face, in scene millimetres (``p_scene = p_lab − shift_mm``)."""

    rig: CubeMirrorRig
    real: Realization
    face_index: int
    layout: DiaphragmLayout
    shift_mm: np.ndarray
    camera: PosedCamera
    H_screen_to_uv: np.ndarray  # homogeneous (s, t, 1) mm → (u, v, 1) px; s, t = lab X', Y' from the hole
    hole_radius_mm: float
    d_sun_rot: np.ndarray
    beam: str = "collimated"
    divergence_full_angle_rad: float = 0.0
    return_into_hole: str = "absorb"
    beam_standoff_mm: float = 50.0

    @property
    def face(self) -> str:
        return self.layout.face

    @property
    def hole_scene(self) -> np.ndarray:
        return self.layout.hole_centre_mm - self.shift_mm

    def to_scene(self, p_lab) -> np.ndarray:
        return np.asarray(p_lab, float) - self.shift_mm

    # -- screen plane <-> image ------------------------------------------------------------
    def screen_to_uv(self, st) -> np.ndarray:
        st = np.asarray(st, float)
        h = st @ self.H_screen_to_uv[:, :2].T + self.H_screen_to_uv[:, 2]
        return h[..., :2] / h[..., 2:3]

    def uv_to_screen(self, uv) -> np.ndarray:
        uv = np.asarray(uv, float)
        Hi = np.linalg.inv(self.H_screen_to_uv)
        u, v = uv[..., 0], uv[..., 1]  # element-wise: a (N, 2) @ (2, 3) product is slow for millions of pixels
        w = Hi[2, 0] * u + Hi[2, 1] * v + Hi[2, 2]
        return np.stack([(Hi[0, 0] * u + Hi[0, 1] * v + Hi[0, 2]) / w, (Hi[1, 0] * u + Hi[1, 1] * v + Hi[1, 2]) / w],
                        axis=-1)

    def screen_mm_per_px(self, uv=None) -> np.ndarray:
        """Local 2×2 Jacobian d(s, t)/d(u, v) at ``uv`` (default: the hole's image)."""
        uv = self.screen_to_uv([0.0, 0.0]) if uv is None else np.asarray(uv, float)
        e = 1e-3
        J = np.empty((2, 2))
        for k in range(2):
            d = np.zeros(2)
            d[k] = e
            J[:, k] = (self.uv_to_screen(uv + d) - self.uv_to_screen(uv - d)) / (2 * e)
        return J

    # -- truth -------------------------------------------------------------------------------
    def trace(self, pose_rad: dict, n_rim: int = 64) -> DiaphragmTruth:
        rig, real, lay = self.rig, self.real, self.layout
        r = self.hole_radius_mm
        hole_st = np.zeros(2)
        hole_uv = self.screen_to_uv(hole_st)
        hole_ell = _conic_centre(self.H_screen_to_uv, hole_st, r)
        flags = {}
        # central ray (placement's exact trace)
        try:
            sp = trace_return_spot(rig, real, lay, pose_rad)
            returned = True
        except GeometryError:
            sp = None
            returned = False
        # rim rays: does the whole beam hit the face? (placement only checks the central ray)
        centre, n = face_in_rot(rig, real, lay.face, pose_rad)
        cp = cube_pose(rig, real, pose_rad)
        d = self.d_sun_rot
        e1, e2 = _perp_basis(d)
        phi = np.linspace(0.0, 2.0 * math.pi, n_rim, endpoint=False)
        hits = 0
        for p in phi:
            o = lay.hole_centre_mm + r * (math.cos(p) * e1 + math.sin(p) * e2)
            try:
                h, s = plane_hit(o, -d, centre, n)
            except GeometryError:
                continue
            if s > 0 and float(-d @ n) < 0 and in_square_face(h, centre, n, rig.cube.edge_mm, cp.R):
                hits += 1
        frac = hits / n_rim
        on_face = bool(sp is not None and sp.on_face)
        flags["beam_misses_face"] = not on_face
        flags["beam_clipped_by_face"] = bool(on_face and frac < 1.0)
        flags["spot_not_returned"] = not returned
        spread = 0.0
        if self.beam == "divergent":
            # hole → face → screen path ≈ 2 × distance; the spot grows by path × tan(half angle)
            spread = 2.0 * rig.diaphragm_screen.distance_to_cube_mm * math.tan(self.divergence_full_angle_rad / 2.0)
        if not returned:
            flags.update(spot_off_detector=True, spot_cut_by_edge=False, spot_overlaps_hole=False)
            spot_rad = r + spread
            truth = DiaphragmTruth(dict(pose_rad), lay.face, float("nan"), on_face, frac, False, None, None, None,
                                   spot_rad, hole_uv, None, hole_ell, None, flags)
            self._hole_flags(flags)
            return truth
        incid = math.acos(min(1.0, abs(float(sp.reflected_dir @ lay.screen_normal))))
        spot_rad = r / math.cos(incid) + spread
        offset = np.asarray(sp.offset_mm, float)
        path = lay.z_screen_mm - sp.hit_on_face_mm[2]
        closed = math.tan(2.0 * sp.tilt_rad) * path
        spot_uv = self.screen_to_uv(offset)
        spot_ell = _conic_centre(self.H_screen_to_uv, offset, r)
        # outline flags of the spot (a circle of spot_rad on the screen, projected)
        ang = np.linspace(0.0, 2.0 * math.pi, 256, endpoint=False)
        rim = offset + spot_rad * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        rim_uv = self.screen_to_uv(rim)
        on = self.camera.on_detector(rim_uv)
        lo, hi = rim_uv.min(axis=0), rim_uv.max(axis=0)
        overlaps = (hi[0] >= -0.5 and lo[0] < self.camera.width - 0.5
                    and hi[1] >= -0.5 and lo[1] < self.camera.height - 0.5)
        flags["spot_off_detector"] = bool(not overlaps)
        flags["spot_cut_by_edge"] = bool(overlaps and not np.all(on))
        flags["spot_overlaps_hole"] = bool(self.return_into_hole == "absorb"
                                           and np.linalg.norm(offset) < spot_rad + r)
        self._hole_flags(flags)
        return DiaphragmTruth(dict(pose_rad), lay.face, float(sp.tilt_rad), on_face, frac, True,
                              np.asarray(sp.spot_mm, float), offset, float(closed), float(spot_rad),
                              hole_uv, spot_uv, hole_ell, spot_ell, flags)

    def _hole_flags(self, flags: dict) -> None:
        ang = np.linspace(0.0, 2.0 * math.pi, 256, endpoint=False)
        rim_uv = self.screen_to_uv(self.hole_radius_mm * np.stack([np.cos(ang), np.sin(ang)], axis=1))
        on = self.camera.on_detector(rim_uv)
        flags["hole_off_detector"] = bool(not np.any(on))
        flags["hole_cut_by_edge"] = bool(np.any(on) and not np.all(on))
        flags["beam_source_in_view"] = self.beam_source_in_view()

    def beam_source_in_view(self) -> bool:
        """Is a ``diffuse``-mode beam disk (``null`` BSDF, which blocks shadow rays) in the view?"""
        if self.return_into_hole != "diffuse":
            return False
        c = self.hole_scene - self.beam_standoff_mm * self.d_sun_rot
        e1, e2 = _perp_basis(self.d_sun_rot)
        ang = np.linspace(0.0, 2.0 * math.pi, 64, endpoint=False)
        rad = self.hole_radius_mm + self.beam_standoff_mm * math.tan(self.divergence_full_angle_rad / 2.0)
        pts = c + rad * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
        uv, ok = self.camera.project(np.vstack([pts, c]))
        if not np.any(ok):  # behind the camera
            return False
        lo, hi = uv[ok].min(axis=0), uv[ok].max(axis=0)
        return bool(hi[0] >= -0.5 and lo[0] < self.camera.width - 0.5
                    and hi[1] >= -0.5 and lo[1] < self.camera.height - 0.5)

    def beam_directions(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Unit vectors towards the simulator of the beam's pencils, and their weights (sum 1)."""
        if self.beam == "collimated":
            return self.d_sun_rot[None, :].copy(), np.ones(1)
        # a sunflower rule alone has a first moment (n = 16: the spot would move by 0.18 mm over
        # the 1.3 m return path); adding each direction's mirror image about the axis zeroes it
        d = self.d_sun_rot
        half = disk_directions(d, self.divergence_full_angle_rad, (int(n) + 1) // 2)
        mirror = 2.0 * (half @ d)[:, None] * d[None, :] - half
        dirs = np.vstack([half, mirror])
        return dirs, np.full(len(dirs), 1.0 / len(dirs))

    def as_dict(self) -> dict:
        return {
            "face": self.face, "face_index": self.face_index,
            "shift_mm": self.shift_mm, "scene_origin": "measured face centre at its exact null pose (lab frame)",
            "hole_lab_mm": self.layout.hole_centre_mm, "hole_scene_mm": self.hole_scene,
            "z_screen_lab_mm": self.layout.z_screen_mm, "null_pose_rad": self.layout.null_pose_rad,
            "hole_radius_mm": self.hole_radius_mm, "d_sun_rot": self.d_sun_rot,
            "H_screen_to_uv": self.H_screen_to_uv,
            "screen_coordinates": "s, t = lab X', Y' (mm) from the hole centre, in the screen plane",
            "camera": self.camera.as_dict(), "beam": self.beam,
            "divergence_full_angle_rad": self.divergence_full_angle_rad,
            "return_into_hole": self.return_into_hole, "beam_standoff_mm": self.beam_standoff_mm,
        }


def diaphragm_geometry(rig: CubeMirrorRig, real: Realization | None = None, face_index: int = 0, *,
                       view_azimuth_deg: float = 0.0, principal_point_px=None,
                       beam: str = "collimated", divergence_full_angle_arcmin: float | None = None,
                       return_into_hole: str = "absorb", beam_standoff_mm: float = 50.0) -> DiaphragmGeometry:
    """Lab geometry of the diaphragm rig for face ``face_index`` (numpy only)."""
    if rig.diaphragm_screen is None or rig.aiming_camera is None:
        raise GeometryError("this rig has no diaphragm screen / aiming camera (procedure.method != 'diaphragm')")
    if beam not in BEAM_MODES:
        raise ValueError(f"beam = {beam!r}: must be one of {BEAM_MODES}")
    if return_into_hole not in RETURN_MODES:
        raise ValueError(f"return_into_hole = {return_into_hole!r}: must be one of {RETURN_MODES}")
    if not (0.0 < beam_standoff_mm < 0.9 * rig.diaphragm_screen.distance_to_cube_mm):
        raise ValueError(f"beam_standoff_mm = {beam_standoff_mm!r}: must be in (0, 0.9 × distance_to_cube_mm)")
    real = real if real is not None else realization_from_rig(rig)
    lay = diaphragm_layout(rig, real, face_index)
    shift, _ = face_in_rot(rig, real, lay.face, lay.null_pose_rad)
    hole = lay.hole_centre_mm - shift
    cam = aiming_camera(rig.aiming_camera, hole, view_azimuth_deg=view_azimuth_deg, principal_point_px=principal_point_px)
    Hmat = screen_homography(cam, hole)
    div = 0.0
    if beam == "divergent":
        arcmin = rig.sun_simulator.collimation_full_angle_arcmin if divergence_full_angle_arcmin is None else divergence_full_angle_arcmin
        if not (0.0 < arcmin < 600.0):
            raise ValueError(f"divergence_full_angle_arcmin = {arcmin!r}: must be in (0, 600)")
        div = math.radians(arcmin / 60.0)
    return DiaphragmGeometry(rig, real, int(face_index), lay, np.asarray(shift, float), cam, Hmat,
                             0.5 * rig.diaphragm_screen.hole_diameter_mm, np.asarray(real.d_sun_rot, float),
                             beam, div, return_into_hole, float(beam_standoff_mm))


def true_cube_mesh(rig: CubeMirrorRig, real: Realization):
    """The cube mesh in its ideal frame with each measured face turned to its true normal.

    Each face is rotated about its ideal centre by the smallest rotation taking the nominal
    normal to ``R_cube_from_mount · real.face_normals_mount[face]`` — the plane that
    :func:`rigsim.truth.cube_mirror.placement.face_in_rot` traces against.
    """
    from scipy.spatial.transform import Rotation

    from rigsim.optics.meshes import cube_mesh

    m = cube_mesh(rig.cube.edge_mm)
    v = np.array(m.vertices, float)
    fn = np.array(m.face_normals, float)
    half = 0.5 * rig.cube.edge_mm
    for face, n_mount in real.face_normals_mount.items():
        n0 = FACE_NORMALS[face]
        n1 = _unit(real.R_cube_from_mount @ n_mount)
        axis = np.cross(n0, n1)
        s = np.linalg.norm(axis)
        if s < 1e-15:
            continue
        rot = Rotation.from_rotvec(axis / s * math.atan2(s, float(n0 @ n1))).as_matrix()
        tri = np.where(fn @ n0 > 0.999)[0]
        idx = np.unique(m.faces[tri].ravel())
        c = half * n0
        v[idx] = (v[idx] - c) @ rot.T + c
    import trimesh

    out = trimesh.Trimesh(vertices=v, faces=np.array(m.faces), process=False)
    return out


def rasterise_screen_disk(geom: DiaphragmGeometry, centre_st, radius_mm: float, *, ss: int = 16,
                          value: float = 1.0) -> np.ndarray:
    """Analytic image of a uniform-radiance disk of the screen plane: each pixel holds ``value``
    times the fraction of its (film) area whose back-projection onto the screen lies inside the
    disk (``ss × ss`` sub-samples in rim pixels). This is what a perfect renderer with a box pixel
    filter and Mitsuba's ``perspective`` (radiance) response produces."""
    cam = geom.camera
    centre_st = np.asarray(centre_st, float)
    ang = np.linspace(0.0, 2.0 * math.pi, 256, endpoint=False)
    rim = geom.screen_to_uv(centre_st + radius_mm * np.stack([np.cos(ang), np.sin(ang)], axis=1))
    u0 = max(0, int(math.floor(rim[:, 0].min())) - 2)
    u1 = min(cam.width - 1, int(math.ceil(rim[:, 0].max())) + 2)
    v0 = max(0, int(math.floor(rim[:, 1].min())) - 2)
    v1 = min(cam.height - 1, int(math.ceil(rim[:, 1].max())) + 2)
    img = np.zeros((cam.height, cam.width))
    if u1 < u0 or v1 < v0:
        return img
    vv, uu = np.mgrid[v0:v1 + 1, u0:u1 + 1]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(float)
    st = geom.uv_to_screen(uv)
    dist = np.linalg.norm(st - centre_st, axis=1)
    J = geom.screen_mm_per_px(geom.screen_to_uv(centre_st))
    diag = float(np.linalg.norm(np.abs(J).sum(axis=1)))  # screen size of one pixel, generous
    cov = (dist < radius_mm).astype(float)
    rimpx = np.abs(dist - radius_mm) < diag
    if np.any(rimpx):
        off = (np.arange(ss) + 0.5) / ss - 0.5
        ou, ov = np.meshgrid(off, off)
        sub = uv[rimpx][:, None, :] + np.stack([ou.ravel(), ov.ravel()], axis=1)[None, :, :]
        sst = geom.uv_to_screen(sub.reshape(-1, 2)).reshape(sub.shape)
        cov[rimpx] = np.mean(np.linalg.norm(sst - centre_st, axis=2) < radius_mm, axis=1)
    img[v0:v1 + 1, u0:u1 + 1] = value * cov.reshape(vv.shape)
    return img
