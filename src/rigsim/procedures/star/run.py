"""Seed 004 end to end, in LOST's shape: generate → pipeline → compare.

* :func:`generate`: the commanded attitude sequence (the rig's ``[sequence]``, what the user knows),
  the true one (commanded + attitude knowledge error + jitter, :func:`rigsim.truth.star.true_sequence`)
  and the rendered frames, each split into its :class:`~rigsim.procedures.star.pipeline.StarObservation`
  and its truth (:class:`rigsim.truth.star.StarField`);
* the pipeline (:mod:`rigsim.procedures.star.pipeline`) on the observations and the nominal rig;
* :func:`compare`: its output against the truth (centroids by HIP, wrong identifications).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from rigsim.estimation.star_id import IdentResult
from rigsim.imaging.stars import Observations
from rigsim.optics import attitude as att
from rigsim.procedures.star.pipeline import PipelineOutput, StarObservation, StarPipeline
from rigsim.procedures.star.study import CentroidNoise
from rigsim.render.star import render_sequence
from rigsim.rig.star import StarRig
from rigsim.truth.star import StarSky, true_sequence


def generate(rig: StarRig, *, seed: int = 0, renderer: str = "analytic", mitsuba=None, noiseless: bool = False,
             sky: StarSky | None = None):
    """Rendered frames of the rig's sequence: yields (StarObservation, StarField truth, the rendered Frame)."""
    sky = sky if sky is not None else StarSky(rig)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 4004]))
    commanded = att.from_rig(rig.sequence, rng, jitter=False)
    true_seq = true_sequence(rig, commanded, rng)
    # no FITS cards: the run writes no rendered frame (exported frames carry the commanded attitude's WCS)
    for fr in render_sequence(sky, true_seq, seed=seed, renderer=renderer, noiseless=noiseless, mitsuba=mitsuba,
                              fits_header=False):
        k = fr.index
        yield StarObservation(k, float(commanded.times_s[k]), fr.dn, commanded.R_cam_from_icrs[k]), fr.truth, fr


def _score_centroids(truth, usable: Observations, ident: IdentResult) -> dict:
    """Identified centroids against the truth (matched by HIP)."""
    pos = {int(h): i for i, h in enumerate(truth.hip)}
    e, s, ph, wrong = [], [], [], 0
    for oi, h in zip(ident.obs_index, ident.hip):
        i = pos.get(int(h))
        if i is None or np.linalg.norm(truth.uv[i] - usable.uv[oi]) > 1.5:
            wrong += 1
            continue
        e.append(usable.uv[oi] - truth.uv[i])
        s.append(usable.sigma_uv[oi])
        ph.append(truth.photons[i])
    return {"err": np.array(e).reshape(-1, 2), "sigma": np.array(s).reshape(-1, 2), "photons": np.array(ph),
            "wrong": wrong}


def compare(out: PipelineOutput, truths: list, rig: StarRig, sky: StarSky) -> tuple[dict, dict]:
    """The pipeline's identifications and centroids against the truth of each frame:
    (identification statistics, centroid statistics)."""
    cs = {"err": [], "sigma": [], "photons": []}
    wrong = in_field = 0
    for tr, usable, ident in zip(truths, out.usable, out.ident):
        in_field += int(np.sum(sky.camera.on_detector(tr.uv, 0.0)))
        if ident.ok:
            sc = _score_centroids(tr, usable, ident)
            for k in cs:
                cs[k].append(sc[k])
            wrong += sc["wrong"]
    for k in cs:
        cs[k] = np.concatenate(cs[k]) if cs[k] else np.zeros((0, 2) if k != "photons" else 0)
    err, sig = cs["err"], cs["sigma"]
    noise = CentroidNoise.from_rig(rig, background_photons_per_px=sky.background_photons_per_px)
    crlb = noise.sigma(cs["photons"]) if len(err) else np.zeros(0)
    centroid_stats = {
        "n": len(err),
        "rms_px": np.sqrt(np.mean(err**2, axis=0)).tolist() if len(err) else [np.nan, np.nan],
        "mean_px": np.mean(err, axis=0).tolist() if len(err) else [np.nan, np.nan],
        "chi_rms": np.sqrt(np.mean((err / sig) ** 2, axis=0)).tolist() if len(err) else [np.nan, np.nan],
        "error_over_crlb_rms": float(np.sqrt(np.mean((err / crlb[:, None]) ** 2))) if len(err) else np.nan,
    }
    ident_stats = {**out.ident_stats, "stars_in_field": in_field, "wrong": int(wrong)}
    return ident_stats, centroid_stats


