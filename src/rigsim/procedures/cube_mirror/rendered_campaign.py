"""Seeds 000 and 001 end to end on rendered frames — the main job (``rigsim run cube-mirror``).

Seed 000 (2-axis turntable, diaphragm screen, aiming camera):
  1. sun-sensor sweep: render the sun simulator through the sensor at every sweep pose, centroid,
     fit intrinsics + R(sun←rot) by least squares (:mod:`rigsim.procedures.cube_mirror.sweep`);
  2. concentricity search of the two faces on rendered aiming-camera frames
     (:mod:`rigsim.procedures.cube_mirror.concentricity`, Table 1);
  3. TRIAD → R(cube←rot);  4. R(cube←sun) = R(cube←rot)·R(sun←rot)ᵀ;  5. compare with truth.
Seed 001 (3-axis turntable, autocollimator): step A (align the autocollimator on the inner-frame
plane mirror), B (the sweep), C (null two faces on autocollimator frames), D (compose)
(:mod:`rigsim.procedures.cube_mirror.autocollimation`).

The estimators see turntable readings, centroids and nominal geometry only. The truth side
(:class:`~rigsim.truth.cube_mirror.realization.Realization`) drives the renderers and the comparison.

Error budget (:func:`rendered_error_budget`): rendering a whole campaign takes a minute, so the
Monte Carlo runs the *same* procedure (the same search loop, stopping rule, command steps and
least-squares fits) with the image measurements replaced by exact values plus the noise measured
on this run's rendered frames (sun-sensor centroid rms against the exact spot; aiming-camera
offset or autocollimator reading scatter over repeated frames). docs/campaign.md explains it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from rigsim.errors import SearchError
from rigsim.estimation.sun_calibration import SunCalibration
from rigsim.frames import ARCSEC_PER_RAD, RAD_PER_ARCSEC
from rigsim.procedures.cube_mirror.campaign import (
    PAPER_RSS_ARCSEC,
    BudgetRow,
    CampaignResult,
    compare,
    simulate_sweep,
)
from rigsim.procedures.cube_mirror.nulls import TracedSearch
from rigsim.procedures.cube_mirror.pipeline import default_axis_order, estimate, fit_sun_sensor
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.truth.cube_mirror.realization import Noise, Realization, draw_realization, noise_from_rig


class _NullProgress:
    def update(self, n: int = 1) -> None:
        pass

    def set_description(self, s: str) -> None:
        pass

    total = 0


@dataclass
class RenderedCampaign:
    rig_name: str
    method: str
    seed: int
    sweep: object  # SweepObservation
    calibration: SunCalibration
    searches: list[TracedSearch]
    step_a: object | None
    result: CampaignResult
    times: dict[str, float]
    measured_noise: dict = field(default_factory=dict)
    sweep_truth: object = None  # SweepTruth

    @property
    def error_arcsec(self) -> np.ndarray:
        return self.result.error_arcsec

    @property
    def null_unit(self) -> str:
        return "px" if self.method == "diaphragm" else "arcsec"


def _encoder_errors(rig: CubeMirrorRig, noise: Noise, rng: np.random.Generator) -> dict[str, float]:
    return {a.label: float(rng.normal(0.0, noise.encoder_sigma_rad.get(a.label, 0.0)))
            for a in rig.turntable.axes if a.label in ("X", "Y")}


def _null_noise(resid: list, unit: str) -> dict:
    """rms of (measured − exact) null measurements, overall and per axis."""
    r = np.array(resid)
    return {"null_measurement_rms": float(np.sqrt(np.mean(r**2))),
            "null_measurement_rms_xy": np.sqrt(np.mean(r**2, axis=0)).tolist(),
            "null_measurement_unit": unit, "null_measurement_n": len(r)}


def expected_frames(rig: CubeMirrorRig) -> int:
    """Frames the progress bar counts: the sweep poses plus a typical null search."""
    k = int(round(rig.procedure.sweep_range_deg / rig.procedure.sweep_step_deg))
    return (2 * k + 1) ** 2 + 2 * 3 + (3 if rig.procedure.method == "autocollimator" else 0)


def run_rendered_campaign(rig: CubeMirrorRig, real: Realization, *, seed: int = 0, axis_order: str | None = None,
                          noise: Noise | None = None, noiseless: bool = False, threshold: float | None = None,
                          sweep_spp: int = 256, sweep_step_deg: float | None = None, repeat_frames: int = 0,
                          progress=None, frames=None, aiming_workers: int = 1,
                          autocollimator_spp: int | None = None, sweep: tuple | None = None) -> RenderedCampaign:
    """One campaign on rendered frames against the rig instance ``real``.

    ``noise``: the random errors that are not image noise (encoder noise; default the rig's).
    ``noiseless``: detector noise off in every frame (rendering noise stays). ``threshold``
    overrides the null-search threshold (px for seed 000, arcsec for 001). ``repeat_frames`` > 0
    renders that many extra frames at the first face's final pose to measure the null measurement
    scatter (for :func:`rendered_error_budget`). ``frames``
    (:class:`~rigsim.procedures.cube_mirror.user_frames.CampaignFrames`) sees every sweep frame.
    ``aiming_workers``: processes rendering each aiming-camera frame's fixed pencil chunks (the frames
    are the same for any count). ``autocollimator_spp``: samples per pixel of the autocollimator's
    frames (seed 001; default :data:`~rigsim.procedures.cube_mirror.autocollimation.DEFAULT_SPP`).
    """
    from rigsim.procedures.cube_mirror.sweep import render_sweep

    pb = progress if progress is not None else _NullProgress()
    noise = noise if noise is not None else noise_from_rig(rig)
    order = axis_order or default_axis_order(rig)
    rng = np.random.default_rng(seed)
    times: dict[str, float] = {}
    measured: dict = {}

    # ---- step 1 / B: the sun-sensor sweep
    pb.set_description("sun-sensor sweep")
    t0 = time.perf_counter()
    sweep_seed = int(rng.integers(2**31))
    if sweep is None:
        sweep, sweep_truth = render_sweep(rig, real, noise, sweep_seed, spp=sweep_spp, noiseless=noiseless,
                                          step_deg=sweep_step_deg, progress=pb.update,
                                          on_frame=None if frames is None else frames.sweep_frame)
        times["sweep render + centroid"] = time.perf_counter() - t0
    else:
        sweep, sweep_truth = sweep
    t0 = time.perf_counter()
    cal = fit_sun_sensor(rig, sweep.readings, sweep.uv, order, sigma_uv=sweep.sigma_uv)
    times["sweep least squares"] = time.perf_counter() - t0
    res_px = sweep.uv - sweep_truth.uv_centre  # everything: rendering, detector, centroider
    measured["sun_centroid_rms_px"] = float(np.sqrt(np.mean(res_px**2)))
    measured["sun_centroid_rms_px_xy"] = np.sqrt(np.mean(res_px**2, axis=0)).tolist()

    # ---- steps 2–3 / A, C: the null searches
    searches: list[TracedSearch] = []
    step_a = None
    search_seed = int(rng.integers(2**31))
    if rig.procedure.method == "diaphragm":
        from rigsim.procedures.cube_mirror.concentricity import OffsetMeasurer, concentricity_search
        from rigsim.render.cube_mirror.aiming import ConcentricityRenderer

        resid = []
        flat_dn = None  # the screen's flat frames, taken once: the screen and the aiming camera do not move
        for fi, face in enumerate(rig.procedure.faces):
            pb.set_description(f"concentricity search, face {face}")
            t0 = time.perf_counter()
            renderer = ConcentricityRenderer(rig, real, fi, workers=aiming_workers)
            times[f"aiming-camera scene build, face {face}"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            meas = OffsetMeasurer(rig, real, fi, renderer=renderer, seed=search_seed + fi, noiseless=noiseless,
                                  on_frame=None if frames is None else frames.null_frame, flat_dn=flat_dn)
            res = concentricity_search(rig, real, fi, meas, _encoder_errors(rig, noise, rng), axis_order=order,
                                       threshold_px=threshold, progress=pb.update)
            flat_dn = meas.flat_dn
            times[f"concentricity search, face {face}"] = time.perf_counter() - t0
            searches.append(res)
            # near the null only: further out the hole's lost light scales the offset by ~4 %
            # (harmless for a null search, but not noise)
            resid += [s.measured + meas.bias_px - s.true for s in res.steps if np.max(np.abs(s.true)) < 3.0]
            if repeat_frames and fi == 0:
                pb.set_description("aiming-camera repeatability")
                t0 = time.perf_counter()
                for _ in range(int(repeat_frames)):
                    m, ex, _f = meas(res.final_true_pose_rad)
                    resid.append(m + meas.bias_px - ex)
                    pb.update(1)
                times["aiming-camera repeatability frames"] = time.perf_counter() - t0
            renderer.close()
            del renderer, meas  # the next face's scene is built without this one's still held
        measured.update(_null_noise(resid, "px"))
    else:
        from rigsim.procedures.cube_mirror.autocollimation import (
            FaceReadingMeasurer,
            autocollimator_face_search,
            step_a_align,
        )

        pb.set_description("step A: autocollimator on the plane mirror")
        t0 = time.perf_counter()
        step_a = step_a_align(rig, real, rng, rendered=True, threshold_arcsec=threshold, progress=pb.update,
                              noiseless=noiseless, spp=autocollimator_spp)
        times["step A (plane mirror)"] = time.perf_counter() - t0
        resid = [np.asarray(m) - np.asarray(e) for m, e in zip(step_a.measured_arcsec, step_a.exact_arcsec)]
        rig_c = rig if threshold is None else rig.model_copy(update={
            "autocollimator": rig.autocollimator.model_copy(update={"null_threshold_arcsec": float(threshold)})})
        for fi, face in enumerate(rig.procedure.faces):
            pb.set_description(f"step C: autocollimator null, face {face}")
            t0 = time.perf_counter()
            res = autocollimator_face_search(rig_c, real, fi, step_a.axis_rot, _encoder_errors(rig, noise, rng),
                                             rendered=True, seed=search_seed + fi, noiseless=noiseless,
                                             axis_order=order, progress=pb.update, spp=autocollimator_spp,
                                             on_frame=None if frames is None else frames.null_frame)
            times[f"step C search, face {face}"] = time.perf_counter() - t0
            searches.append(res)
            resid += [s.measured - s.true for s in res.steps]
            if repeat_frames and fi == 0:
                pb.set_description("autocollimator repeatability")
                t0 = time.perf_counter()
                meas = FaceReadingMeasurer(rig, real, face, step_a.axis_rot, rendered=True,
                                           seed=search_seed + 1000, noiseless=noiseless, spp=autocollimator_spp)
                for _ in range(int(repeat_frames)):
                    m, ex, _f = meas(res.final_true_pose_rad)
                    resid.append(np.asarray(m) - np.asarray(ex))
                    pb.update(1)
                times["autocollimator repeatability frames"] = time.perf_counter() - t0
        measured.update(_null_noise(resid, "arcsec"))
    for s in searches:
        if not s.converged:
            raise SearchError(f"face {s.face}: the null search did not converge ({s.message})")

    # ---- step 4 / C3, D: TRIAD and composition
    t0 = time.perf_counter()
    est = estimate(rig, [s.final_reading_rad for s in searches], order, calibration=cal)
    result = compare(rig, est, real)
    times["TRIAD + compose"] = time.perf_counter() - t0
    return RenderedCampaign(rig.name, rig.procedure.method, int(seed), sweep, cal, searches, step_a, result, times,
                            measured, sweep_truth)


# ------------------------------------------------------------------ Monte-Carlo budget (surrogate)

def _exact_null_rig(rig: CubeMirrorRig) -> CubeMirrorRig:
    """The same rig whose searches end exactly on the null (continuous commands, tiny threshold)."""
    proc = rig.procedure.model_copy(update={"command_resolution_deg": 0.0, "max_search_iterations": 30})
    upd = {"procedure": proc}
    if rig.aiming_camera is not None:
        upd["aiming_camera"] = rig.aiming_camera.model_copy(update={"concentric_threshold_px": 1e-4})
    if rig.autocollimator is not None:
        upd["autocollimator"] = rig.autocollimator.model_copy(update={"null_threshold_arcsec": 1e-4})
    return rig.model_copy(update=upd)


def _layout_key(real: Realization, face_index: int) -> bytes:
    """Everything of ``real`` the diaphragm layout and geometry of a face depend on (the true
    turntable axes, beam, cube orientation and that face's normal); not the null bias or encoders."""
    face_normals = [real.face_normals_mount[f] for f in sorted(real.face_normals_mount)]
    parts = [np.array([a.wobble_rad, a.wobble_phase_rad]) for a in real.turntable.axes]
    parts += [a.direction for a in real.turntable.axes] + [real.d_sun_rot, real.R_cube_from_mount] + face_normals
    labels = "".join(a.label for a in real.turntable.axes)
    return f"{face_index}:{labels}".encode() + b"".join(np.asarray(p, np.float64).tobytes() for p in parts)


class _GeometryMemo:
    """Diaphragm geometry per (rig, face, true geometry), computed once per budget: a row whose draws
    leave the turntable and cube ideal (σ1, σ3, σ4, centroid) has one layout for all its trials."""

    def __init__(self, maxsize: int = 64):
        self.maxsize, self._d = maxsize, {}

    def __call__(self, rig: CubeMirrorRig, real: Realization, face_index: int):
        from rigsim.truth.cube_mirror.diaphragm import diaphragm_geometry

        key = (id(rig), _layout_key(real, face_index))
        g = self._d.get(key)
        if g is None:
            g = diaphragm_geometry(rig, real, face_index)
            if len(self._d) >= self.maxsize:
                self._d.pop(next(iter(self._d)))
            self._d[key] = g
        return g


def surrogate_campaign(rig: CubeMirrorRig, real: Realization, noise: Noise, rng: np.random.Generator, *,
                       null_sigma: float, null_mode: str = "search", axis_order: str | None = None,
                       fit_calibration: bool = True) -> CampaignResult:
    """The rendered campaign's procedure with exact measurements plus measured noise.

    ``null_sigma``: 1σ per axis of the null measurement (px for seed 000, arcsec for 001).
    ``null_mode``: ``"search"`` (the rig's threshold and command steps; the start is scattered by
    ± half a command step, the phase of the command grid against the null) or ``"exact"`` (the
    search ends on the null: isolates the other sources).
    """
    order, null_readings, sweep_readings, sweep_uv = surrogate_observations(
        rig, real, noise, rng, null_sigma=null_sigma, null_mode=null_mode, axis_order=axis_order,
        fit_calibration=fit_calibration)
    est = estimate(rig, null_readings, order, sweep_readings=sweep_readings, sweep_uv=sweep_uv)
    return compare(rig, est, real)


def surrogate_observations(rig: CubeMirrorRig, real: Realization, noise: Noise, rng: np.random.Generator, *,
                           null_sigma: float, null_mode: str = "search", axis_order: str | None = None,
                           fit_calibration: bool = True, geometry=None, exact_rig: CubeMirrorRig | None = None):
    """The random part of :func:`surrogate_campaign` (every draw from ``rng``): the sweep and the null
    searches → (axis order, null readings, sweep readings or None, sweep centroids or None).

    ``geometry(rig, real, face_index)``: where the diaphragm geometry comes from (a
    :class:`_GeometryMemo` in the budget; default: computed here). ``exact_rig``: ``_exact_null_rig(rig)``
    if the caller already has it.
    """
    order = axis_order or default_axis_order(rig)
    sweep_readings = sweep_uv = None
    if fit_calibration:  # without it the budget row isolates the other sources (compare: step 1 exact)
        sweep_readings, sweep_uv = simulate_sweep(rig, real, noise, rng)
    r = rig if null_mode == "search" else (exact_rig if exact_rig is not None else _exact_null_rig(rig))
    sig = null_sigma if null_mode == "search" else 0.0
    null_readings = []
    if rig.procedure.method == "diaphragm":
        from rigsim.procedures.cube_mirror.concentricity import OffsetMeasurer, concentricity_search

        q = math.radians(r.procedure.command_resolution_deg)
        for fi in range(2):
            geom = geometry(r, real, fi) if geometry is not None else None
            meas = OffsetMeasurer(r, real, fi, renderer=None, sigma_px=sig, rng=rng, geometry=geom)
            jitter = {a: float(rng.uniform(-q / 2, q / 2)) for a in ("X", "Y")} if q > 0 else None
            res = concentricity_search(r, real, fi, meas, _encoder_errors(rig, noise, rng), axis_order=order,
                                       start_offset_rad=jitter)
            if not res.converged:
                raise SearchError(f"face {res.face}: surrogate search did not converge ({res.message})")
            null_readings.append(res.final_reading_rad)
    else:
        from rigsim.procedures.cube_mirror.autocollimation import autocollimator_face_search, step_a_align

        sa = step_a_align(r, real, rng, rendered=False, reading_sigma_arcsec=sig)
        for fi in range(2):
            res = autocollimator_face_search(r, real, fi, sa.axis_rot, _encoder_errors(rig, noise, rng),
                                             rendered=False, seed=int(rng.integers(2**31)), reading_sigma_arcsec=sig,
                                             axis_order=order)
            if not res.converged:
                raise SearchError(f"face {res.face}: surrogate search did not converge ({res.message})")
            null_readings.append(res.final_reading_rad)
    return order, null_readings, sweep_readings, sweep_uv


@dataclass
class RenderedBudget:
    rows: list[BudgetRow]
    errors: dict[str, np.ndarray]  # row name → (n, 3) per-trial errors, arcsec
    sun_centroid_sigma_px: float
    null_sigma: float
    null_unit: str
    paper_rows: list[str]  # rows whose RSS the "together" row is compared with
    together_row: str

    def rss_of_sources(self) -> np.ndarray:
        sig = np.array([r.sigma_arcsec for r in self.rows if r.source in self.paper_rows])
        return np.sqrt((sig**2).sum(axis=0))

    def together(self) -> BudgetRow:
        return next(r for r in self.rows if r.source == self.together_row)


def rendered_budget_sources(rig: CubeMirrorRig, null_sigma: float, centroid_sigma_px: float):
    """name → (drawn rig errors, Noise, null mode, paper σ)."""
    full = noise_from_rig(rig)
    z = Noise()
    enc = replace(z, encoder_sigma_rad=full.encoder_sigma_rad)
    cen = replace(z, centroid_sigma_px=centroid_sigma_px)
    if rig.procedure.method == "diaphragm":
        thr = rig.aiming_camera.concentric_threshold_px
        q = rig.procedure.command_resolution_deg
        return {
            f"σ1 aiming null (search: < {thr:g} px, {q:g}° steps, measured centre noise)": (set(), z, "search", 2.34),
            "σ2 turntable perpendicularity": ({"perpendicularity"}, z, "exact", 2.0),
            "σ3 aiming-camera mounting": ({"mounting"}, z, "exact", 2.0),
            "σ4 angle readout": (set(), enc, "exact", 0.4),
            "sun-sensor centroid noise (measured on rendered frames)": (set(), cen, "exact", None),
        }
    thr = rig.autocollimator.null_threshold_arcsec
    return {
        f"autocollimator nulls (steps A and C: < {thr:g}″, measured reading noise)": (set(), z, "search", None),
        "turntable perpendicularity": ({"perpendicularity"}, z, "exact", None),
        "plane-mirror perpendicularity": ({"plane_mirror"}, z, "exact", None),
        "angle readout": (set(), enc, "exact", None),
        "sun-sensor centroid noise (measured on rendered frames)": (set(), cen, "exact", None),
    }


def rendered_error_budget(rig: CubeMirrorRig, n_trials: int, seed: int, *, null_sigma: float, centroid_sigma_px: float,
                          axis_order: str | None = None, progress=None, workers: int | None = None) -> RenderedBudget:
    """Per-axis σ of the R(cube←sun) error: each source alone, the paper's sources together (seed
    000) or every image-independent source together (001), and everything together.

    ``workers``: processes that run the estimates (sweep fit, TRIAD) beside this one, which draws
    the trials and runs the searches in order (default :func:`~rigsim.procedures.cube_mirror.estimate_pool.default_workers`);
    the result does not depend on it."""
    from rigsim.procedures.cube_mirror.estimate_pool import EstimatePool, default_workers

    pb = progress if progress is not None else _NullProgress()
    rng = np.random.default_rng(seed)
    sources = rendered_budget_sources(rig, null_sigma, centroid_sigma_px)
    memo = _GeometryMemo() if rig.procedure.method == "diaphragm" else None
    exact_rig = _exact_null_rig(rig)
    pending: list[tuple[str, float | None, list]] = []  # row name, paper σ, per-trial futures of the error

    def trials(pool: EstimatePool, name: str, drawn: set, noise: Noise, mode: str, paper) -> None:
        pb.set_description(f"budget: {name[:40]}")
        fit = noise.centroid_sigma_px > 0 or any(noise.encoder_sigma_rad.values()) or "perpendicularity" in drawn
        futures = []
        for _ in range(n_trials):
            real = draw_realization(rig, rng, drawn)
            order, nulls, sweep_readings, sweep_uv = surrogate_observations(
                rig, real, noise, rng, null_sigma=null_sigma, null_mode=mode, axis_order=axis_order,
                fit_calibration=fit, geometry=memo, exact_rig=exact_rig)
            futures.append(pool.submit(real, nulls, order, sweep_readings, sweep_uv))
            pb.update(1)
        pending.append((name, paper, futures))

    names = list(sources)
    full = noise_from_rig(rig)
    readout = replace(Noise(), encoder_sigma_rad=full.encoder_sigma_rad)
    with EstimatePool(rig, default_workers() if workers is None else int(workers)) as pool:
        for name, (drawn, noise, mode, paper) in sources.items():
            trials(pool, name, drawn, noise, mode, paper)
        if rig.procedure.method == "diaphragm":
            paper_rows = [n for n in names if sources[n][3] is not None]
            together = "σ1..σ4 together (paper's sources)"
            trials(pool, together, {"perpendicularity", "mounting"}, readout, "search", PAPER_RSS_ARCSEC)
        else:
            paper_rows = names[:-1]
            together = "all but the sun-sensor centroid, together"
            trials(pool, together, {"perpendicularity", "plane_mirror"}, readout, "search", None)
        trials(pool, "all sources together", {"perpendicularity", "mounting", "plane_mirror"},
               Noise(full.encoder_sigma_rad, 0.0, centroid_sigma_px), "search", None)
        rows: list[BudgetRow] = []
        errs: dict[str, np.ndarray] = {}
        for name, paper, futures in pending:
            e = np.array([f.result() for f in futures]).reshape(n_trials, 3)
            errs[name] = e
            rows.append(BudgetRow(name, e.std(axis=0, ddof=1), paper, n_trials))
    unit = "px" if rig.procedure.method == "diaphragm" else "arcsec"
    return RenderedBudget(rows, errs, centroid_sigma_px, null_sigma, unit, paper_rows, together)


def budget_trials_count(rig: CubeMirrorRig, n_trials: int) -> int:
    return n_trials * (len(rendered_budget_sources(rig, 0.0, 0.0)) + 2)


__all__ = [
    "ARCSEC_PER_RAD",
    "RAD_PER_ARCSEC",
    "RenderedBudget",
    "RenderedCampaign",
    "budget_trials_count",
    "expected_frames",
    "rendered_budget_sources",
    "rendered_error_budget",
    "run_rendered_campaign",
    "surrogate_campaign",
    "surrogate_observations",
]
