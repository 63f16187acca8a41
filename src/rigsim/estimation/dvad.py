"""Estimators of seed 003: the simplified method (eqs 1–4) and dual-vector attitude (DVAD, eqs 7–15).

Inputs are spot positions in rigsim pixels (u, v), shape (..., 2 detectors [M1, M2], 2): the
reference spots (A1, B1, measured at the reference state) and the measured spots (A2, B2). They
may come from rigsim's frames or from a user's own centroider. The estimators use the nominal
camera geometry only (:class:`~rigsim.optics.line_camera.CameraGeometry`), never truth. All
functions are vectorised over the leading axes (Monte Carlo, or real-time streams).

Two readings of the paper (docs/boresight.md gives every reason):

``"consistent"`` (default)
    * eq 2 with the sign of eqs 3, 4 and 14 (a right-handed rotation about X moves the spots
      towards −y);
    * eq 11 with the pixel size d; eq 12 as three unit column vectors;
    * DVAD's two vectors are the *facet normals*, n = normalize(û_out − û_back) — the bisector of the
      outgoing beam (from the laser's emitter, which sits at the design reference point) and the
      returning beam (to the measured spot). The paper's factor ½ in eq 14 is the first-order form
      of this bisector; with it, M_Rot = Mt·M0ᵀ is exactly the camera's rotation;
    * eq 14 as an exact change of frame (OTA → HRC, a rotation by ω about Y) and exact XYZ Euler
      angles (no ½, no small-angle ratios);
    * Δf: eq 15 with eq 1's form and sign as the first guess, then refined exactly from the
      prism's rigidity (the angle between the two facet normals cannot change, so the loop focal
      length F' that keeps it is the true one), Δf = Kf·(F' − F).
    The round trip truth → exact forward model → DVAD is exact (tested ≤ 1e-9 rad).

    The consistent DVAD inverts a loop model (``loop_model``, :mod:`rigsim.optics.loop_models`):
    ``"physical"`` (default) as above; ``"paper"`` takes Δf from eq 15 alone (the paper's loop moves
    the spots in y only, so there is nothing to refine and no x motion to separate from β), removes
    its antisymmetric y shift from the spots and solves the rotation from the facet normals at F.

``"as_printed"``
    The printed formulas wherever they can be evaluated: eq 2's sign, DVAD on the spot vectors
    (eq 11) with the ½ and the ratios of eq 14, eq 14's ω mixing ``[[cos ω, sin ω], [sin ω, cos ω]]``
    (not a rotation), eq 15's sign. Two printed formulas cannot be evaluated as printed and get
    the minimal repair: eq 11 adds pixels to millimetres (d inserted) and eq 15 divides F by a
    product (the quotient arranged as in eq 1, the sign kept).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rigsim.frames import ARCSEC_PER_RAD
from rigsim.optics.line_camera import CameraGeometry, euler_xyz, rotation_xyz
from rigsim.optics.loop_models import check_loop_model

__all__ = ["BoresightEstimate", "DVADSolver", "READINGS", "METHODS", "simplified", "dvad", "estimate",
           "triad_columns"]

READINGS = ("consistent", "as_printed")
METHODS = ("dvad", "simplified")


@dataclass
class BoresightEstimate:
    """(Δf, α, β, γ) per sample: α, β, γ are the camera's rotation against the prism about X_HRC,
    Y_HRC, Z_HRC (intrinsic XYZ Euler angles of R(reference ← perturbed)); Δf its focal-length change."""

    delta_f_mm: np.ndarray
    alpha_rad: np.ndarray
    beta_rad: np.ndarray
    gamma_rad: np.ndarray
    method: str
    reading: str
    R_hrc: np.ndarray | None = None          # (..., 3, 3) rotation, when the method gives one
    info: dict = field(default_factory=dict)

    @property
    def angles_rad(self) -> np.ndarray:
        return np.stack([self.alpha_rad, self.beta_rad, self.gamma_rad], axis=-1)

    @property
    def angles_arcsec(self) -> np.ndarray:
        return self.angles_rad * ARCSEC_PER_RAD

    def rotation(self) -> np.ndarray:
        """The camera rotation R(ref HRC ← perturbed HRC): DVAD's matrix, or Rx·Ry·Rz of the angles."""
        if self.R_hrc is not None:
            return self.R_hrc
        return rotation_xyz(self.alpha_rad, self.beta_rad, self.gamma_rad)

    def as_dict(self, index=None) -> dict:
        sel = (lambda a: np.asarray(a)[index]) if index is not None else np.asarray
        return {"method": self.method, "reading": self.reading,
                "delta_f_um": (sel(self.delta_f_mm) * 1e3).tolist(),
                "alpha_arcsec": (sel(self.alpha_rad) * ARCSEC_PER_RAD).tolist(),
                "beta_arcsec": (sel(self.beta_rad) * ARCSEC_PER_RAD).tolist(),
                "gamma_arcsec": (sel(self.gamma_rad) * ARCSEC_PER_RAD).tolist()}


