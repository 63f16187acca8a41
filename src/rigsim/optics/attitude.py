"""Attitudes of a star sensor: pointings and sequences (inertial, slew, random).

An attitude is ``R_cam_from_icrs`` (v_cam = R @ v_icrs); the camera frame is rigsim's (x right
= +u, y down = +v, z boresight). ``pointing(ra, dec, roll)`` puts the boresight on (ra, dec) with
celestial north up the image (−v) at roll 0, so east is to the left (−u), as on a sky seen from
inside; a positive roll turns the camera about its +z axis (the stars turn the other way in the
image). Motion is a constant body angular velocity per frame, ``omega_cam_rad_s``: the attitude
at time offset τ from a frame's mid-exposure is ``exp(ω τ)ᵀ · R`` (``attitude_at``).

A sequence built from a rig's ``[sequence]`` table without jitter is the *commanded* attitude:
what the spacecraft was told to do, known to the user. The true attitude (jitter, pointing error)
is :func:`rigsim.truth.star.true_sequence`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.optics.sky import radec_to_unit

__all__ = ["AttitudeSequence", "pointing", "boresight_radec", "perturb", "inertial", "slew", "random_pointings",
           "from_rig"]


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


def from_rig(seq, rng: np.random.Generator | None = None, *, jitter: bool = True) -> AttitudeSequence:
    """The sequence described by a rig's ``[sequence]`` table; ``jitter=False``: the commanded one
    (no attitude noise; a ``random`` sequence still draws its pointings from ``rng``)."""
    rng = rng if rng is not None else np.random.default_rng(0)
    jit = np.radians(seq.jitter_arcsec / 3600.0) if jitter else 0.0
    if seq.kind == "inertial":
        return inertial(seq.start_ra_deg, seq.start_dec_deg, seq.start_roll_deg, seq.n_frames,
                        seq.frame_interval_s, jit, rng)
    if seq.kind == "slew":
        return slew(seq.start_ra_deg, seq.start_dec_deg, seq.start_roll_deg, seq.n_frames,
                    seq.frame_interval_s, seq.slew_rate_deg_per_s, seq.slew_direction_deg,
                    seq.roll_rate_deg_per_s, jit, rng)
    return random_pointings(seq.n_frames, rng, seq.frame_interval_s)


def pointing(ra_deg: float, dec_deg: float, roll_deg: float = 0.0) -> np.ndarray:
    """R_cam_from_icrs with the boresight at (ra, dec), north up (−v) at roll 0."""
    ra, dec = np.radians(ra_deg), np.radians(dec_deg)
    z = radec_to_unit(ra, dec)
    east = np.array([-np.sin(ra), np.cos(ra), 0.0])
    north = np.array([-np.sin(dec) * np.cos(ra), -np.sin(dec) * np.sin(ra), np.cos(dec)])
    R0 = np.stack([-east, -north, z])  # rows: camera x, y, z in ICRS
    Rroll = Rotation.from_rotvec([0.0, 0.0, np.radians(roll_deg)]).as_matrix()
    return Rroll.T @ R0


def boresight_radec(R_cam_from_icrs) -> tuple[float, float]:
    z = np.asarray(R_cam_from_icrs)[..., 2, :]
    ra = np.degrees(np.mod(np.arctan2(z[..., 1], z[..., 0]), 2 * np.pi))
    dec = np.degrees(np.arcsin(np.clip(z[..., 2], -1, 1)))
    return ra, dec
