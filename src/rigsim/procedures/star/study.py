"""Monte-Carlo study of seed 004's claim: principal-point accuracy of AD vs ADS EKFs.

Each trial draws a new slew (uniformly random start on the sky, random direction and roll; the
rig's rate, frame count and interval), takes the stars a sensor would use (catalogue stars on
the detector ≥ 5 px from the edge, not saturated, no neighbour within 8 px, the brightest
``max_stars_per_frame``), adds Gaussian centroid noise of σ = ``scale`` × CRLB(star photons) per
axis (the Gaussian-fit CRLB of rigsim.imaging with the rig's PSF, background, dark signal and
read noise; ``scale`` is measured on rendered frames by the pipeline), and runs every EKF on
the *same* data in three cases:

* ``f_known``  : f = true f (an oracle: the case where the ground calibration of f is perfect), state (u0, v0);
* ``f_biased`` : f = the ``[nominal]`` focal length (true + its error), state (u0, v0);
* ``f_joint``  : state (f, u0, v0), f starting at the nominal value with σ = ``nominal.focal_length_sigma_px``.

The principal point starts at its nominal value, k1 and k2 stay at theirs (ground calibration) in
every EKF case; the batch LSQ estimates all five from the nominal values.
Improvement of ADS over AD per axis = 1 − RMS(ADS error)/RMS(AD error), with a paired bootstrap
95 % interval over trials. The patent claims +64.0 % (u0) and +21.7 % (v0).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rigsim.estimation.star_calibration import FrameObs, batch_lsq
from rigsim.estimation.star_ekf_batch import run_ekf_batch
from rigsim.optics import attitude as att
from rigsim.procedures.star.pipeline import pipeline_case_setup

__all__ = ["CASES", "CentroidNoise", "usable_truth_obs", "simulate_frames", "StudyResult", "run_study",
           "improvement", "CLAIM"]

CASES = ("f_known", "f_biased", "f_joint")
CLAIM = {"u0": 0.640, "v0": 0.217}
TRIALS_PER_BATCH = 40
"""Trials whose filters run together (:func:`run_ekf_batch`; more: fewer numpy calls, more memory)."""


@dataclass(frozen=True)
class CentroidNoise:
    """Per-axis centroid σ = scale · CRLB(photons) of the rig's Gaussian PSF."""

    qe: float
    background_e: float
    read_noise_e: float
    sigma_px: float
    scale: float = 1.0

    @classmethod
    def from_rig(cls, rig, scale: float = 1.0, background_photons_per_px: float = 0.0) -> "CentroidNoise":
        d = rig.sensor.detector
        read = float(np.sqrt(d.read_noise_e**2 + 1.0 / (12.0 * d.gain_dn_per_e**2)))
        return cls(d.quantum_efficiency, d.quantum_efficiency * background_photons_per_px + d.dark_mean_e,
                   read, rig.sensor.psf_sigma_px, float(scale))

    def sigma(self, photons) -> np.ndarray:
        from rigsim.imaging import crlb_gaussian

        F = np.maximum(np.asarray(photons, float) * self.qe, 1.0)
        c = crlb_gaussian(F, self.background_e, self.read_noise_e, self.sigma_px, du=0.25, dv=0.25, roi_px=11)
        return self.scale * c.sigma_rms


def usable_truth_obs(sky, truth, max_stars: int, *, edge_px: float = 5.0, min_sep_px: float = 8.0):
    """Indices of the stars of a StarField a sensor would use (see the module docstring)."""
    rig = sky.rig
    cam = sky.camera
    inside = cam.on_detector(truth.uv, edge_px)
    d = rig.sensor.detector
    peak_e = truth.photons * d.quantum_efficiency * 0.234 * (0.77 / rig.sensor.psf_sigma_px) ** 2
    unsat = peak_e < 0.9 * min(d.full_well_e, (2**d.adc_bits - 1 - d.offset_dn) / d.gain_dn_per_e)
    if len(truth) > 1:
        dd = np.linalg.norm(truth.uv[:, None, :] - truth.uv[None, :, :], axis=2)
        np.fill_diagonal(dd, np.inf)
        iso = dd.min(axis=1) > min_sep_px
    else:
        iso = np.ones(len(truth), bool)
    idx = np.flatnonzero(inside & unsat & iso)
    return idx[np.argsort(-truth.photons[idx])][:max_stars]


