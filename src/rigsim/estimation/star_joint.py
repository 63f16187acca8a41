"""Identification and calibration together: each identified frame is matched again with the camera
the previous round calibrated (a better camera matches fainter stars and rejects near misses), then
the intrinsics and every attitude are fitted jointly (:func:`rigsim.estimation.star_bundle.bundle_adjust`).

Which distortion terms are fitted: ``"auto"`` fits k1 and adds k2 only when the data support it
(χ² falls by more than 9 with it: 3σ for one more parameter); a narrow field rarely supports k2,
and a k2 the data cannot see only inflates the other terms' σ."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from rigsim.estimation.star_bundle import BundleResult, HeldOut, bundle_adjust, held_out_check
from rigsim.estimation.star_calibration import FrameObs
from rigsim.estimation.star_id import IdentResult, identify
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.sky import SkyCatalogue

__all__ = ["DISTORTION_TERMS", "JointCalibration", "joint_calibration"]

DISTORTION_TERMS = ("auto", "none", "k1", "k1,k2")
K2_DELTA_CHI2 = 9.0


@dataclass
class JointCalibration:
    """The joint fit, the identifications it rests on, the stars it used and the held-out check."""

    bundle: BundleResult
    ident: list            # per frame: IdentResult (the last round's)
    frames_obs: list       # per frame: FrameObs of the matched stars (centroid σ as measured)
    held_out: list         # HeldOut per frame left out in turn (empty with fewer than 2 frames)
    estimated: tuple[str, ...]
    k2_delta_chi2: float | None  # χ² gained by fitting k2 ("auto"), None when not tried


def _frame_obs(usable, ident: IdentResult, k: int, dirs_transform=None) -> FrameObs:
    o = ident.obs_index
    dirs = ident.dirs_icrs if dirs_transform is None else dirs_transform(k, ident.dirs_icrs)
    return FrameObs(usable.uv[o], usable.sigma_uv[o], dirs, usable.flux[o])


def _fit(frames, camera0, R0, estimate, prior_sigma) -> BundleResult:
    return bundle_adjust(frames, camera0, R0, estimate=estimate, prior_sigma=prior_sigma)


def joint_calibration(usable: list, ident: list, sky: SkyCatalogue, camera0: PinholeBrown, *,
                      prior_sigma: dict, distortion: str = "auto", match_tolerance_px: float = 2.0,
                      rounds: int = 2, held_out: bool = True, reidentify: bool = True,
                      dirs_transform=None) -> JointCalibration:
    """``usable``: per frame, the extracted stars (anything with ``uv``, ``sigma_uv``, ``flux``);
    ``ident``: per frame, its first identification (frames not identified stay out); ``camera0``: the
    nominal camera (the fit's start and prior mean, with ``prior_sigma`` name → 1σ). ``reidentify``
    False: one fit on the identifications as given. ``dirs_transform(k, dirs)``: the directions frame
    k's stars are seen in (e.g. refracted by the air), applied to the catalogue's before the fit.
    Returns the last round's fit, identifications and stars."""
    if distortion not in DISTORTION_TERMS:
        raise ValueError(f"distortion = {distortion!r}: allowed {', '.join(DISTORTION_TERMS)}")
    base = ("f", "u0", "v0")
    est = base + {"none": (), "k1": ("k1",), "k1,k2": ("k1", "k2"), "auto": ("k1",)}[distortion]
    cur = list(ident)
    cam = camera0
    # a first camera: the focal length the identifications imply (lost in space reports it), if any
    f_id = [float(getattr(i, "f_px", np.nan) or np.nan) for i in cur if i.ok]
    f_id = [f for f in f_id if np.isfinite(f)]
    if f_id:
        cam = camera0.with_params(fx=float(np.median(f_id)), fy=float(np.median(f_id)))
    fit = None
    dk2 = None
    for _ in range(max(1, rounds) if reidentify else 1):
        if reidentify:
            cur = [identify(u.uv, sky, i.R_cam_from_icrs, cam, search_radius_px=4.0 * match_tolerance_px,
                            match_tolerance_px=match_tolerance_px, min_matches=3) if i.ok else i
                   for u, i in zip(usable, cur)]
        frames = [_frame_obs(u, i, k, dirs_transform) if i.ok else FrameObs(np.zeros((0, 2)), np.zeros((0, 2)),
                                                                               np.zeros((0, 3)))
                  for k, (u, i) in enumerate(zip(usable, cur))]
        R0 = [i.R_cam_from_icrs for i in cur]
        fit = _fit(frames, camera0, R0, est, prior_sigma)
        if distortion == "auto" and fit.success:
            # the same noise (the k1 fit's floor) for both: k2 stays when it lowers χ² by more than 9
            fit2 = bundle_adjust(frames, camera0, R0, estimate=est + ("k2",), prior_sigma=prior_sigma,
                                 sigma_floor_px=fit.sigma_floor_px)
            dk2 = fit.chi2_reduced * fit.dof - fit2.chi2_reduced * fit2.dof
            if fit2.success and dk2 > K2_DELTA_CHI2:
                fit = _fit(frames, camera0, R0, est + ("k2",), prior_sigma)
        if fit.success:  # the next round predicts with this round's camera and attitudes
            cam = fit.camera(camera0)
            cur = [replace(i, R_cam_from_icrs=R) if i.ok and np.all(np.isfinite(R)) else i for i, R in zip(cur, fit.R)]
    estimated = fit.names
    ho = held_out_check(frames, camera0, R0, estimate=estimated, prior_sigma=prior_sigma) if held_out else []
    return JointCalibration(fit, cur, frames, ho, estimated, dk2)
