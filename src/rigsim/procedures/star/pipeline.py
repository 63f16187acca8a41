"""End-to-end seed-004 run on rendered frames: render → extract → identify → calibrate → compare.

The stages only pass observations forward; the truth (``StarFrame.truth``) is read only in
``_score_*`` functions, after estimation, to report errors. The a-priori attitude given to
identification is the true attitude rotated by ``identification.attitude_error_deg`` about a
random axis (a gyro-propagated attitude; the only way the truth enters the pipeline, by design).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.estimation.observability import observability
from rigsim.estimation.star_calibration import MODELS, FrameObs, batch_lsq, run_ekf
from rigsim.estimation.star_id import identify
from rigsim.imaging.stars import extract_stars
from rigsim.procedures.star.study import CASES, CentroidNoise, case_setup
from rigsim.render.star import render_sequence
from rigsim.truth import star as att
from rigsim.truth.star import StarSky

__all__ = ["PipelineResult", "run_pipeline", "per_star_residuals"]


@dataclass
class PipelineResult:
    rig: object
    seed: int
    renderer: str
    frames_obs: list                      # list[FrameObs] per frame (identified, usable)
    ident: list                           # list[IdentResult]
    ident_stats: dict
    centroid_stats: dict
    ekf: dict                             # (case, model) -> EKFResult
    batch: object                         # BatchResult (f, u0, v0, k1, k2)
    batch_pp: object                      # BatchResult (u0, v0) with f, k known (reference)
    observability: dict                   # (model, state label) -> Observability
    truth_theta: np.ndarray
    times: dict = field(default_factory=dict)
    sample_frame: object = None           # first StarFrame (dn + truth) for the report
    R_est: list = field(default_factory=list)
    noise_scale: float = 1.0


def _score_centroids(fr, obs, ident) -> dict:
    """Compare identified centroids with the truth (by HIP). Truth is read here only."""
    tr = fr.truth
    pos = {int(h): i for i, h in enumerate(tr.hip)}
    e, s, ph, wrong = [], [], [], 0
    for oi, h in zip(ident.obs_index, ident.hip):
        i = pos.get(int(h))
        if i is None or np.linalg.norm(tr.uv[i] - obs.uv[oi]) > 1.5:
            wrong += 1
            continue
        e.append(obs.uv[oi] - tr.uv[i])
        s.append(obs.sigma_uv[oi])
        ph.append(tr.photons[i])
    return {"err": np.array(e).reshape(-1, 2), "sigma": np.array(s).reshape(-1, 2), "photons": np.array(ph),
            "wrong": wrong}


def run_pipeline(rig, *, seed: int = 0, renderer: str = "analytic", mitsuba=None, noiseless: bool = False,
                 progress=None, sky: StarSky | None = None) -> PipelineResult:
    t0 = time.perf_counter()
    times = {}
    sky = sky if sky is not None else StarSky(rig)
    times["catalogue"] = time.perf_counter() - t0
    s = rig.sensor
    idc = rig.identification
    c = rig.calibration
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 4004]))
    seq = att.from_rig(rig.sequence, rng)
    # nominal camera for identification: f with the 'biased' assumption, centre principal point, known k
    nominal = s.camera(f_px=s.f_px + c.f_bias_px, principal_point_px=rig.prior_principal_point())
    frames_obs, idents, R_est = [], [], []
    cstats = {"err": [], "sigma": [], "photons": [], "wrong": 0, "detected": 0, "usable": 0, "in_field": 0}
    sample = None
    t_render = t_extract = t_ident = 0.0
    tr0 = time.perf_counter()
    for fr in render_sequence(sky, seq, seed=seed, renderer=renderer, noiseless=noiseless, mitsuba=mitsuba):
        t_render += time.perf_counter() - tr0
        if sample is None:
            sample = fr
        t1 = time.perf_counter()
        obs = extract_stars(fr.dn, s.detector, s.psf_sigma_px, method=c.centroid_method)
        usable = obs.subset(np.flatnonzero(obs.usable))
        t2 = time.perf_counter()
        ax = rng.normal(size=3)
        R_prior = Rotation.from_rotvec(np.radians(idc.attitude_error_deg) * ax / np.linalg.norm(ax)).as_matrix() @ fr.truth.R_cam_from_icrs
        ident = identify(usable.uv, sky, R_prior, nominal, search_radius_px=idc.search_radius_px,
                         match_tolerance_px=idc.match_tolerance_px, min_matches=idc.min_matches)
        t3 = time.perf_counter()
        t_extract += t2 - t1
        t_ident += t3 - t2
        idents.append(ident)
        R_est.append(ident.R_cam_from_icrs)
        cstats["detected"] += len(obs)
        cstats["usable"] += len(usable)
        cstats["in_field"] += int(np.sum(sky.camera.on_detector(fr.truth.uv, 0.0)))
        if ident.ok:
            o = usable.subset(ident.obs_index)
            frames_obs.append(FrameObs(o.uv, o.sigma_uv, ident.dirs_icrs, o.flux))
            sc = _score_centroids(fr, usable, ident)
            for k in ("err", "sigma", "photons"):
                cstats[k].append(sc[k])
            cstats["wrong"] += sc["wrong"]
        else:
            frames_obs.append(FrameObs(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 3)), np.zeros(0)))
        if progress is not None:
            progress.update(1)
        tr0 = time.perf_counter()
    times.update(render=t_render, extract=t_extract, identify=t_ident)
    for k in ("err", "sigma", "photons"):
        cstats[k] = np.concatenate(cstats[k]) if cstats[k] else np.zeros((0, 2) if k != "photons" else 0)
    err, sig = cstats["err"], cstats["sigma"]
    noise = CentroidNoise.from_rig(rig, background_photons_per_px=sky.background_photons_per_px)
    crlb = noise.sigma(cstats["photons"]) if len(err) else np.zeros(0)
    centroid_stats = {
        "n": int(len(err)),
        "rms_px": np.sqrt(np.mean(err**2, axis=0)).tolist() if len(err) else [np.nan, np.nan],
        "mean_px": np.mean(err, axis=0).tolist() if len(err) else [np.nan, np.nan],
        "chi_rms": np.sqrt(np.mean((err / sig) ** 2, axis=0)).tolist() if len(err) else [np.nan, np.nan],
        "error_over_crlb_rms": float(np.sqrt(np.mean((err / crlb[:, None]) ** 2))) if len(err) else np.nan,
    }
    n_ok = sum(i.ok for i in idents)
    ident_stats = {
        "frames": len(idents), "frames_identified": int(n_ok),
        "stars_in_field": cstats["in_field"], "detected": cstats["detected"], "usable": cstats["usable"],
        "identified": int(sum(len(i) for i in idents)), "wrong": int(cstats["wrong"]),
        "attitude_error_deg": idc.attitude_error_deg,
        "reasons": [i.reason for i in idents if not i.ok],
    }
    # calibration
    t4 = time.perf_counter()
    true = np.array([s.f_px, *s.principal_point_px, s.k1, s.k2])
    ekf = {}
    for case in CASES:
        th0, est, ps = case_setup(rig, case)
        for model in MODELS:
            ekf[(case, model)] = run_ekf(frames_obs, th0, model=model, estimate=est, prior_sigma=ps,
                                         weighting=c.weighting, process_sigma=c.process_noise_px,
                                         p12=(s.p1, s.p2), max_stars=c.max_stars_per_frame)
    times["ekf (9 runs)"] = time.perf_counter() - t4
    t5 = time.perf_counter()
    th_b = np.array([s.f_px + c.f_bias_px, *rig.prior_principal_point(), 0.0, 0.0])
    batch = batch_lsq(frames_obs, th_b, weighting=c.weighting, p12=(s.p1, s.p2), max_stars=c.max_stars_per_frame)
    th_pp = np.array([s.f_px, *rig.prior_principal_point(), s.k1, s.k2])
    batch_pp = batch_lsq(frames_obs, th_pp, estimate=("u0", "v0"), weighting=c.weighting, p12=(s.p1, s.p2),
                         max_stars=c.max_stars_per_frame)
    times["batch LSQ"] = time.perf_counter() - t5
    obsv = {}
    for model in MODELS:
        for label, est in (("u0,v0", ("u0", "v0")), ("f,u0,v0", ("f", "u0", "v0")),
                           ("f,u0,v0,k1,k2", ("f", "u0", "v0", "k1", "k2"))):
            obsv[(model, label)] = observability(frames_obs, batch.theta, model=model, estimate=est,
                                                 weighting=c.weighting, p12=(s.p1, s.p2),
                                                 max_stars=c.max_stars_per_frame)
    times["total"] = time.perf_counter() - t0
    return PipelineResult(rig, int(seed), renderer, frames_obs, idents, ident_stats, centroid_stats, ekf, batch,
                          batch_pp, obsv, true, times, sample, R_est,
                          noise_scale=float(centroid_stats["error_over_crlb_rms"]))


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
