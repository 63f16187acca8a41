"""Seeds 000 and 001, analytic: the cube-mirror calibration campaign and its error budget.

Steps (seed 000 / seed 001):
1. sun-sensor calibration sweep → R(sun←rot) by least squares      (000 step 1 / 001 step B)
2. null two cube faces on the reference direction → θ1..θ4          (000 steps 2–3 / 001 step C)
   (seed 001 first aligns the autocollimator on the inner-frame plane mirror, step A)
3. TRIAD → R(cube←rot)                                              (000 step 4 / 001 step C3)
4. R(cube←sun) = R(cube←rot) · R(sun←rot)ᵀ                          (001 eq 9; 000 eq 11 reading)
5. compare with the rig's truth, per cube axis, in arcseconds.

The simulated rig (:class:`Realization`) produces the observations; :func:`estimate` turns
observations and the nominal rig into the recovered rotations (no truth); :func:`compare` puts
them beside the truth.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from rigsim.estimation.sun_calibration import SunCalibration, sweep_poses
from rigsim.frames import ARCSEC_PER_RAD, small_angle_error
from rigsim.procedures.cube_mirror.pipeline import CubeMirrorEstimate, default_axis_order, estimate
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import TruePose, TurntableReading, pose_deg_to_rad
from rigsim.truth.cube_mirror.realization import Noise, Realization, draw_realization, noise_from_rig, tilt

PAPER_RSS_ARCSEC = 3.69
PAPER_SIGMAS_ARCSEC = {"σ1 aiming null (1 px)": 2.34, "σ2 turntable perpendicularity": 2.0, "σ3 aiming-camera mounting": 2.0, "σ4 angle readout": 0.4}


def compare(rig: CubeMirrorRig, est: CubeMirrorEstimate, real: Realization) -> CampaignResult:
    """The estimate beside the rig instance's truth. Without a step-1 calibration (the budget's rows
    that leave the sweep untouched) R(sun←rot) is taken as exact: the row then measures the other
    sources alone."""
    R_sun = est.R_sun_from_rot if est.calibration is not None else real.R_sun_from_mount
    return CampaignResult(rig.name, est.axis_order, est.calibration, [r.deg() for r in est.null_readings],
                          R_sun, real.R_sun_from_mount, est.R_cube_from_rot, real.R_cube_from_mount,
                          est.R_cube_from_rot @ R_sun.T, real.R_cube_from_sun)


@dataclass
class CampaignResult:
    rig_name: str
    axis_order: str
    calibration: SunCalibration | None
    null_poses_deg: list[dict[str, float]]  # recorded readings θ1..θ4
    R_sun_from_rot_est: np.ndarray
    R_sun_from_rot_true: np.ndarray
    R_cube_from_rot_est: np.ndarray
    R_cube_from_rot_true: np.ndarray
    R_cube_from_sun_est: np.ndarray
    R_cube_from_sun_true: np.ndarray

    @property
    def error_arcsec(self) -> np.ndarray:
        """Per-axis small-angle error of R(cube←sun), about the cube axes (arcsec)."""
        return small_angle_error(self.R_cube_from_sun_est, self.R_cube_from_sun_true) * ARCSEC_PER_RAD

    @property
    def sun_error_arcsec(self) -> np.ndarray:
        return small_angle_error(self.R_sun_from_rot_est, self.R_sun_from_rot_true) * ARCSEC_PER_RAD

    @property
    def cube_error_arcsec(self) -> np.ndarray:
        return small_angle_error(self.R_cube_from_rot_est, self.R_cube_from_rot_true) * ARCSEC_PER_RAD


def simulate_sweep(rig: CubeMirrorRig, real: Realization, noise: Noise, rng: np.random.Generator
                   ) -> tuple[TurntableReading, np.ndarray]:
    """Step 1 / B: turntable readings and centroids of every sweep pose that lands on the detector."""
    proc = rig.procedure
    fixed = {a.label: 0.0 for a in rig.turntable.axes if a.label not in proc.sweep_axes}
    poses = TruePose(sweep_poses(proc.sweep_axes, proc.sweep_range_deg, proc.sweep_step_deg, fixed))
    s_mount = np.einsum("nji,j->ni", real.turntable.R_rot_from_mount(poses), real.d_sun_rot)
    cam = rig.sun_sensor.camera()
    uv = cam.project(s_mount @ real.R_sun_from_mount.T)
    keep = cam.on_detector(uv, margin_px=3.0)
    uv = uv[keep] + rng.normal(0.0, noise.centroid_sigma_px, (keep.sum(), 2)) if noise.centroid_sigma_px else uv[keep]
    readings = {}
    for k, v in poses.items():
        readings[k] = v[keep] + real.encoder_bias_rad.get(k, 0.0) + rng.normal(0.0, noise.encoder_sigma_rad.get(k, 0.0), keep.sum())
    return TurntableReading(readings), uv


def reference_direction(rig: CubeMirrorRig, real: Realization, noise: Noise, rng: np.random.Generator) -> np.ndarray:
    """The direction the faces are nulled on, in the rot frame (true)."""
    if rig.procedure.method == "diaphragm":
        return real.d_sun_rot
    # Seed 001 step A: autocollimator adjusted until it reads zero on the inner-frame plane mirror
    # (middle and outer frames at zero). Its axis ends up along the mirror normal, within its resolution.
    zero = {a.label: -real.encoder_bias_rad.get(a.label, 0.0) for a in rig.turntable.axes}
    m = real.turntable.R_rot_from_mount(zero) @ real.plane_mirror_normal_mount
    return tilt(m, rng.normal(0.0, noise.null_sigma_rad, 2))


def simulate_nulls(rig: CubeMirrorRig, real: Realization, noise: Noise, rng: np.random.Generator, d_ref: np.ndarray
                   ) -> list[TurntableReading]:
    """Steps 2–3 / C: exact true poses at which each face is nulled (within the null error), as read."""
    out = []
    free = [lab for lab in ("X", "Y") if lab in {a.label for a in rig.turntable.axes}]
    for i, face in enumerate(rig.procedure.faces):
        start = pose_deg_to_rad(rig.procedure.nominal_poses_deg[i])
        eps = real.null_bias_rad[i] + rng.normal(0.0, noise.null_sigma_rad, 2)
        d_null = tilt(d_ref, eps)
        fixed = {a.label: start.get(a.label, 0.0) for a in rig.turntable.axes if a.label not in free}
        true_pose = real.turntable.solve_alignment(real.face_normals_mount[face], d_null, free, start, fixed)
        reading = {k: v + real.encoder_bias_rad.get(k, 0.0) + rng.normal(0.0, noise.encoder_sigma_rad.get(k, 0.0)) for k, v in true_pose.items()}
        # axes that are not adjusted are set to their nominal value and read back exactly as set
        for k in fixed:
            reading[k] = fixed[k]
        out.append(TurntableReading(reading))
    return out


def run_campaign(
    rig: CubeMirrorRig,
    real: Realization,
    noise: Noise,
    rng: np.random.Generator,
    axis_order: str | None = None,
    fit_calibration: bool = True,
) -> CampaignResult:
    """Simulate the observations of one campaign on the rig instance ``real``, estimate, compare."""
    axis_order = axis_order or default_axis_order(rig)
    sweep_readings = sweep_uv = None
    if fit_calibration:  # step 1 / B; without it the budget row isolates the other sources
        sweep_readings, sweep_uv = simulate_sweep(rig, real, noise, rng)
    d_ref = reference_direction(rig, real, noise, rng)  # steps 2–3 / A, C
    readings_null = simulate_nulls(rig, real, noise, rng, d_ref)
    sig = None if sweep_uv is None or not noise.centroid_sigma_px else np.full(np.shape(sweep_uv), noise.centroid_sigma_px)
    est = estimate(rig, readings_null, axis_order, sweep_readings=sweep_readings, sweep_uv=sweep_uv,
                   sweep_sigma_uv=sig)  # the fit judged against the noise the simulation drew
    return compare(rig, est, real)


# ---------------------------------------------------------------- error budget (Monte Carlo)

@dataclass
class BudgetRow:
    source: str
    sigma_arcsec: np.ndarray  # per cube axis
    paper_arcsec: float | None
    n: int

    @property
    def rss_arcsec(self) -> float:
        return float(np.sqrt(np.sum(self.sigma_arcsec**2)))


def budget_sources(rig: CubeMirrorRig) -> dict[str, tuple[set[str], Callable[[Noise], Noise], float | None]]:
    """Error sources of the rig: name → (drawn rig errors, noise filter, paper's σ)."""
    zero = Noise()
    full = noise_from_rig(rig)
    if rig.procedure.method == "diaphragm":
        return {
            "σ1 aiming null (1 px)": (set(), lambda n: replace(zero, null_sigma_rad=full.null_sigma_rad), 2.34),
            "σ2 turntable perpendicularity": ({"perpendicularity"}, lambda n: zero, 2.0),
            "σ3 aiming-camera mounting": ({"mounting"}, lambda n: zero, 2.0),
            "σ4 angle readout": (set(), lambda n: replace(zero, encoder_sigma_rad=full.encoder_sigma_rad), 0.4),
            "sun-sensor centroid noise": (set(), lambda n: replace(zero, centroid_sigma_px=full.centroid_sigma_px), None),
        }
    return {
        "autocollimator reading": (set(), lambda n: replace(zero, null_sigma_rad=full.null_sigma_rad), rig.autocollimator.resolution_arcsec),
        "turntable perpendicularity": ({"perpendicularity"}, lambda n: zero, rig.turntable.perpendicularity_sigma_arcsec),
        "plane-mirror perpendicularity": ({"plane_mirror"}, lambda n: zero, rig.plane_mirror.perpendicularity_spec_arcsec),
        "angle readout": (set(), lambda n: replace(zero, encoder_sigma_rad=full.encoder_sigma_rad), None),
        "sun-sensor centroid noise": (set(), lambda n: replace(zero, centroid_sigma_px=full.centroid_sigma_px), None),
    }


def error_budget(
    rig: CubeMirrorRig,
    n_trials: int,
    seed: int,
    axis_order: str | None = None,
    progress: Callable[[int], None] | None = None,
    paper_sources_only: bool = False,
) -> list[BudgetRow]:
    """Per-axis σ of the R(cube←sun) error, one row per source alone, then all together.

    Each trial draws a rig instance and the random errors, runs the whole campaign
    (including the least-squares sweep fit when step 1 is affected) and measures the error
    against that trial's truth.
    """
    rng = np.random.default_rng(seed)
    sources = budget_sources(rig)
    if paper_sources_only:
        sources = {k: v for k, v in sources.items() if v[2] is not None}
    rows = []

    def trials(drawn: set[str], noise: Noise) -> np.ndarray:
        errs = np.empty((n_trials, 3))
        needs_fit = bool(drawn & {"perpendicularity"}) or noise.centroid_sigma_px > 0 or any(noise.encoder_sigma_rad.values())
        for t in range(n_trials):
            real = draw_realization(rig, rng, drawn)
            errs[t] = run_campaign(rig, real, noise, rng, axis_order, fit_calibration=needs_fit).error_arcsec
            if progress:
                progress(1)
        return errs

    all_drawn: set[str] = set()
    all_noise = Noise()
    for name, (drawn, nf, paper) in sources.items():
        noise = nf(None)
        e = trials(drawn, noise)
        rows.append(BudgetRow(name, e.std(axis=0, ddof=1), paper, n_trials))
        all_drawn |= drawn
        all_noise = Noise(
            {**all_noise.encoder_sigma_rad, **noise.encoder_sigma_rad},
            max(all_noise.null_sigma_rad, noise.null_sigma_rad),
            max(all_noise.centroid_sigma_px, noise.centroid_sigma_px),
        )
    if rig.procedure.method == "diaphragm":
        # the paper's four sources together (it leaves the step-1 calibration out of its budget)
        paper_drawn: set[str] = set()
        for name, (drawn, nf, paper) in sources.items():
            if paper is not None:
                paper_drawn |= drawn
        full = noise_from_rig(rig)
        paper_noise = Noise(full.encoder_sigma_rad, full.null_sigma_rad, 0.0)
        e = trials(paper_drawn, paper_noise)
        rows.append(BudgetRow("σ1..σ4 together (paper's sources)", e.std(axis=0, ddof=1), PAPER_RSS_ARCSEC, n_trials))
    if not paper_sources_only:
        e = trials(all_drawn, all_noise)
        rows.append(BudgetRow("all sources together", e.std(axis=0, ddof=1), None, n_trials))
    return rows
