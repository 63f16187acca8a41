"""The truth of the star sensor's frames: the true attitude sequence (the commanded one with its
pointing error and jitter) and, per frame, which stars the true camera images, where, how bright.

``StarSky(rig)`` holds the catalogue (Hp ≤ ``sky.magnitude_limit``, proper motion propagated to
``sky.epoch_year``) and the true camera. ``StarSky.field(R_cam_from_icrs, ...)`` returns a
:class:`StarField`: the stars whose image centre lies on the detector, their true directions in
the camera frame, their true image positions (distorted projection with the *true* intrinsics,
averaged over the exposure's sub-steps when motion smear is on) and their expected photons.
Radiometry: docs/star_calibration.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.optics.attitude import AttitudeSequence, perturb
from rigsim.optics.sky import SkyCatalogue, StarCatalogue, field_cone_cos, star_photons

__all__ = ["StarField", "StarSky", "true_sequence"]


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
    bv: np.ndarray | None = None  # (N,) catalogue colour B−V (mag) of each star (the traced PSF's spectrum)

    def __len__(self) -> int:
        return int(self.hip.shape[0])

    def as_dict(self) -> dict:
        """The frame's truth for its sidecar (JSON-able)."""
        return {"R_cam_from_icrs": self.R_cam_from_icrs.tolist(), "hip": self.hip.tolist(), "mag": self.mag.tolist(),
                "photons": self.photons.tolist(), "uv": self.uv.tolist(),
                "background_photons_per_px": self.background_photons_per_px}


class StarSky:
    """Catalogue + true camera + radiometry of a :class:`rigsim.rig.star.StarRig`."""

    def __init__(self, rig, catalogue: StarCatalogue | None = None, *, sky: SkyCatalogue | None = None):
        self.rig = rig
        s = rig.sensor
        self.sky = sky if sky is not None else SkyCatalogue.load(rig.sky.magnitude_limit, rig.sky.epoch_year, catalogue)
        self.catalogue = self.sky.catalogue
        self.vectors = self.sky.vectors
        self.camera = s.camera()
        W, H = s.resolution_px
        # cone that holds every direction imaged on the detector (+ margin for smear / PSF)
        self.cone_cos = field_cone_cos(self.camera)
        self.shape_hw = (H, W)
        det = s.detector
        self._phot = dict(zero_point_photons_per_s_cm2=rig.sky.zero_point_photons_per_s_cm2,
                          aperture_area_cm2=s.aperture_area_cm2, transmission=s.optics_transmission,
                          exposure_s=det.exposure_s)
        self.pixel_arcsec = pix_arcsec = s.pixel_pitch_um * 1e-3 / s.focal_length_mm * 180.0 / math.pi * 3600.0
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
                         shape_hw=self.shape_hw, bv=cat.bv_mag[gi])


def true_sequence(rig, commanded: AttitudeSequence, rng: np.random.Generator) -> AttitudeSequence:
    """The attitudes the sensor really had during a commanded sequence: each frame's commanded
    attitude turned by the attitude knowledge error (``identification.attitude_error_deg`` about a
    random axis, drawn per frame: what the a-priori attitude misses) and the jitter
    (``sequence.jitter_arcsec`` per axis, 1σ). Body rates are the commanded ones."""
    n = len(commanded)
    ax = rng.normal(size=(n, 3))
    ax /= np.linalg.norm(ax, axis=1, keepdims=True)
    err = Rotation.from_rotvec(np.radians(rig.identification.attitude_error_deg) * ax).as_matrix()
    R = perturb(err @ commanded.R_cam_from_icrs, np.radians(rig.sequence.jitter_arcsec / 3600.0), rng)
    return AttitudeSequence(commanded.kind, commanded.times_s.copy(), R, commanded.omega_cam_rad_s.copy())