def _check(geom: CameraGeometry, ref_uv, meas_uv, reading: str):
    if reading not in READINGS:
        raise ValueError(f"reading = {reading!r}: allowed {READINGS}")
    ref = np.asarray(ref_uv, dtype=float)
    meas = np.asarray(meas_uv, dtype=float)
    for name, a in (("ref_uv", ref), ("meas_uv", meas)):
        if a.shape[-2:] != (2, 2):
            raise ValueError(f"{name} must have shape (..., 2 detectors, 2 [u, v]), got {a.shape}")
    return geom.uv_to_xy(ref), geom.uv_to_xy(meas)


# ------------------------------------------------------------------------------ simplified
def simplified(geom: CameraGeometry, ref_uv, meas_uv, reading: str = "consistent") -> BoresightEstimate:
    """Eqs 1–4: small angles, rotation order ignored, detector tilts ignored (the paper's method)."""
    ref, meas = _check(geom, ref_uv, meas_uv, reading)
    d, F, Kf = geom.pitch_mm, geom.F, geom.telecentric_factor
    L = geom.L_mm if reading == "consistent" else abs(geom.center_y_mm[0]) + abs(geom.center_y_mm[1])
    dx1 = meas[..., 0, 0] - ref[..., 0, 0]
    dy1 = meas[..., 0, 1] - ref[..., 0, 1]
    dx2 = meas[..., 1, 0] - ref[..., 1, 0]
    dy2 = meas[..., 1, 1] - ref[..., 1, 1]
    cb2 = math.cos(geom.beta_half_angle_rad) ** 2
    cw2 = math.cos(geom.off_axis_rad) ** 2
    delta_f = Kf * ((dy1 - dy2) * d / 2.0) * F / L                                    # eq 1
    alpha = np.arctan(((dy1 + dy2) * d / 2.0) * cb2 / (2.0 * F))                     # eq 2 as printed
    if reading == "consistent":
        alpha = -alpha                                                                 # sign of eqs 3, 4, 14
    beta = np.arctan(((dx1 + dx2) * d / 2.0) * cw2 / (2.0 * F))                       # eq 3
    gamma = np.arctan(((dx1 - dx2) * d / 2.0) / L)                                    # eq 4
    return BoresightEstimate(delta_f, alpha, beta, gamma, "simplified", reading)