@dataclass
class PipelineResult:
    rig: object
    seed: int
    renderer: str
    frames_obs: list                      # list[FrameObs] per frame (identified, usable)
    ident: list                           # list[IdentResult]
    ident_stats: dict
    centroid_stats: dict
    ekf: dict                             # (case, model) -> EKFResult, cases PIPELINE_CASES
    batch: object                         # BatchResult (f, u0, v0, k1, k2)
    observability: dict                   # (model, state label) -> Observability
    truth_theta: np.ndarray
    nominal_theta: np.ndarray
    times: dict = field(default_factory=dict)
    sample_frame: object = None           # the first rendered Frame (dn + truth) for the report
    R_est: list = field(default_factory=list)
    noise_scale: float = 1.0
    output: PipelineOutput | None = None  # what the pipeline recovered (for the result JSON)
    true_R: list = field(default_factory=list)  # per frame: the true mid-exposure R(cam←ICRS)


def run_pipeline(rig: StarRig, *, seed: int = 0, renderer: str = "analytic", mitsuba=None, noiseless: bool = False,
                 progress=None, sky: StarSky | None = None, on_frame=None, equations: str = "framework",
                 weighting: str | None = None) -> PipelineResult:
    """generate → pipeline → compare on the rig's sequence (module docstring). ``on_frame(obs)``
    sees every observation (e.g. to write it as a file); ``equations`` and ``weighting`` go to
    :meth:`StarPipeline.calibrate`."""
    t0 = time.perf_counter()
    sky = sky if sky is not None else StarSky(rig)
    times = {"catalogue": time.perf_counter() - t0}
    nominal = rig.nominal_rig()
    pipe = StarPipeline(nominal, sky.sky)
    truths, sample = [], None
    t_render = 0.0
    tr0 = time.perf_counter()
    use_pattern = nominal.calibration.fixed_pattern == "sequence"
    held = []  # the observations, when the fixed pattern comes from the whole sequence
    for obs, truth, fr in generate(rig, seed=seed, renderer=renderer, mitsuba=mitsuba, noiseless=noiseless, sky=sky):
        t_render += time.perf_counter() - tr0
        sample = sample if sample is not None else fr
        truths.append(truth)
        if on_frame is not None:
            on_frame(obs)
        if use_pattern:
            held.append(obs)
        else:
            pipe.add(obs)
        if progress is not None:
            progress.update(1)
        tr0 = time.perf_counter()
    if use_pattern:
        pipe.set_sequence_pattern(held)
        for obs in held:
            pipe.add(obs)
    out = pipe.calibrate(equations=equations, weighting=weighting)
    times.update(render=t_render, **out.times)
    ident_stats, centroid_stats = compare(out, truths, rig, sky)
    s = rig.sensor
    times["total"] = time.perf_counter() - t0
    return PipelineResult(rig, int(seed), renderer, out.frames_obs, out.ident, ident_stats, centroid_stats, out.ekf,
                          out.batch, out.observability, np.array([s.f_px, *s.principal_point_px, s.k1, s.k2]),
                          np.array(nominal.sensor.theta, dtype=float), times, sample, out.R_est,
                          noise_scale=float(centroid_stats["error_over_crlb_rms"]), output=out,
                          true_R=[tr.R_cam_from_icrs for tr in truths])
