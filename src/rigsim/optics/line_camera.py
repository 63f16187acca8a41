"""Camera geometry and the exact forward model (truth) of seed 003.

Frames (docs/boresight.md): ``OTA`` — origin O at the camera's ideal lens, +Z towards the prism,
focal plane z = −F; ``HRC`` — Z from the CCD centre through O, ``R_ota_from_hrc = Rot_Y(−ω)``.

The loop of one CMOS (one *path*): the laser's emitter sits (through the transceiver's beam
splitter) at the focal-plane point ``e`` of the reference spot. The camera maps a focal-plane
point p to the object-space direction of the ray through O, ``û(p) ∝ (−p_x, −p_y, F')``, and back
(an ideal, distortion-free, in-focus camera of focal length F'). The beam leaves along
``û_out = û(e)``, is reflected by its prism facet (unit normal f, prism-fixed) into
``û_back = û_out − 2 (û_out·f) f`` and lands where the ray through O along ``û_back`` meets the
focal plane. Each path has its own facet, normal to its own beam at the reference: each path is
an autocollimator. A rotation about a facet's normal moves neither spot of that path — a plane
mirror is blind to it — but the two facets' normals are 2β ≈ 9.5° apart, so any rotation of the
camera (including one about Z_HRC) tilts at least one facet against its beam: that is what makes
γ observable, with lever arm L = Lc1 − Lc2 rather than F.

Perturbations: the camera's rotation against the prism ``E`` (R(reference HRC ← perturbed HRC),
intrinsic XYZ Euler angles α, β, γ — the paper's "XYZ 转序") and its focal-length change Δf. The
loop's focal length is ``F' = F + Δf / Kf`` (Kf, the paper's telecentric factor: eq 1 is this
model's first-order inverse; docs/boresight.md derives the physical meaning of Kf from the laser's
chief ray). All functions broadcast over a leading sample axis and use float64.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.frames import ARCSEC_PER_RAD, Rot_Y

__all__ = [
    "CameraGeometry",
    "rotation_xyz",
    "euler_xyz",
    "unit",
    "spots_uv",
    "facet_normals_ota",
    "loop_trace",
]


def unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rotation_xyz(alpha, beta, gamma) -> np.ndarray:
    """``Rx(α)·Ry(β)·Rz(γ)`` (intrinsic XYZ, scipy ``"XYZ"``), broadcasting over the angles."""
    a, b, g = np.broadcast_arrays(np.asarray(alpha, float), np.asarray(beta, float), np.asarray(gamma, float))
    ang = np.stack([a, b, g], axis=-1)
    return Rotation.from_euler("XYZ", ang.reshape(-1, 3)).as_matrix().reshape(*a.shape, 3, 3)


def euler_xyz(R: np.ndarray) -> np.ndarray:
    """(α, β, γ) with ``R = Rx(α)Ry(β)Rz(γ)``: α = atan2(−R23, R33), β = asin(R13),
    γ = atan2(−R12, R11) (closed form, vectorised; |β| < 90°). Returns shape (..., 3)."""
    R = np.asarray(R, dtype=float)
    a = np.arctan2(-R[..., 1, 2], R[..., 2, 2])
    b = np.arcsin(np.clip(R[..., 0, 2], -1.0, 1.0))
    g = np.arctan2(-R[..., 0, 1], R[..., 0, 0])
    return np.stack([a, b, g], axis=-1)


@dataclass(frozen=True)
class CameraGeometry:
    """Numbers of one camera (mm, rad, px), built from a :class:`~rigsim.rig.boresight.LineCamera`
    or directly (studies vary F, L and the tilts)."""

    name: str = "camera"
    focal_length_mm: float = 6000.0
    off_axis_rad: float = math.radians(6.0)
    telecentric_factor: float = 0.5
    pitch_mm: float = 0.010
    width_px: int = 5120
    height_px: int = 3840
    center_y_mm: tuple[float, float] = (500.0, -500.0)       # Lc1, Lc2
    tilt_rad: tuple[float, float] = (0.0, 0.0)                # θm1, θm2
    reference_xy_px: tuple[tuple[float, float], tuple[float, float]] = ((0.0, 0.0), (0.0, 0.0))  # A1, B1
    prism_pitch_rad: float = 0.0
    facet_distance_mm: float = 1000.0
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def from_rig(cls, cam) -> "CameraGeometry":
        return cls(name=cam.name, focal_length_mm=cam.focal_length_mm, off_axis_rad=math.radians(cam.off_axis_deg),
                   telecentric_factor=cam.telecentric_factor, pitch_mm=cam.pixel_pitch_um * 1e-3,
                   width_px=cam.detector_width_px, height_px=cam.detector_height_px,
                   center_y_mm=(cam.m1_center_y_mm, cam.m2_center_y_mm),
                   tilt_rad=(math.radians(cam.m1_tilt_deg), math.radians(cam.m2_tilt_deg)),
                   reference_xy_px=(tuple(cam.m1_reference_px), tuple(cam.m2_reference_px)),
                   prism_pitch_rad=math.radians(cam.prism_pitch_deg), facet_distance_mm=cam.facet_distance_mm)

    def with_(self, **kw) -> "CameraGeometry":
        """A copy with some fields changed (``with_(focal_length_mm=3000)``); the cache is fresh."""
        kw.setdefault("_cache", {})
        return replace(self, **kw)

    # -- derived numbers ---------------------------------------------------------------------
    @property
    def F(self) -> float:
        return self.focal_length_mm

    @property
    def L_mm(self) -> float:
        """Centre distance of the two detectors, L = Lc1 − Lc2 (the paper's 'Lc1 + Lc2' for unsigned distances)."""
        return self.center_y_mm[0] - self.center_y_mm[1]

    @property
    def cx(self) -> float:
        return (self.width_px - 1) / 2.0

    @property
    def cy(self) -> float:
        return (self.height_px - 1) / 2.0

    @property
    def centers_mm(self) -> np.ndarray:
        """A0, B0: detector centres in the focal plane (x, y), mm, shape (2, 2)."""
        x = self.F * math.tan(self.off_axis_rad)
        return np.array([[x, self.center_y_mm[0]], [x, self.center_y_mm[1]]])

    @property
    def beta_half_angle_rad(self) -> float:
        """β of eq 2: half the angle between OA0 and OB0."""
        a, b = (np.array([c[0], c[1], -self.F]) for c in self.centers_mm)
        return 0.5 * math.atan2(np.linalg.norm(np.cross(a, b)), float(a @ b))

    @property
    def R_ota_from_hrc(self) -> np.ndarray:
        return Rot_Y(-self.off_axis_rad)

    @property
    def R_prism_from_hrc(self) -> np.ndarray:
        """Design orientation of the camera frame in the prism frame (about Y)."""
        return Rot_Y(self.prism_pitch_rad)

    def _rot2(self, j: int) -> np.ndarray:
        c, s = math.cos(self.tilt_rad[j]), math.sin(self.tilt_rad[j])
        return np.array([[c, -s], [s, c]])

    # -- pixels <-> focal plane ----------------------------------------------------------------
    def uv_to_xy(self, uv) -> np.ndarray:
        """rigsim pixels (u, v) → the paper's centred detector coordinates (x, y)."""
        uv = np.asarray(uv, float)
        return uv - np.array([self.cx, self.cy])

    def xy_to_uv(self, xy) -> np.ndarray:
        xy = np.asarray(xy, float)
        return xy + np.array([self.cx, self.cy])

    def xy_to_focal(self, xy, tilt_rad=None) -> np.ndarray:
        """Eqs 8–11 (with the pixel size d): (..., 2 detectors, 2) px → focal-plane (x, y) mm."""
        xy = np.asarray(xy, float)
        t = self.tilt_rad if tilt_rad is None else tilt_rad
        out = np.empty(np.broadcast_shapes(xy.shape, (2, 2)))
        for j in range(2):
            c, s = math.cos(t[j]), math.sin(t[j])
            x, y = xy[..., j, 0], xy[..., j, 1]
            out[..., j, 0] = self.centers_mm[j, 0] + self.pitch_mm * (c * x - s * y)
            out[..., j, 1] = self.centers_mm[j, 1] + self.pitch_mm * (s * x + c * y)
        return out

    def focal_to_xy(self, P, tilt_rad=None) -> np.ndarray:
        """Inverse of :meth:`xy_to_focal`."""
        P = np.asarray(P, float)
        t = self.tilt_rad if tilt_rad is None else tilt_rad
        out = np.empty(np.broadcast_shapes(P.shape, (2, 2)))
        for j in range(2):
            c, s = math.cos(t[j]), math.sin(t[j])
            dx = (P[..., j, 0] - self.centers_mm[j, 0]) / self.pitch_mm
            dy = (P[..., j, 1] - self.centers_mm[j, 1]) / self.pitch_mm
            out[..., j, 0] = c * dx + s * dy
            out[..., j, 1] = -s * dx + c * dy
        return out

    @property
    def emitter_mm(self) -> np.ndarray:
        """Focal-plane points of the two laser emitters (= the reference points A1, B1), (2, 2) mm."""
        return self.xy_to_focal(np.array(self.reference_xy_px, float))

    @property
    def reference_uv(self) -> np.ndarray:
        """Design reference spots A1, B1 in rigsim pixels, (2, 2)."""
        return self.xy_to_uv(np.array(self.reference_xy_px, float))

    def roi_origin(self, detector: int, window_px: int) -> tuple[int, int]:
        """Detector pixel of the nominal ROI's pixel (0, 0): the ``window_px`` window centred on the
        design reference spot of ``detector`` (0 = M1, 1 = M2)."""
        ref = self.reference_uv[detector]
        return int(round(ref[0])) - window_px // 2, int(round(ref[1])) - window_px // 2


def facet_normals_ota(geom: CameraGeometry) -> np.ndarray:
    """Unit normals (pointing back at the camera) of the two prism facets in the reference OTA
    frame, shape (2, 3): each is normal to its own laser beam (autocollimation at the reference)."""
    e = geom.emitter_mm
    u_out = unit(np.column_stack([-e[:, 0], -e[:, 1], np.full(2, geom.F)]))
    return -u_out


def loop_trace(geom: CameraGeometry, E_hrc=None, delta_f_mm=0.0, emitter_mm=None,
               facet_normals=None) -> np.ndarray:
    """Exact in-focus loop: focal-plane landing points (..., 2 detectors, 2) in mm (OTA x, y).

    ``E_hrc`` (..., 3, 3): camera rotation against the prism (R(ref HRC ← perturbed HRC)); the
    prism-fixed facet normals, seen from the perturbed camera, are ``E_otaᵀ f``. ``delta_f_mm``
    (...): camera focal-length change; the loop's focal length is F + Δf/Kf. ``emitter_mm``
    (..., 2, 2) overrides the emitter points (default the design's)."""
    E = np.eye(3) if E_hrc is None else np.asarray(E_hrc, float)
    dF = np.asarray(delta_f_mm, float) / geom.telecentric_factor
    Fp = geom.F + dF
    C = geom.R_ota_from_hrc
    E_ota = C @ E @ C.T
    f0 = facet_normals_ota(geom) if facet_normals is None else np.asarray(facet_normals, float)
    e = geom.emitter_mm if emitter_mm is None else np.asarray(emitter_mm, float)
    batch = np.broadcast_shapes(E_ota.shape[:-2], Fp.shape, e.shape[:-2])
    out = np.empty(batch + (2, 2))
    for j in range(2):
        # facet normal in the perturbed camera frame: f = E_otaᵀ f0
        f = np.einsum("...ji,j->...i", E_ota, f0[j]) if f0.ndim == 2 else np.einsum("...ji,...j->...i", E_ota, f0[..., j, :])
        ex, ey = e[..., j, 0], e[..., j, 1]
        uo = np.stack(np.broadcast_arrays(-ex, -ey, Fp), axis=-1)
        uo = uo / np.linalg.norm(uo, axis=-1, keepdims=True)
        ub = uo - 2.0 * np.sum(uo * f, axis=-1, keepdims=True) * f
        out[..., j, 0] = Fp * ub[..., 0] / (-ub[..., 2])
        out[..., j, 1] = Fp * ub[..., 1] / (-ub[..., 2])
    return out


def spots_uv(geom: CameraGeometry, E_hrc=None, delta_f_mm=0.0, tilt_rad=None) -> np.ndarray:
    """Exact spot positions in rigsim pixels, shape (..., 2 detectors [M1, M2], 2 [u, v]).

    ``tilt_rad`` overrides the detectors' true tilts (θm1, θm2) used to turn focal-plane points
    into pixels (studies where the true tilt differs from the design)."""
    P = loop_trace(geom, E_hrc, delta_f_mm)
    return geom.xy_to_uv(geom.focal_to_xy(P, tilt_rad))


# ------------------------------------------------------------------------------ two cameras
def relative_rotation(E1: np.ndarray, E2: np.ndarray, geom1: CameraGeometry, geom2: CameraGeometry) -> np.ndarray:
    """Change of the angle between the two cameras, as a rotation in camera 1's HRC axes.

    With R(prism ← HRC_k) = R_k⁰·E_k (design orientation, measured rotation against the prism),
    R(C1 ← C2) = E1ᵀ·R1⁰ᵀ·R2⁰·E2; the returned ΔR = R(C1 ← C2)·R⁰(C1 ← C2)ᵀ is independent of the
    prism's own motion (it cancels). Shape (..., 3, 3)."""
    R0 = geom1.R_prism_from_hrc.T @ geom2.R_prism_from_hrc
    R = np.swapaxes(E1, -1, -2) @ R0 @ E2
    return R @ R0.T


def small_angles_arcsec(R: np.ndarray) -> np.ndarray:
    """Rotation vector (x, y, z) of R in arcsec (small angles: the per-axis angles)."""
    from scipy.spatial.transform import Rotation

    R = np.asarray(R, float)
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(*R.shape[:-2], 3) * ARCSEC_PER_RAD