# ------------------------------------------------------------------------------ DVAD
def triad_columns(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Eq 12 read as three unit *columns*: [a×b/|a×b|, (a+b)/|a+b|, (a×b)/|a×b| × (a+b)/|a+b|]."""
    c1 = np.cross(a, b)
    c1 = c1 / np.linalg.norm(c1, axis=-1, keepdims=True)
    c2 = a + b
    c2 = c2 / np.linalg.norm(c2, axis=-1, keepdims=True)
    c3 = np.cross(c1, c2)
    return np.stack([c1, c2, c3], axis=-1)


def _vectors(P: np.ndarray, Fp) -> np.ndarray:
    """Eq 11: v'' = (x, y, −F') for focal-plane points P (..., 2)."""
    Fp = np.asarray(Fp, float)
    return np.stack(np.broadcast_arrays(P[..., 0], P[..., 1], -Fp), axis=-1)


def dvad(geom: CameraGeometry, ref_uv, meas_uv, reading: str = "consistent", *,
         iterations: int = 3, loop_model: str = "physical") -> BoresightEstimate:
    """Eqs 7–15 (dual-vector attitude). See the module docstring for the two readings.

    ``iterations``: fixed-point steps of the rigidity equation for F' (consistent reading); the
    eq-15 start is good to second order, so 2–3 steps reach machine precision (tested).
    ``loop_model``: the loop the consistent reading inverts (the printed DVAD has its own)."""
    check_loop_model(loop_model)
    ref, meas = _check(geom, ref_uv, meas_uv, reading)
    F, Kf, w = geom.F, geom.telecentric_factor, geom.off_axis_rad
    P_ref = geom.xy_to_focal(ref)                       # eqs 8–11 (with d), nominal tilts
    P_meas = geom.xy_to_focal(meas)
    if reading == "as_printed":
        vr = _vectors(P_ref, F)
        vm = _vectors(P_meas, F)
        M0 = triad_columns(vr[..., 0, :], vr[..., 1, :])
        Mt = triad_columns(vm[..., 0, :], vm[..., 1, :])
        M = Mt @ np.swapaxes(M0, -1, -2)                 # eq 13
        rx = -M[..., 2, 1] / M[..., 2, 2]
        rz = -M[..., 1, 0] / M[..., 0, 0]
        alpha = 0.5 * (rx * math.cos(w) + rz * math.sin(w))        # eq 14 as printed
        beta = 0.5 * M[..., 2, 0] / np.sqrt(1.0 - M[..., 2, 0] ** 2)
        gamma = 0.5 * (rx * math.sin(w) + rz * math.cos(w))
        dy = (P_meas[..., 0, 1] - P_ref[..., 0, 1]) - (P_meas[..., 1, 1] - P_ref[..., 1, 1])
        delta_f = -(Kf / 2.0) * F * dy / (P_ref[..., 0, 1] - P_ref[..., 1, 1])   # eq 15, sign kept
        return BoresightEstimate(delta_f, alpha, beta, gamma, "dvad", reading, None,
                                 {"M_rot_ota": M})
    # consistent reading
    sol = DVADSolver(geom, ref_uv, iterations=iterations, loop_model=loop_model)
    return sol.solve(meas_uv)


def _unit3(x, y, z):
    r = 1.0 / np.sqrt(x * x + y * y + z * z)
    return x * r, y * r, z * r


def _cross3(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


class DVADSolver:
    """The consistent DVAD with the reference part computed once (real time, vectorised).

    ``ref_uv`` (2, 2) or (..., 2, 2). :meth:`solve` takes measured spots (..., 2, 2) and returns a
    :class:`BoresightEstimate`. Arithmetic is done on component arrays (x, y, z) — the same algorithm
    as described in the module docstring:

    1. eqs 8–11: spots → focal-plane points P (nominal tilts, pixel size d);
    2. facet normals n_j(F') = normalize(û(P_j, F') − û(e_j, F')), û the unit vector from O to the
       focal-plane point at −F' (return beam) and from the emitter point (outgoing beam, reversed);
    3. F' from the prism's rigidity, n_A(F')·n_B(F') = n_A⁰·n_B⁰: eq 15 (eq 1's form and sign) as
       the start, then fixed-point steps with the reference slope d(n_A·n_B)/dF';
    4. eq 12 (unit columns) in the HRC frame, M_Rot = Mt·M0ᵀ → the camera rotation
       E = R(ref HRC ← perturbed HRC) = M0_hrc·Mt_hrcᵀ; XYZ Euler angles; Δf = Kf·(F' − F).

    ``loop_model="paper"`` replaces step 3: F' − F = F·(Δy1 − Δy2)/(2L) (eq 15 in eq 1's form, no
    refinement); the spots' y displacements are replaced by their mean (the paper's loop puts Δf
    in their difference only) and the normals are taken at F.
    """

    def __init__(self, geom: CameraGeometry, ref_uv=None, *, iterations: int = 3, loop_model: str = "physical"):
        self.geom = geom
        self.iterations = int(iterations)
        self.loop_model = check_loop_model(loop_model)
        ref = np.asarray(geom.reference_uv if ref_uv is None else ref_uv, dtype=float)
        if ref.shape[-2:] != (2, 2):
            raise ValueError(f"ref_uv must have shape (..., 2 detectors, 2 [u, v]), got {ref.shape}")
        F = geom.F
        C = geom.R_ota_from_hrc
        self._CT = C.T                                   # OTA -> HRC
        e = geom.emitter_mm
        self._e = e
        self._ee = (e[0, 0] ** 2 + e[0, 1] ** 2, e[1, 0] ** 2 + e[1, 1] ** 2)
        P0 = geom.xy_to_focal(geom.uv_to_xy(ref))
        self._P0y = (P0[..., 0, 1], P0[..., 1, 1])
        nA, nB = self._normals(P0, F)
        self._cos0 = nA[0] * nB[0] + nA[1] * nB[1] + nA[2] * nB[2]
        h = 1e-3 * F
        cp = self._cos_at(P0, F + h)
        cm = self._cos_at(P0, F - h)
        self._slope = (cp - cm) / (2.0 * h)
        self._A = self._triad_hrc(nA, nB)                # M0 in HRC: columns c1, c2, c3

    # -- pieces ------------------------------------------------------------------------------
    def _normals(self, P, Fp):
        out = []
        for j in (0, 1):
            px, py = P[..., j, 0], P[..., j, 1]
            rb = 1.0 / np.sqrt(px * px + py * py + Fp * Fp)
            ro = 1.0 / np.sqrt(self._ee[j] + Fp * Fp)
            ex, ey = self._e[j]
            # n = û_back − û_out, û_back = (px, py, −F')/|.|, û_out = (−ex, −ey, F')/|.|
            out.append(_unit3(px * rb + ex * ro, py * rb + ey * ro, -Fp * (rb + ro)))
        return out

    def _cos_at(self, P, Fp):
        a, b = self._normals(P, Fp)
        return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]

    def _triad_hrc(self, a, b):
        CT = self._CT
        def to_hrc(v):
            return tuple(CT[i, 0] * v[0] + CT[i, 1] * v[1] + CT[i, 2] * v[2] for i in range(3))
        a, b = to_hrc(a), to_hrc(b)
        c1 = _unit3(*_cross3(a, b))
        c2 = _unit3(a[0] + b[0], a[1] + b[1], a[2] + b[2])
        c3 = _cross3(c1, c2)
        return (c1, c2, c3)

    # -- solve -------------------------------------------------------------------------------
    def solve(self, meas_uv) -> BoresightEstimate:
        g = self.geom
        meas = np.asarray(meas_uv, dtype=float)
        if meas.shape[-2:] != (2, 2):
            raise ValueError(f"meas_uv must have shape (..., 2 detectors, 2 [u, v]), got {meas.shape}")
        F, Kf = g.F, g.telecentric_factor
        P = g.xy_to_focal(g.uv_to_xy(meas))
        # eq 15 with eq 1's form and sign, as the loop focal change dF' = Δf/Kf
        dy = (P[..., 0, 1] - self._P0y[0]) - (P[..., 1, 1] - self._P0y[1])
        if self.loop_model == "paper":
            dF = 0.5 * F * dy / g.L_mm
            P = P.copy()
            P[..., 0, 1] -= 0.5 * dy
            P[..., 1, 1] += 0.5 * dy
            Fn = F + np.zeros_like(dF)
        else:
            dF = 0.5 * F * dy / (self._P0y[0] - self._P0y[1])
            for _ in range(self.iterations):
                dF = dF - (self._cos_at(P, F + dF) - self._cos0) / self._slope
            Fn = F + dF
        a, b = self._normals(P, Fn)
        resid = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] - self._cos0
        B = self._triad_hrc(a, b)
        A = self._A
        # E = M0_hrc · Mt_hrcᵀ: E_ij = Σ_k A_k[i] B_k[j]
        E = np.empty(np.broadcast_shapes(np.shape(B[0][0]), np.shape(A[0][0])) + (3, 3))
        for i in range(3):
            for j in range(3):
                E[..., i, j] = A[0][i] * B[0][j] + A[1][i] * B[1][j] + A[2][i] * B[2][j]
        ang = euler_xyz(E)
        return BoresightEstimate(Kf * dF, ang[..., 0], ang[..., 1], ang[..., 2], "dvad", "consistent", E,
                                 {"loop_focal_change_mm": dF, "rigidity_residual_cos": resid})


def estimate(geom: CameraGeometry, ref_uv, meas_uv, method: str = "dvad", reading: str = "consistent",
             **kw) -> BoresightEstimate:
    """``method`` on the spots: DVAD (keywords ``iterations``, ``loop_model``) or the simplified eqs 1–4
    (which assume the paper's loop by construction and take no keywords but ``loop_model``)."""
    if method == "dvad":
        return dvad(geom, ref_uv, meas_uv, reading, **kw)
    if method == "simplified":
        check_loop_model(kw.pop("loop_model", "physical"))
        return simplified(geom, ref_uv, meas_uv, reading)
    raise ValueError(f"method = {method!r}: allowed {METHODS}")