def simulate_frames(sky, seq, noise: CentroidNoise, rng: np.random.Generator, max_stars: int) -> list[FrameObs]:
    fields = [sky.field(seq.R_cam_from_icrs[k]) for k in range(len(seq))]
    idxs = [usable_truth_obs(sky, tr, max_stars) for tr in fields]
    # the CRLB of every star of the sequence in one call (it is per star); the noise is drawn frame by frame
    sigs = np.split(noise.sigma(np.concatenate([tr.photons[idx] for tr, idx in zip(fields, idxs)])),
                    np.cumsum([idx.size for idx in idxs])[:-1])
    out = []
    for tr, idx, sig in zip(fields, idxs, sigs):
        uv = tr.uv[idx] + rng.normal(size=(idx.size, 2)) * sig[:, None]
        out.append(FrameObs(uv, np.repeat(sig[:, None], 2, 1), tr.dirs_icrs[idx], tr.photons[idx]))
    return out


def random_slew(rig, rng: np.random.Generator):
    s = rig.sequence
    ra = rng.uniform(0.0, 360.0)
    dec = np.degrees(np.arcsin(rng.uniform(-1.0, 1.0)))
    return att.slew(ra, dec, rng.uniform(0, 360), s.n_frames, s.frame_interval_s, s.slew_rate_deg_per_s,
                    rng.uniform(0, 360), s.roll_rate_deg_per_s)


def case_setup(rig, case: str):
    """(θ0 start, estimated names, prior σ) of a study case, θ = (f, u0, v0, k1, k2): the pipeline's
    cases (``f_biased`` is its ``f_nominal``), plus ``f_known``, the study's oracle, with the true f."""
    if case not in CASES:
        raise ValueError(f"case = {case!r}: allowed {CASES}")
    th, est, ps = pipeline_case_setup(rig.nominal_rig(), "f_joint" if case == "f_joint" else "f_nominal")
    if case == "f_known":
        th[0] = rig.sensor.f_px
    return th, est, ps


def improvement(err_ad: np.ndarray, err_ads: np.ndarray, rng: np.random.Generator, n_boot: int = 2000):
    """1 − RMS(ads)/RMS(ad) per column, with a paired bootstrap 95 % interval."""
    def imp(a, b):
        return 1.0 - np.sqrt(np.mean(b**2, axis=-2)) / np.sqrt(np.mean(a**2, axis=-2))
    est = imp(err_ad, err_ads)
    n = err_ad.shape[0]
    bi = rng.integers(0, n, size=(n_boot, n))
    boots = imp(err_ad[bi], err_ads[bi])
    return est, np.percentile(boots, 2.5, axis=0), np.percentile(boots, 97.5, axis=0)


@dataclass
class StudyResult:
    trials: int
    models: tuple[str, ...]
    weightings: tuple[str, ...]
    noise: CentroidNoise
    errors: dict = field(default_factory=dict)   # (case, model, weighting) -> (trials, 2) u0/v0 error px
    sigmas: dict = field(default_factory=dict)   # same keys -> (trials, 2) EKF-predicted σ
    f_errors: dict = field(default_factory=dict)  # (f_joint, model, weighting) -> (trials,) f error
    batch_errors: np.ndarray | None = None       # (nb, 5) θ error of batch LSQ
    batch_sigmas: np.ndarray | None = None
    n_stars: list = field(default_factory=list)
    equations: str = "framework"

    def rms(self, key) -> np.ndarray:
        return np.sqrt(np.mean(self.errors[key] ** 2, axis=0))

    def improvement_table(self, weighting: str, ads_model: str = "ads", seed: int = 0):
        rng = np.random.default_rng(seed)
        out = {}
        for case in CASES:
            a = self.errors[(case, "ad", weighting)]
            b = self.errors[(case, ads_model, weighting)]
            out[case] = improvement(a, b, rng)
        return out


