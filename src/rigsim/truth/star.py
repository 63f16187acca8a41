"""Attitude sequences of a star sensor: inertial pointing, slews, random pointings.

An attitude is ``R_cam_from_icrs`` (v_cam = R @ v_icrs); the camera frame is rigsim's (x right
= +u, y down = +v, z boresight). ``pointing(ra, dec, roll)`` puts the boresight on (ra, dec) with
celestial north pointing up the image (−v) at roll 0, so east is to the left (−u), as on a sky
seen from inside; a positive roll turns the camera about its +z axis (the stars turn the other way
in the image).

Motion is a constant body angular velocity per frame, ``omega_cam_rad_s``: an attitude at time
offset τ from the frame's mid-exposure is ``exp(ω τ)ᵀ · R`` (``attitude_at``), which the renderer
uses for motion smear.

Which stars a star sensor sees in one frame, where, and how bright: the truth of a frame.

``StarSky(rig)`` holds the catalogue (Hp ≤ ``sky.magnitude_limit``, proper motion propagated to
``sky.epoch_year``) and the true camera. ``StarSky.field(R_cam_from_icrs, ...)`` returns a
:class:`StarField`: the stars whose image centre lies on the detector, their true directions in
the camera frame, their true image positions (distorted projection with the *true* intrinsics —
the mean over the exposure's sub-steps when motion smear is on) and their expected photons.

Radiometry: photons = Φ0·10^(−0.4 Hp) · A_pupil · τ · t_exp · cos θ, θ the field angle (the
entrance pupil seen obliquely; a point source has no cos⁴ law). Sky background per pixel:
Φ0·10^(−0.4 μ) · Ω_px[arcsec²] · A · τ · t (μ = ``sky.background_mag_per_arcsec2``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.optics.sky import (
    StarCatalogue,
    load_hipparcos,
    pointing,
    star_photons,
)

__all__ = ["AttitudeSequence", "pointing", "inertial", "slew", "random_pointings", "from_rig", "perturb",
           "StarField", "StarSky"]


@dataclass(frozen=True)
class AttitudeSequence:
    """``R_cam_from_icrs`` (N, 3, 3) at mid-exposure, times (N,) in s, body rates (N, 3) rad/s."""

    kind: str
    times_s: np.ndarray
    R_cam_from_icrs: np.ndarray
    omega_cam_rad_s: np.ndarray

    def __len__(self) -> int:
        return int(self.times_s.shape[0])

    def attitude_at(self, k: int, tau_s: float | np.ndarray) -> np.ndarray:
        """Attitude(s) of frame k at offset(s) τ from its mid-exposure; shape (..., 3, 3)."""
        tau = np.asarray(tau_s, dtype=float)
        rv = -tau[..., None] * self.omega_cam_rad_s[k]
        D = Rotation.from_rotvec(rv.reshape(-1, 3)).as_matrix().reshape(*tau.shape, 3, 3)
        return D @ self.R_cam_from_icrs[k]

    def subset(self, idx) -> "AttitudeSequence":
        return AttitudeSequence(self.kind, self.times_s[idx], self.R_cam_from_icrs[idx], self.omega_cam_rad_s[idx])


def perturb(R: np.ndarray, sigma_rad: float, rng: np.random.Generator) -> np.ndarray:
    """Apply independent small random rotations (σ per camera axis) to attitudes (N, 3, 3)."""
    R = np.asarray(R, dtype=float)
    if sigma_rad <= 0:
        return R.copy()
    rv = rng.normal(0.0, sigma_rad, size=R.shape[:-2] + (3,))
    D = Rotation.from_rotvec(rv.reshape(-1, 3)).as_matrix().reshape(R.shape)
    return D @ R


def inertial(ra_deg: float, dec_deg: float, roll_deg: float, n_frames: int, interval_s: float = 1.0,
             jitter_rad: float = 0.0, rng: np.random.Generator | None = None) -> AttitudeSequence:
    """Fixed pointing, optional per-frame jitter."""
    R = np.repeat(pointing(ra_deg, dec_deg, roll_deg)[None], n_frames, axis=0)
    if jitter_rad > 0:
        R = perturb(R, jitter_rad, rng if rng is not None else np.random.default_rng(0))
    return AttitudeSequence("inertial", np.arange(n_frames) * float(interval_s), R, np.zeros((n_frames, 3)))


def slew(ra_deg: float, dec_deg: float, roll_deg: float, n_frames: int, interval_s: float,
         rate_deg_s: float, direction_deg: float, roll_rate_deg_s: float = 0.0,
         jitter_rad: float = 0.0, rng: np.random.Generator | None = None) -> AttitudeSequence:
    """Constant-rate slew: the boresight moves at ``rate_deg_s`` towards the sky point first seen in
    image direction ``direction_deg`` (from +u towards +v), while the camera rolls at
    ``roll_rate_deg_s`` about its boresight. Constant body rate ω = rate·(z × d) + roll_rate·z."""
    phi = np.radians(direction_deg)
    d = np.array([np.cos(phi), np.sin(phi), 0.0])
    omega = np.radians(rate_deg_s) * np.cross([0.0, 0.0, 1.0], d) + np.radians(roll_rate_deg_s) * np.array([0.0, 0.0, 1.0])
    t = np.arange(n_frames) * float(interval_s)
    R0 = pointing(ra_deg, dec_deg, roll_deg)
    D = Rotation.from_rotvec(t[:, None] * omega[None, :]).as_matrix()
    R = np.einsum("nji,jk->nik", D, R0)  # exp(ω t)ᵀ R0
    if jitter_rad > 0:
        R = perturb(R, jitter_rad, rng if rng is not None else np.random.default_rng(0))
    return AttitudeSequence("slew", t, R, np.repeat(omega[None], n_frames, axis=0))


def random_pointings(n_frames: int, rng: np.random.Generator, interval_s: float = 1.0) -> AttitudeSequence:
    """Independent uniformly random attitudes (for sampling the sky)."""
    R = Rotation.random(n_frames, random_state=rng).as_matrix()
    return AttitudeSequence("random", np.arange(n_frames) * float(interval_s), R, np.zeros((n_frames, 3)))


def from_rig(seq, rng: np.random.Generator | None = None) -> AttitudeSequence:
    """The sequence described by a :class:`rigsim.rig.star.Sequence`."""
    rng = rng if rng is not None else np.random.default_rng(0)
    jit = np.radians(seq.jitter_arcsec / 3600.0)
    if seq.kind == "inertial":
        return inertial(seq.start_ra_deg, seq.start_dec_deg, seq.start_roll_deg, seq.n_frames,
                        seq.frame_interval_s, jit, rng)
    if seq.kind == "slew":
        return slew(seq.start_ra_deg, seq.start_dec_deg, seq.start_roll_deg, seq.n_frames,
                    seq.frame_interval_s, seq.slew_rate_deg_per_s, seq.slew_direction_deg,
                    seq.roll_rate_deg_per_s, jit, rng)
    return random_pointings(seq.n_frames, rng, seq.frame_interval_s)

# ------------------------------------------------------------------------------------------ (from field.py)
@dataclass(frozen=True)
class StarField:
    """Truth of one frame; arrays of length N (stars with their image centre on the detector)."""

    hip: np.ndarray
    mag: np.ndarray
    photons: np.ndarray          # expected photons of each star over the exposure (all sub-steps)
    dirs_icrs: np.ndarray        # (N, 3) catalogue directions at the observation epoch
    dirs_cam: np.ndarray         # (N, 3) true directions in the camera frame at mid-exposure
    uv: np.ndarray               # (N, 2) true image centroid (px): mean of the sub-step projections
    uv_substeps: np.ndarray      # (N, K, 2) projections at the K sub-exposures
    R_cam_from_icrs: np.ndarray  # (3, 3) mid-exposure attitude
    background_photons_per_px: float
    shape_hw: tuple[int, int]

    def __len__(self) -> int:
        return int(self.hip.shape[0])


class StarSky:
    """Catalogue + true camera + radiometry of a :class:`rigsim.rig.star.StarRig`."""

    def __init__(self, rig, catalogue: StarCatalogue | None = None):
        self.rig = rig
        s = rig.sensor
        cat = (catalogue if catalogue is not None else load_hipparcos()).brighter_than(rig.sky.magnitude_limit)
        self.catalogue = cat
        self.vectors = cat.unit_vectors(rig.sky.epoch_year)
        self.camera = s.camera()
        W, H = s.resolution_px
        # cone that holds every direction imaged on the detector (+ margin for smear / PSF)
        u0, v0 = s.principal_point_px
        corners = np.array([[-0.5, -0.5], [W - 0.5, -0.5], [-0.5, H - 0.5], [W - 0.5, H - 0.5]])
        d = self.camera.unproject(corners)
        self.cone_cos = float(np.cos(np.max(np.arccos(np.clip(d[:, 2], -1, 1))) + math.radians(1.0)))
        self.shape_hw = (H, W)
        det = s.detector
        self._phot = dict(zero_point_photons_per_s_cm2=rig.sky.zero_point_photons_per_s_cm2,
                          aperture_area_cm2=s.aperture_area_cm2, transmission=s.optics_transmission,
                          exposure_s=det.exposure_s)
        pix_arcsec = s.pixel_pitch_um * 1e-3 / s.focal_length_mm * 180.0 / math.pi * 3600.0
        self.background_photons_per_px = float(star_photons(rig.sky.background_mag_per_arcsec2, **self._phot)
                                               * pix_arcsec**2)
        self.exposure_s = det.exposure_s

    def photons(self, mag, cos_theta=1.0) -> np.ndarray:
        return star_photons(mag, **self._phot) * np.asarray(cos_theta, dtype=float)

    def in_cone(self, boresight_icrs: np.ndarray, cos_limit: float | None = None) -> np.ndarray:
        return np.flatnonzero(self.vectors @ boresight_icrs >= (self.cone_cos if cos_limit is None else cos_limit))

    def field(self, R_cam_from_icrs: np.ndarray, *, omega_cam_rad_s=None, substeps: int = 1,
              camera=None, margin_px: float = 0.0) -> StarField:
        """Stars imaged on the detector for one attitude (mid-exposure).

        With ``substeps`` > 1 and a body rate, the exposure is split into that many equal
        sub-exposures at offsets (i + ½)/K − ½ of ``exposure_s``; each carries 1/K of the photons.
        ``camera`` replaces the true camera (for predictions with other intrinsics).
        """
        R = np.asarray(R_cam_from_icrs, dtype=float)
        cam = self.camera if camera is None else camera
        idx = self.in_cone(R[2])
        v_icrs = self.vectors[idx]
        K = int(substeps)
        if K > 1 and omega_cam_rad_s is not None and np.any(np.asarray(omega_cam_rad_s) != 0):
            from scipy.spatial.transform import Rotation

            tau = ((np.arange(K) + 0.5) / K - 0.5) * self.exposure_s
            Ds = Rotation.from_rotvec(-tau[:, None] * np.asarray(omega_cam_rad_s, float)[None, :]).as_matrix()
            Rk = Ds @ R  # (K, 3, 3)
            d_sub = np.einsum("kij,nj->nki", Rk, v_icrs)
        else:
            d_sub = (v_icrs @ R.T)[:, None, :]
        uv_sub = cam.project(d_sub)
        uv = uv_sub.mean(axis=1)
        d_cam = v_icrs @ R.T
        ok = np.all(np.isfinite(uv_sub), axis=(1, 2)) & cam.on_detector(uv, margin_px)
        cos_t = np.clip(d_cam[:, 2], 0.0, 1.0)
        sel = np.flatnonzero(ok)
        cat = self.catalogue
        gi = idx[sel]
        return StarField(hip=cat.hip[gi], mag=cat.hp_mag[gi], photons=self.photons(cat.hp_mag[gi], cos_t[sel]),
                         dirs_icrs=v_icrs[sel], dirs_cam=d_cam[sel], uv=uv[sel], uv_substeps=uv_sub[sel],
                         R_cam_from_icrs=R, background_photons_per_px=self.background_photons_per_px,
                         shape_hw=self.shape_hw)
