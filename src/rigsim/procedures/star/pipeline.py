"""The seed-004 pipeline on observations and the nominal rig only (no truth, no renderer: an import
contract enforces it). :class:`StarPipeline` takes frames one by one (:class:`StarObservation`: a
DN image, its time, the commanded attitude): it extracts and centroids the stars and identifies
them with the commanded attitude as the prior; :meth:`StarPipeline.calibrate` then runs the AD/ADS
EKFs (f fixed at its nominal value, or estimated), batch least squares of (f, u0, v0, k1, k2) from
the nominal values, and the observability analysis. :func:`calibrate_frames` does it all at once.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.errors import InputError
from rigsim.estimation.observability import observability
from rigsim.estimation.star_calibration import MODELS, FrameObs, batch_lsq, run_ekf
from rigsim.estimation.star_id import IdentResult, identify
from rigsim.estimation.star_joint import joint_calibration
from rigsim.estimation.star_lis import identify_lost_in_space
from rigsim.imaging import Flag
from rigsim.imaging.cosmetics import sequence_fixed_pattern, subtract_pattern
from rigsim.imaging.stars import Observations, extract_stars, refit_windows, star_windows
from rigsim.optics.sky import SkyCatalogue
from rigsim.procedures.star.ground_map import corrected_centroids, ground_centroid_map
from rigsim.procedures.star.psf_model import star_image_model
from rigsim.rig.star import NominalStarRig

__all__ = [
    "IDENTIFICATION",
    "PIPELINE_CASES",
    "PipelineOutput",
    "StarObservation",
    "StarPipeline",
    "calibrate_frames",
    "per_star_residuals",
    "pipeline_case_setup",
]

IDENTIFICATION = ("commanded", "lost-in-space")
"""How stars are identified: from the commanded attitude (the prior), or with no prior at all."""

PIPELINE_CASES = ("f_nominal", "f_joint")
"""EKF cases a user can run: state (u0, v0) with f fixed at its nominal value, or (f, u0, v0)."""

OBSERVABILITY_STATES = (("u0,v0", ("u0", "v0")), ("f,u0,v0", ("f", "u0", "v0")),
                        ("f,u0,v0,k1,k2", ("f", "u0", "v0", "k1", "k2")))


@dataclass(frozen=True)
class StarObservation:
    """One frame as the sensor delivers it: the DN image, its time, and the commanded attitude
    (``R_cam_from_icrs`` the spacecraft was told to hold: the identification prior; None for a
    lost-in-space identification)."""

    index: int
    time_s: float
    dn: np.ndarray
    R_commanded: np.ndarray


def pipeline_case_setup(nominal: NominalStarRig, case: str):
    """(θ0, estimated names, prior σ) of a pipeline case, θ = (f, u0, v0, k1, k2), from the nominal rig."""
    s = nominal.sensor
    th0 = np.array(s.theta, dtype=float)
    pp = s.principal_point_sigma_px
    if case == "f_nominal":
        return th0, ("u0", "v0"), [pp, pp]
    if case == "f_joint":
        return th0, ("f", "u0", "v0"), [s.focal_length_sigma_px, pp, pp]
    raise ValueError(f"case = {case!r}: allowed {PIPELINE_CASES}")


@dataclass
class PipelineOutput:
    """What the pipeline recovers (no truth)."""

    nominal: NominalStarRig
    usable: list                 # per frame: the usable extracted stars (rigsim.imaging.stars.Observations)
    ident: list                  # per frame: IdentResult
    frames_obs: list             # per frame: FrameObs of the identified stars
    ident_stats: dict
    ekf: dict = field(default_factory=dict)    # (case, model) -> EKFResult
    batch: object = None                       # BatchResult (f, u0, v0, k1, k2)
    observability: dict = field(default_factory=dict)
    times: dict = field(default_factory=dict)
    joint: object = None                       # JointCalibration: intrinsics and attitudes fitted together
    lis: list = field(default_factory=list)    # per frame: the lost-in-space IdentResult (empty with a prior attitude)

    @property
    def R_est(self) -> list:
        return [i.R_cam_from_icrs for i in self.ident]


class StarPipeline:
    """The seed-004 pipeline, frame by frame: :meth:`add` extracts and identifies one
    :class:`StarObservation`; :meth:`calibrate` runs the estimators over all frames added."""

    def __init__(self, nominal: NominalStarRig, sky: SkyCatalogue, *, identification: str = "commanded",
                 refraction=None, extractions: dict | None = None):
        if not isinstance(nominal, NominalStarRig):
            raise TypeError("the pipeline takes the nominal rig (StarRig.nominal_rig()), not the rig with its truth")
        if identification not in IDENTIFICATION:
            raise ValueError(f"identification = {identification!r}: allowed {', '.join(IDENTIFICATION)}")
        self.nominal, self.sky = nominal, sky
        self.identification = identification
        self.camera = nominal.sensor.camera()
        self.centroid_map = ground_centroid_map(nominal)
        # the forward-model centroider's star image (the traced lens's PSF or the Gaussian)
        self.psf_model = star_image_model(nominal) if nominal.calibration.centroid_method == "model" else None
        # a traced model's PSF depends on the star's field direction and colour: the identified stars' windows are
        # kept, fitted again with the catalogue colour, and again through the first calibrated camera
        self._traced_model = getattr(self.psf_model, "table", None) is not None
        self._windows: list = []
        self.usable: list[Observations] = []
        self.ident: list[IdentResult] = []
        self.frames_obs: list[FrameObs] = []
        self.counts = {"detected": 0, "usable": 0}
        self.times = {"extract": 0.0, "identify": 0.0}
        self.fixed_pattern = None  # a DN image subtracted from every frame before extraction (or None)
        self.fixed_pattern_note = "none"  # what was subtracted, for the output
        # (Site, frame index → UTC time): the air's refraction of every identified star before the joint fit
        self.refraction = refraction
        # shared by pipelines that see the same observation objects: an extraction with equal settings on the same
        # frame and the same fixed-pattern array is made once (a robustness trial's variants differ mostly after it)
        self._extractions = extractions
        c, s = nominal.calibration, nominal.sensor
        self._extraction_settings = (s.detector.model_dump_json(), s.psf_sigma_px, c.centroid_method,
                                     c.single_pixel_filter, c.poor_fit_reference, c.background,
                                     None if s.traced_lens is None else s.traced_lens.model_dump_json())

    def _refract(self, k: int, dirs: np.ndarray) -> np.ndarray:
        if self.refraction is None:
            return dirs
        from rigsim.optics.refraction import apparent_directions

        site, time_of = self.refraction
        return apparent_directions(dirs, site, time_of(k))

    def set_sequence_pattern(self, observations) -> None:
        """Subtract the fixed pattern of these observations (:func:`sequence_pattern`) from every frame."""
        self.fixed_pattern = sequence_pattern(observations, self.nominal)
        self.fixed_pattern_note = f"sequence: {int(np.count_nonzero(self.fixed_pattern))} pixels"

    def add(self, obs: StarObservation) -> IdentResult:
        s, idc = self.nominal.sensor, self.nominal.identification
        t0 = time.perf_counter()
        c = self.nominal.calibration
        key = (id(obs), id(self.fixed_pattern), *self._extraction_settings)
        found = None if self._extractions is None else self._extractions.get(key)
        if found is None:
            found = extract_stars(subtract_pattern(obs.dn, self.fixed_pattern), s.detector, s.psf_sigma_px,
                                  method=c.centroid_method, repair_single_pixels=c.single_pixel_filter,
                                  poor_fit=c.poor_fit_reference, background=c.background, psf_model=self.psf_model)
            if self._extractions is not None:
                self._extractions[key] = found
        keep = found.usable
        if c.reject_poor_fits:
            keep = keep & ((found.flags & int(Flag.POOR_FIT)) == 0)
        usable = found_kept = found.subset(np.flatnonzero(keep))
        if self.centroid_map is not None:  # the ground calibration of the lens's centroid shift ([nominal] centroid_map)
            usable = replace(usable, uv=corrected_centroids(usable.uv, self.centroid_map, self.camera))
        t1 = time.perf_counter()
        if self.identification == "lost-in-space":  # no prior: 4-star patterns of the brightest stars
            order = np.argsort(-usable.flux, kind="stable")
            ident = identify_lost_in_space(usable.uv[order], self.sky, self.camera, **idc.lost_in_space_settings())
            if ident.ok:
                ident = replace(ident, obs_index=order[ident.obs_index])
        else:
            ident = identify(usable.uv, self.sky, obs.R_commanded, self.camera, search_radius_px=idc.search_radius_px,
                             match_tolerance_px=idc.match_tolerance_px, min_matches=idc.min_matches)
        self.times["extract"] += t1 - t0
        self.times["identify"] += time.perf_counter() - t1
        win = None
        if ident.ok and self._traced_model:
            # the traced PSF depends on the star's colour: the identified stars fitted again with the catalogue's B−V
            t2 = time.perf_counter()
            win = star_windows(subtract_pattern(obs.dn, self.fixed_pattern), s.detector, s.psf_sigma_px, found_kept,
                               ident.obs_index, self.psf_model.support_px, bv=self.sky.catalogue.bv_mag[ident.cat_index],
                               repair_single_pixels=c.single_pixel_filter)
            raw = refit_windows(found_kept, win, self.psf_model, s.detector)
            usable = replace(raw, uv=corrected_centroids(raw.uv, self.centroid_map, self.camera))
            self.times["extract"] += time.perf_counter() - t2
        self._windows.append((win, found_kept))
        self.counts["detected"] += len(found)
        self.counts["usable"] += len(usable)
        self.usable.append(usable)
        self.ident.append(ident)
        if ident.ok:
            o = usable.subset(ident.obs_index)
            self.frames_obs.append(FrameObs(o.uv, o.sigma_uv, ident.dirs_icrs, o.flux))
        else:
            self.frames_obs.append(FrameObs(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 3)), np.zeros(0)))
        return ident

    def calibrate(self, *, equations: str = "framework", weighting: str | None = None) -> PipelineOutput:
        """EKFs, batch least squares and observability over the frames added; ``equations`` and
        ``weighting`` (default: the rig's) as in :func:`rigsim.estimation.star_calibration.run_ekf`
        (the observability analysis always uses the framework sets)."""
        s, c = self.nominal.sensor, self.nominal.calibration
        weighting = c.weighting if weighting is None else weighting
        p12 = (s.p1, s.p2)
        t0 = time.perf_counter()
        joint = None
        lis_ident = []
        frames_obs = self.frames_obs
        if any(i.ok for i in self.ident):
            # intrinsics and every attitude fitted together; without a prior attitude the frames are
            # identified again with each round's camera (lost in space starts from the nominal one)
            lis = self.identification == "lost-in-space"

            def joint_fit():
                return joint_calibration(self.usable, self.ident, self.sky, self.camera,
                                         prior_sigma={"f": s.focal_length_sigma_px, "u0": s.principal_point_sigma_px,
                                                      "v0": s.principal_point_sigma_px},
                                         distortion=c.distortion_terms,
                                         match_tolerance_px=self.nominal.identification.match_tolerance_px,
                                         reidentify=lis, held_out=len(self.ident) >= 2, dirs_transform=self._refract)
            joint = joint_fit()
            if self._traced_model and joint.bundle.success:
                # the traced PSF's shape follows the star's angle from the optical axis: the identified stars fitted
                # again with their model looked up through the calibrated camera, then the joint fit again
                self._refit_through(joint.bundle.theta)
                joint = joint_fit()
            if lis:
                lis_ident = list(self.ident)
                self.ident = joint.ident
            # every estimator below takes the centroid σ with the noise floor the joint fit found
            floor = joint.bundle.sigma_floor_px if np.isfinite(joint.bundle.sigma_floor_px) else 0.0
            frames_obs = [FrameObs(fo.uv[m], np.sqrt(fo.sigma_uv[m] ** 2 + floor**2), fo.dirs_icrs[m],
                                   None if fo.flux is None else fo.flux[m])
                          for fo, m in zip(joint.frames_obs, joint.bundle.used)]
        self.times["joint fit"] = time.perf_counter() - t0
        ident_stats = {"frames": len(self.ident), "frames_identified": int(sum(i.ok for i in self.ident)),
                       **self.counts, "identified": int(sum(len(i) for i in self.ident)),
                       "attitude_error_deg": self.nominal.identification.attitude_error_deg,
                       "fixed_pattern": self.fixed_pattern_note,
                       "centroid_map": "none" if s.centroid_map is None else
                       f"ground map of the traced lens (B−V {s.centroid_map.reference_bv:g}, σ {s.centroid_map.sigma_px:g} px)",
                       "centroider": c.centroid_method if self.psf_model is None else
                       "forward model: " + "; ".join(self.psf_model.includes),
                       "reasons": [i.reason for i in self.ident if not i.ok],
                       "refraction": "off (no site and time)" if self.refraction is None else
                       "on: {:.4f}°, {:.4f}°, {:.0f} m, {:.1f} hPa, {:.1f} °C".format(
                           self.refraction[0].latitude_deg, self.refraction[0].longitude_deg, self.refraction[0].height_m,
                           self.refraction[0].pressure, self.refraction[0].temperature_c)}
        out = PipelineOutput(self.nominal, self.usable, self.ident, frames_obs, ident_stats, times=dict(self.times),
                             joint=joint, lis=lis_ident)
        t0 = time.perf_counter()
        for case in PIPELINE_CASES:
            th0, est, ps = pipeline_case_setup(self.nominal, case)
            for model in MODELS:
                out.ekf[(case, model)] = run_ekf(frames_obs, th0, model=model, estimate=est, prior_sigma=ps,
                                                 weighting=weighting, process_sigma=c.process_noise_px, p12=p12,
                                                 max_stars=c.max_stars_per_frame, equations=equations)
        out.times[f"ekf ({len(out.ekf)} runs)"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        out.batch = batch_lsq(frames_obs, np.array(s.theta, dtype=float), weighting=weighting, p12=p12,
                              max_stars=c.max_stars_per_frame, equations=equations)
        out.times["batch LSQ"] = time.perf_counter() - t0
        for model in MODELS:
            for label, est in OBSERVABILITY_STATES:
                out.observability[(model, label)] = observability(frames_obs, out.batch.theta, model=model,
                                                                  estimate=est, weighting=weighting, p12=p12,
                                                                  max_stars=c.max_stars_per_frame)
        return out


    def _refit_through(self, theta) -> None:
        """The identified stars' kept windows fitted again, the traced model's field directions taken through
        the camera of ``theta`` = (f, u0, v0, k1, k2) (the first calibration), and ``usable`` updated."""
        f, u0, v0, k1, k2 = (float(x) for x in theta[:5])
        model = replace(self.psf_model, camera=self.nominal.sensor.camera(f_px=f, principal_point_px=(u0, v0), k1=k1, k2=k2))
        t0 = time.perf_counter()
        for k, (win, found_kept) in enumerate(self._windows):
            if win is None:
                continue
            raw = refit_windows(found_kept, win, model, self.nominal.sensor.detector)
            self.usable[k] = replace(raw, uv=corrected_centroids(raw.uv, self.centroid_map, self.camera))
            o = self.usable[k].subset(self.ident[k].obs_index)
            self.frames_obs[k] = FrameObs(o.uv, o.sigma_uv, self.ident[k].dirs_icrs, o.flux)
        self.times["extract"] += time.perf_counter() - t0


MIN_PATTERN_MOTION_PX = 3.0
"""Least image motion between consecutive commanded attitudes for a fixed pattern from the sequence:
about 4 PSF σ, so that each pixel sees sky in most frames."""


def sequence_pattern(observations, nominal: NominalStarRig) -> np.ndarray:
    """The fixed pattern of a sequence (:func:`rigsim.imaging.cosmetics.sequence_fixed_pattern`),
    after checking from the commanded attitudes that the stars move enough for it (a staring
    sequence would take its stars for defects)."""
    obs = list(observations)
    R = [o.R_commanded for o in obs]
    if any(r is None for r in R):
        raise InputError("[calibration] fixed_pattern = 'sequence': needs the commanded attitude of every frame")
    f = nominal.sensor.f_px
    steps = [f * float(np.arccos(np.clip(R[k][2] @ R[k + 1][2], -1.0, 1.0))) for k in range(len(R) - 1)]
    if not steps or float(np.median(steps)) < MIN_PATTERN_MOTION_PX:
        got = f"{float(np.median(steps)):.2f} px" if steps else "a single frame"
        raise InputError(f"[calibration] fixed_pattern = 'sequence': the stars move {got} between frames (median), "
                         f"at least {MIN_PATTERN_MOTION_PX:g} px is needed; use 'none' for a staring sequence")
    return sequence_fixed_pattern([o.dn for o in obs])


def calibrate_frames(frames: Iterable[StarObservation], nominal: NominalStarRig, sky: SkyCatalogue, *,
                     identification: str = "commanded") -> PipelineOutput:
    """The whole pipeline on a sequence of observations (a user's own frames welcome). With the rig's
    ``[calibration] fixed_pattern = "sequence"`` the frames are read twice: once for the pattern."""
    pipe = StarPipeline(nominal, sky, identification=identification)
    if nominal.calibration.fixed_pattern == "sequence":
        frames = list(frames)
        if any(f.R_commanded is None for f in frames):  # lost in space: nothing tells that the stars move
            pipe.fixed_pattern_note = "none: no commanded attitudes to check that the stars move"
        else:
            pipe.set_sequence_pattern(frames)
    for fr in frames:
        pipe.add(fr)
    return pipe.calibrate()


def per_star_residuals(frames_obs, theta, p12=(0.0, 0.0), width: int = 1024, height: int = 1024):
    """Image-plane residuals (measured − predicted, px) of every star with intrinsics θ: per frame the
    attitude is fitted (Wahba) with those intrinsics and the catalogue stars are re-projected.
    Returns (uv (M, 2), residual (M, 2))."""
    from rigsim.optics.camera import PinholeBrown

    f, u0, v0, k1, k2 = theta
    cam = PinholeBrown(f, f, u0, v0, k1, k2, p12[0], p12[1], 0.0, width, height)
    uv_all, r_all = [], []
    for fo in frames_obs:
        if len(fo) < 3:
            continue
        b = cam.unproject(fo.uv)
        rot, _ = Rotation.align_vectors(b, fo.dirs_icrs)
        pred = cam.project(fo.dirs_icrs @ rot.as_matrix().T)
        uv_all.append(fo.uv)
        r_all.append(fo.uv - pred)
    return np.concatenate(uv_all), np.concatenate(r_all)