def run_study(rig, sky, *, trials: int | None = None, seed: int | None = None, noise: CentroidNoise | None = None,
              models=("ad", "ads", "ads_improved"), weightings=None, batch_trials: int = 40,
              progress=None, equations: str = "framework") -> StudyResult:
    """The Monte-Carlo AD-vs-ADS study (module docstring) with the given weightings (default: the
    rig's) and equation set."""
    trials = rig.study.trials if trials is None else int(trials)
    seed = rig.study.seed if seed is None else int(seed)
    weightings = (rig.calibration.weighting,) if weightings is None else tuple(weightings)
    noise = noise if noise is not None else CentroidNoise.from_rig(rig, background_photons_per_px=sky.background_photons_per_px)
    c = rig.calibration
    s = rig.sensor
    n = rig.nominal_rig().sensor
    p12 = (n.p1, n.p2)  # the estimators' tangential distortion: the nominal one
    true = np.array([s.f_px, *s.principal_point_px, s.k1, s.k2])
    res = StudyResult(trials, tuple(models), weightings, noise, equations=equations)
    setups = {case: case_setup(rig, case) for case in CASES}
    th_batch = np.array(n.theta, dtype=float)
    rng_master = np.random.default_rng(seed)
    seeds = rng_master.integers(0, 2**63 - 1, size=trials)
    groups = (("f_known", "f_biased"), ("f_joint",))   # the cases of a group differ only in θ0
    cache: dict = {}
    for t0 in range(0, trials, TRIALS_PER_BATCH):
        # the filters of a chunk of trials × the cases of a group run together (run_ekf_batch)
        chunk = []
        for t in range(t0, min(trials, t0 + TRIALS_PER_BATCH)):
            rng = np.random.default_rng(int(seeds[t]))
            seq = random_slew(rig, rng)
            chunk.append(simulate_frames(sky, seq, noise, rng, c.max_stars_per_frame))
            res.n_stars.append(float(np.mean([len(f) for f in chunk[-1]])))
        for group in groups:
            _, est, ps = setups[group[0]]
            th0s = np.array([setups[case][0] for _ in chunk for case in group])
            seqs = [frames for frames in chunk for _ in group]
            for model in models:
                for w in weightings:
                    rs = run_ekf_batch(seqs, th0s, model=model, estimate=est, prior_sigma=ps, weighting=w,
                                       process_sigma=c.process_noise_px, p12=p12, equations=equations, cache=cache)
                    for case, r in zip(group * len(chunk), rs):
                        key = (case, model, w)
                        res.errors.setdefault(key, []).append(r.theta[1:3] - true[1:3])
                        res.sigmas.setdefault(key, []).append(r.sigma[-2:])
                        if case == "f_joint":
                            res.f_errors.setdefault(key, []).append(r.theta[0] - true[0])
        for t, frames in zip(range(t0, t0 + len(chunk)), chunk):
            if t < batch_trials:
                b = batch_lsq(frames, th_batch, p12=p12, weighting=weightings[0], equations=equations)
                if res.batch_errors is None:
                    res.batch_errors, res.batch_sigmas = [], []
                res.batch_errors.append(b.theta - true)
                res.batch_sigmas.append(b.sigma)
        cache.clear()
        if progress is not None:
            progress.update(len(chunk))
    res.errors = {k: np.array(v) for k, v in res.errors.items()}
    res.sigmas = {k: np.array(v) for k, v in res.sigmas.items()}
    res.f_errors = {k: np.array(v) for k, v in res.f_errors.items()}
    if res.batch_errors is not None:
        res.batch_errors = np.array(res.batch_errors)
        res.batch_sigmas = np.array(res.batch_sigmas)
    return res
