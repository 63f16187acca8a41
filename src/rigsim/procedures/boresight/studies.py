"""The analyses of seed 003 (section 3: Figs 4–8; section 4: the thermal-vacuum orbit scenario)
and the check of each claim the paper makes, under rigsim's documented model.

Monte Carlo (Figs 4–7): the exact forward model gives the true spots of the reference state and of
a perturbed state (α = β = γ = ``perturbation_arcsec``, Δf = ``perturbation_delta_f_um``); Gaussian
centroid noise σ is added to each coordinate of the measured spots and σ/√N to the reference
spots (N reference measurements, eqs 16–17); both methods estimate; the errors against truth are
reported as 1σ (RMS about the mean) and 3σ (the paper's eqs 19–22 are 3σ). Fig 8 is noise-free
(the systematic residual; with noise both methods share the same spots, so the difference of their
means converges to it). Numbers are in µm (Δf) and arcsec (angles).

Every analysis runs under a loop model (``loop_model``, :mod:`rigsim.optics.loop_models`): it sets
the forward model that makes the spots and the loop the consistent DVAD inverts. The rendered orbit
scenario is always the physical loop (Mitsuba renders physics).
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.estimation.dvad import estimate
from rigsim.frames import ARCSEC_PER_RAD
from rigsim.optics.line_camera import CameraGeometry, relative_rotation, rotation_xyz, small_angles_arcsec
from rigsim.optics.line_camera import spots_uv  # noqa: F401 (importable from here, as before)
from rigsim.optics.loop_models import LOOP_MODELS, check_loop_model, loop_spots_uv
from rigsim.rig.boresight import BoresightRig
from rigsim.truth.boresight import OrbitTruth, orbit_truth

__all__ = ["PARAMS", "mc_errors", "predicted_3sigma", "sweep", "fig8_residual", "rotation_order",
           "orbit_truth", "run_orbit", "orbit_from_frames", "claims", "run_study", "EQ20_COS2BETA", "eq20_focal_threshold",
           "beta_noise_excess", "loop_model_comparison", "orbit_frame_pool"]

PARAMS = ("delta_f_um", "alpha_arcsec", "beta_arcsec", "gamma_arcsec")
AS = ARCSEC_PER_RAD
EQ20_COS2BETA = ("reevaluated", "fixed")


def predicted_3sigma(geom: CameraGeometry, sigma_px: float) -> dict:
    """Eqs 19–22 (3σ) for centroid error σ."""
    d, F, L, Kf = geom.pitch_mm, geom.F, geom.L_mm, geom.telecentric_factor
    r2 = math.sqrt(2.0)
    return {
        "delta_f_um": 3 * Kf * r2 * d / 2 * F / L * sigma_px * 1e3,
        "alpha_arcsec": 3 * r2 * d * math.cos(geom.beta_half_angle_rad) ** 2 / (2 * 2 * F) * sigma_px * AS,
        "beta_arcsec": 3 * r2 * d * math.cos(geom.off_axis_rad) ** 2 / (2 * 2 * F) * sigma_px * AS,
        "gamma_arcsec": 3 * r2 * d / 2 * sigma_px / L * AS,
    }


def eq20_focal_threshold(geom: CameraGeometry, sigma_px: float, target_arcsec: float = 0.1, *,
                         cos2beta: str = "reevaluated", tol_mm: float = 1e-9) -> dict:
    """Focal length (mm) at which eq 20's 3σ α error reaches ``target_arcsec`` for centroid error σ.

    Eq 20 is 3·√2·d·cos²β·σ/(4F): ``cos2beta="fixed"`` keeps β (half the angle between OA0 and OB0)
    at ``geom``'s focal length; ``"reevaluated"`` recomputes β with the focal length being solved for
    (L and ω fixed), F = K·cos²β(F), by fixed-point iteration. Returns {"F_mm", "beta_half_angle_deg",
    "cos2beta"}."""
    if cos2beta not in EQ20_COS2BETA:
        raise ValueError(f"cos2beta = {cos2beta!r}: allowed {EQ20_COS2BETA}")
    K = 3 * math.sqrt(2.0) * geom.pitch_mm * sigma_px / (4 * target_arcsec / AS)
    beta = geom.beta_half_angle_rad
    F = K * math.cos(beta) ** 2
    if cos2beta == "reevaluated":
        for _ in range(200):
            beta = geom.with_(focal_length_mm=F).beta_half_angle_rad
            F_new = K * math.cos(beta) ** 2
            done = abs(F_new - F) < tol_mm
            F = F_new
            if done:
                break
        else:
            raise RuntimeError("eq 20 threshold: the fixed-point iteration did not converge")
    return {"F_mm": F, "beta_half_angle_deg": math.degrees(beta), "cos2beta": cos2beta}


def beta_noise_excess(geom: CameraGeometry) -> float:
    """σ_β of the physical-loop DVAD over eq 21's, to first order: √(1 + (2F·tan ω / L)²) / cos²ω.

    Under the physical loop a focal change moves both spots in x by (2/Kf)·Δf·tan ω and β moves them
    apart in y by β·L·tan ω, so β and Δf are solved from the mean x and the y difference together."""
    F, L, w = geom.F, geom.L_mm, geom.off_axis_rad
    return math.sqrt(1.0 + (2.0 * F * math.tan(w) / L) ** 2) / math.cos(w) ** 2


def _state(geom, arcsec, df_um, n=1):
    a = arcsec / AS
    E = rotation_xyz(a, a, a)
    return np.broadcast_to(E, (n, 3, 3)), np.full(n, df_um * 1e-3)


def _estimate(geom, ref, meas, method, reading, loop_model):
    if method == "dvad_physical_loop":      # the physical loop's DVAD, whatever made the spots
        return estimate(geom, ref, meas, "dvad", reading, loop_model="physical")
    return estimate(geom, ref, meas, method, reading, loop_model=loop_model)


def mc_errors(geom: CameraGeometry, sigma_px: float, runs: int, rng: np.random.Generator, *,
              arcsec: float = 10.0, df_um: float = 10.0, n_ref: int = 100, reading: str = "consistent",
              methods=("dvad", "simplified"), loop_model: str = "physical") -> dict:
    """Monte-Carlo errors against truth: {method: {param: (runs,) errors}} (µm / arcsec).

    ``loop_model`` makes the true spots and is the loop DVAD inverts; method ``"dvad_physical_loop"``
    is the physical loop's DVAD on the same spots."""
    check_loop_model(loop_model)
    E, df = _state(geom, arcsec, df_um)
    truth_ref = loop_spots_uv(geom, loop_model=loop_model)
    truth_meas = loop_spots_uv(geom, E[0], df[0], loop_model=loop_model)
    ref = truth_ref + rng.normal(0.0, sigma_px / math.sqrt(n_ref), (runs, 2, 2))
    meas = truth_meas + rng.normal(0.0, sigma_px, (runs, 2, 2))
    true = np.array([df_um, arcsec, arcsec, arcsec])
    out = {}
    for m in methods:
        est = _estimate(geom, ref, meas, m, reading, loop_model)
        vals = np.column_stack([est.delta_f_mm * 1e3, est.angles_arcsec])
        out[m] = {p: vals[:, k] - true[k] for k, p in enumerate(PARAMS)}
        out[m]["_R"] = est.rotation()
    out["_E_true"] = E[0]
    return out


def _stats(err: np.ndarray) -> dict:
    return {"mean": float(np.mean(err)), "std": float(np.std(err, ddof=1)), "three_sigma": float(3 * np.std(err, ddof=1)),
            "rms": float(np.sqrt(np.mean(err ** 2)))}


def sweep(geoms: list[CameraGeometry], xs, sigma_px, runs: int, seed: int, *, arcsec=10.0, df_um=10.0,
          n_ref=100, reading="consistent", relative_with: CameraGeometry | None = None,
          loop_model: str = "physical") -> dict:
    """One Monte Carlo per point (geometry and σ may both vary): rows of 1σ/3σ per method/param,
    the eqs 19–22 prediction, and (if ``relative_with``) the 3σ of the relative angle between this
    camera and a second, identical-noise camera; all under ``loop_model``."""
    rng = np.random.default_rng(seed)
    rows = []
    sigmas = np.broadcast_to(np.asarray(sigma_px, float), (len(xs),))
    for x, g, s in zip(xs, geoms, sigmas):
        e = mc_errors(g, float(s), runs, rng, arcsec=arcsec, df_um=df_um, n_ref=n_ref, reading=reading,
                      loop_model=loop_model)
        row = {"x": float(x), "sigma_px": float(s), "pred3": predicted_3sigma(g, float(s))}
        for m in ("dvad", "simplified"):
            row[m] = {p: _stats(e[m][p]) for p in PARAMS}
        if relative_with is not None:
            e2 = mc_errors(relative_with, float(s), runs, rng, arcsec=arcsec, df_um=df_um, n_ref=n_ref, reading=reading,
                           methods=("dvad",), loop_model=loop_model)
            Rt = relative_rotation(e["_E_true"], e2["_E_true"], g, relative_with)
            Re = relative_rotation(e["dvad"]["_R"], e2["dvad"]["_R"], g, relative_with)
            err = small_angles_arcsec(Re @ np.swapaxes(Rt, -1, -2)[None])
            row["relative_dvad"] = {ax: _stats(err[:, k]) for k, ax in enumerate("xyz")}
        rows.append(row)
    return {"rows": rows}


def fig8_residual(geom: CameraGeometry, ranges_px, tilts_deg, *, reading="consistent", df_um: float = 0.0,
                  loop_model: str = "physical") -> dict:
    """Noise-free |DVAD − simplified| and each method's error against truth, for perturbations
    α = β = γ = r·d/(2F) (a rotation that alone would move a spot by r px) and tilts θm1 = −θm2,
    under ``loop_model``."""
    out = {"ranges_px": list(map(float, ranges_px)), "tilts_deg": list(map(float, tilts_deg)), "rows": []}
    for t in tilts_deg:
        g = geom.with_(tilt_rad=(math.radians(t), -math.radians(t)))
        for r in ranges_px:
            a = r * g.pitch_mm / (2 * g.F)
            E = rotation_xyz(a, a, a)
            ref = loop_spots_uv(g, loop_model=loop_model)
            meas = loop_spots_uv(g, E, df_um * 1e-3, loop_model=loop_model)
            true = np.array([df_um, a * AS, a * AS, a * AS])
            res = {}
            for m in ("dvad", "simplified"):
                est = estimate(g, ref, meas, m, reading, loop_model=loop_model)
                res[m] = np.concatenate([np.atleast_1d(est.delta_f_mm * 1e3), np.ravel(est.angles_arcsec)])
            pdvad = estimate(g, ref, meas, "dvad", "as_printed")
            res["dvad_as_printed"] = np.concatenate([np.atleast_1d(pdvad.delta_f_mm * 1e3), np.ravel(pdvad.angles_arcsec)])
            out["rows"].append({
                "tilt_deg": float(t), "range_px": float(r), "angle_arcsec": float(a * AS),
                "diff": dict(zip(PARAMS, np.abs(res["dvad"] - res["simplified"]).tolist())),
                "diff_as_printed": dict(zip(PARAMS, np.abs(res["dvad_as_printed"] - res["simplified"]).tolist())),
                "err_simplified": dict(zip(PARAMS, (res["simplified"] - true).tolist())),
                "err_dvad": dict(zip(PARAMS, (res["dvad"] - true).tolist())),
                "err_dvad_as_printed": dict(zip(PARAMS, (res["dvad_as_printed"] - true).tolist())),
            })
    return out


def rotation_order(angle_arcsec: float = 120.0) -> dict:
    """How far apart the six Euler orders of α = β = γ = angle are (the paper's eq 5 / '2′ → 0.1″').

    Returns the largest per-axis difference of the XYZ angles of each order's matrix from the
    common value, and the largest angle between two orders' matrices (arcsec)."""
    a = angle_arcsec / AS
    mats = {o: Rotation.from_euler(o, [a, a, a]).as_matrix() for o in ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")}
    per_axis = 0.0
    for R in mats.values():
        eul = Rotation.from_matrix(R).as_euler("XYZ")
        per_axis = max(per_axis, float(np.abs(eul - a).max() * AS))
    pair = 0.0
    for R1 in mats.values():
        for R2 in mats.values():
            pair = max(pair, float(Rotation.from_matrix(R1 @ R2.T).magnitude() * AS))
    return {"angle_arcsec": angle_arcsec, "max_per_axis_arcsec": per_axis, "max_between_orders_arcsec": pair}


def _fit_sine(t, y, period):
    A = np.column_stack([np.sin(2 * np.pi * t / period), np.cos(2 * np.pi * t / period), np.ones_like(t)])
    c, *_ = np.linalg.lstsq(A, y, rcond=None)
    return float(np.hypot(c[0], c[1])), float(np.degrees(np.arctan2(c[1], c[0]))), float(c[2])


def _dense(rig, geoms, n=400) -> dict:
    o = rig.orbit
    d = orbit_truth(rig, geoms, np.linspace(0.0, o.orbits * o.period_min, n))
    return {"t_min": d.t_min.tolist(), "relative_arcsec": d.relative.tolist(),
            "delta_f_um": [(x * 1e3).tolist() for x in d.delta_f_mm]}


def _orbit_estimates(geoms, ref_uv, meas, truth: OrbitTruth, o, reading) -> dict:
    est = {}
    for method in ("dvad", "simplified"):
        e = [estimate(geoms[c], ref_uv[c], meas[c], method, reading) for c in range(2)]
        Rrel = relative_rotation(e[0].rotation(), e[1].rotation(), geoms[0], geoms[1])
        rel = small_angles_arcsec(Rrel)
        err_rel = small_angles_arcsec(Rrel @ np.swapaxes(truth.relative_R, 1, 2))
        est[method] = {
            "relative_arcsec": rel.tolist(),
            "relative_error_arcsec": err_rel.tolist(),
            "relative_rms_arcsec": np.sqrt(np.mean(err_rel ** 2, axis=0)).tolist(),
            "delta_f_um": [(x.delta_f_mm * 1e3).tolist() for x in e],
            "delta_f_error_um": [((x.delta_f_mm - truth.delta_f_mm[c]) * 1e3).tolist() for c, x in enumerate(e)],
            "delta_f_rms_um": [float(np.sqrt(np.mean(((x.delta_f_mm - truth.delta_f_mm[c]) * 1e3) ** 2))) for c, x in enumerate(e)],
            "camera_angles_arcsec": [x.angles_arcsec.tolist() for x in e],
        }
        amp, phase, off = _fit_sine(truth.t_min, rel[:, 1], o.period_min)
        tamp, tphase, _ = _fit_sine(truth.t_min, truth.relative[:, 1], o.period_min)
        est[method]["pitch_fit"] = {"amplitude_arcsec": amp, "phase_deg": phase, "offset_arcsec": off,
                                    "true_amplitude_arcsec": tamp, "true_phase_deg": tphase}
    return est


def run_orbit(rig: BoresightRig, *, seed: int = 2023, progress=None, centroider: str | None = None,
              reading: str = "consistent", spp: int | None = None, measurements: int | None = None,
              jitter_px: float = 0.1, on_frame=None, workers: int | None = None, frame_pool=None) -> dict:
    """Render the four CMOS ROIs at every measurement of the orbit scenario, centroid, estimate
    per camera (DVAD, and the simplified method for comparison), form the relative angle and compare
    with truth. ``progress(n)`` is called after each rendered frame. ``centroider``: a method of
    :func:`rigsim.imaging.centroid` (default the rig's ``[orbit] centroider``), or ``"model"``: the
    forward-model fit of the core's image (:mod:`rigsim.procedures.boresight.model_spot`).

    ``jitter_px``: the same frames are also evaluated with Gaussian noise of this σ added to every
    measured centroid (an *equivalent* centroid error, the paper's 0.1 px: vibration, thermal
    gradients, stray light — not modelled physically); key ``estimates_jitter``.
    ``on_frame(stage, camera, detector, k, frame)`` sees every rendered ROI (stage "reference" or
    "measurement"), e.g. to write it as a file.
    ``workers``: processes rendering the frames (1, or 2: camera 1's frames in a worker subprocess,
    :mod:`~rigsim.procedures.boresight.frame_pool`); default 2 on two or more CPUs. The frames and every
    number are the same for any ``workers``. ``frame_pool``: one from :func:`orbit_frame_pool`, started
    earlier (then ``workers`` is its, and the caller closes it)."""
    from rigsim.procedures.boresight.frame_pool import render_task
    from rigsim.render.boresight import LoopRenderer

    t_start = time.perf_counter()
    centroider = rig.orbit.centroider if centroider is None else centroider
    geoms = [CameraGeometry.from_rig(c) for c in rig.cameras]
    if len(geoms) < 2:
        raise ValueError("the orbit scenario needs two cameras")
    o = rig.orbit
    n_meas = measurements or o.measurements
    own_pool = frame_pool is None
    pool = orbit_frame_pool(rig, workers, spp) if own_pool else frame_pool
    try:
        truth = orbit_truth(rig, geoms, np.linspace(0.0, o.orbits * o.period_min, n_meas))
        # every frame as a task (camera, detector, E, Δf, seed, with truth), in the order they are used
        tasks = [(c, j, None, 0.0, seed * 1000 + 100 * c + 10 * j + k, k == 0)
                 for c in range(2) for j in range(2) for k in range(o.reference_frames)]
        tasks += [(c, j, truth.E[c][k], truth.delta_f_mm[c][k], seed * 7919 + 1000 * k + 10 * c + j, True)
                  for k in range(n_meas) for c in range(2) for j in range(2)]
        pool.start(tasks)
        rends = {(c, j): LoopRenderer(rig, c, j, spp=spp) for c in range(2) if c not in pool.remote for j in range(2)}
        for r in rends.values():
            r.warm_up()
        t_warm = time.perf_counter() - t_start
        frames = iter(range(len(tasks)))

        def next_frame():
            i = next(frames)
            fr = pool.result(i)
            if fr is None:   # this process's camera, or the worker failed
                key = tasks[i][:2]
                if key not in rends:
                    rends[key] = LoopRenderer(rig, key[0], key[1], spp=spp)
                fr = render_task(rends, tasks[i])
            return fr

        res = _orbit_frames(rig, geoms, truth, next_frame, seed=seed, progress=progress, centroider=centroider,
                            reading=reading, jitter_px=jitter_px, on_frame=on_frame)
    finally:
        if own_pool:
            pool.close()
    res.update({"seconds": time.perf_counter() - t_start, "warm_up_seconds": t_warm,
                "spp": rends[(0, 0)].spp, "window_px": rends[(0, 0)].window_px})
    return res


def orbit_from_frames(rig: BoresightRig, frames, *, seed: int = 2023, centroider: str | None = None,
                      reading: str = "consistent", measurements: int | None = None) -> dict:
    """:func:`run_orbit` on frames already rendered, in the order its ``on_frame`` saw them (the
    reference frames, then every measurement's four): the same result for another centroider or
    reading without rendering again (``seconds`` and the render keys are not set)."""
    o = rig.orbit
    geoms = [CameraGeometry.from_rig(c) for c in rig.cameras]
    n_meas = measurements or o.measurements
    frames = list(frames)
    if len(frames) != 4 * (o.reference_frames + n_meas):
        raise ValueError(f"{len(frames)} frames for {o.reference_frames} reference frames and {n_meas} measurements "
                         f"of four ROIs each")
    truth = orbit_truth(rig, geoms, np.linspace(0.0, o.orbits * o.period_min, n_meas))
    it = iter(frames)
    return _orbit_frames(rig, geoms, truth, lambda: next(it), seed=seed, progress=None,
                         centroider=rig.orbit.centroider if centroider is None else centroider, reading=reading,
                         jitter_px=0.0, on_frame=None)


def orbit_frame_pool(rig: BoresightRig, workers: int | None = None, spp: int | None = None):
    """The :class:`~rigsim.procedures.boresight.frame_pool.FramePool` of :func:`run_orbit` for ``workers``
    processes (``None``: :func:`~rigsim.procedures.boresight.frame_pool.default_workers`): with 2, a worker
    renders camera 1's frames. Started early (e.g. before the analyses) it has its kernels compiled when the
    orbit begins; pass it as ``run_orbit(frame_pool=…)`` and close it."""
    from rigsim.procedures.boresight.frame_pool import FramePool, default_workers

    workers = default_workers() if workers is None else workers
    if isinstance(workers, bool) or int(workers) != workers or workers < 1:
        raise ValueError(f"workers = {workers!r}: must be an integer >= 1")
    return FramePool(rig, {1} if workers > 1 and len(rig.cameras) >= 2 else (), spp=spp)


def _orbit_frames(rig, geoms, truth, next_frame, *, seed, progress, centroider, reading, jitter_px, on_frame) -> dict:
    """:func:`run_orbit` from the frames (``next_frame()``, in the tasks' order) on: centroids, estimates, truth."""
    import warnings

    from rigsim.imaging import NoiseModel
    from rigsim.procedures.boresight.model_spot import roi_centroids

    noise = NoiseModel.from_detector(rig.detector)
    o = rig.orbit

    def centroid_rois(rois, origins, *, method, noise, camera):
        return roi_centroids(rig, rois, origins, method=method, noise=noise, camera=camera)
    n_meas = len(truth.t_min)
    step = 0

    def tick():
        if progress:
            progress(1)

    # reference: the mean of many frames at the reference state (eqs 16-17)
    ref_uv = np.zeros((2, 2, 2))
    ref_single = np.zeros((2, o.reference_frames, 2, 2))
    fidelity = []
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        for c in range(2):
            for j in range(2):
                rois, origins = [], []
                for k in range(o.reference_frames):
                    fr = next_frame()
                    if on_frame is not None:
                        on_frame("reference", c, j, k, fr)
                    if k == 0:
                        fidelity.append(float(np.abs(fr.photon_centroid() - np.array(fr.truth["pixel_centroid_uv"])).max()))
                    rois.append(fr.dn)
                    origins.append(fr.origin_uv)
                    tick()
                m = centroid_rois(np.stack(rois), origins, method=centroider, noise=noise, camera=c)
                if not m.valid.all():
                    raise RuntimeError(f"reference spot of camera {c} M{j + 1} not measurable")
                ref_single[c, :, j] = m.uv
                ref_uv[c, j] = m.uv.mean(axis=0)
        meas = np.zeros((2, n_meas, 2, 2))
        centroid_err = []
        sample_rois = []
        for k in range(n_meas):
            for c in range(2):
                for j in range(2):
                    fr = next_frame()
                    if on_frame is not None:
                        on_frame("measurement", c, j, k, fr)
                    fidelity.append(float(np.abs(fr.photon_centroid() - np.array(fr.truth["pixel_centroid_uv"])).max()))
                    m = centroid_rois(fr.dn, [fr.origin_uv], method=centroider, noise=noise, camera=c)
                    if not m.valid.all():
                        raise RuntimeError(f"measurement {k}: spot of camera {c} M{j + 1} not measurable")
                    meas[c, k, j] = m.uv[0]
                    centroid_err.append(m.uv[0] - np.array(fr.truth["spot_uv"]))
                    if k == n_meas // 4:
                        sample_rois.append({"camera": geoms[c].name, "detector": f"M{j + 1}", "dn": fr.dn,
                                            "origin_uv": fr.origin_uv, "spot_uv": fr.truth["spot_uv"],
                                            "measured_uv": m.uv[0].tolist(), "t_min": float(truth.t_min[k])})
                    step += 1
                    tick()
    res = {"t_min": truth.t_min.tolist(), "period_min": o.period_min, "measurements": n_meas,
           "reference_frames": o.reference_frames, "centroider": centroider, "reading": reading,
           "jitter_px": jitter_px}
    res["estimates"] = _orbit_estimates(geoms, ref_uv, meas, truth, o, reading)
    if jitter_px > 0:
        jr = np.random.default_rng(seed + 99)
        res["estimates_jitter"] = _orbit_estimates(geoms, ref_uv, meas + jr.normal(0.0, jitter_px, meas.shape),
                                                   truth, o, reading)
    # steady state: each reference frame on its own against the mean reference (white noise)
    ss = []
    for k in range(o.reference_frames):
        e = [estimate(geoms[c], ref_uv[c], ref_single[c, k], "dvad", reading) for c in range(2)]
        ss.append(small_angles_arcsec(relative_rotation(e[0].rotation(), e[1].rotation(), geoms[0], geoms[1])))
    ss = np.array(ss)
    ce = np.array(centroid_err)
    res.update({
        "true_relative_arcsec": truth.relative.tolist(),
        "truth_dense": _dense(rig, geoms),
        "true_delta_f_um": [(x * 1e3).tolist() for x in truth.delta_f_mm],
        "steady_state_relative_std_arcsec": np.std(ss, axis=0, ddof=1).tolist(),
        "reference_centroid_std_px": np.std(ref_single, axis=1, ddof=1).mean(axis=(0, 1)).tolist(),
        "_rois": sample_rois,
        "centroid_error_px": {"mean": ce.mean(axis=0).tolist(), "std": ce.std(axis=0, ddof=1).tolist(),
                              "max_abs": np.abs(ce).max(axis=0).tolist()},
        "render_fidelity_max_px": float(max(fidelity)),
        "_spots": {"geoms": geoms, "ref_uv": ref_uv, "meas": meas, "truth": truth, "reference_frames": o.reference_frames,
                   "ref_std": np.std(ref_single, axis=1, ddof=1)},
        "frames_rendered": int(4 * (o.reference_frames + n_meas)),
    })
    return res


# ------------------------------------------------------------------------------ the claims
def _verdict(ok: bool | None) -> str:
    return {True: "holds", False: "does not hold", None: "partly"}[ok]


_NOTES = {
    "eqs19_22": {
        "physical": "they describe the simplified method; the exact DVAD separates Δf from β (a focal change moves both "
                    "off-axis spots in x by 2Δf·tan ω/Kf), which costs β noise; the simplified method is quieter in β "
                    "but biased by Δf (0.007″ per µm)",
        "paper": "under the paper's loop a focal change moves the spots in y only: the DVAD takes Δf from eq 15 alone and "
                 "pays no β noise; its rotation step keeps the off-axis geometry's gains, 0.55 % off eqs 2 and 4"},
    "fig8": {
        "physical": "the cause is not the rotation order: eqs 2 and 4 carry a 0.55 % first-order gain error in the "
                    "off-axis geometry (ω = 6°). The printed DVAD (eq 12's bisector of unnormalised vectors) has a "
                    "0.69 % gain error of its own, so printed DVAD and simplified agree to 0.03″ at 200 px",
        "paper": "under the paper's loop eqs 1–4 are its exact inverse at zero tilt, so the difference is the DVAD's: "
                 "its rotation step maps spot motion with the off-axis geometry's gains, 0.55 % off eqs 2 and 4"},
    "delta_f": {
        "physical": "the simplified method's Δf error is β·Kf·F·tan ω (β moves the two spots apart in y)",
        "paper": "under the paper's loop β moves no spot in y: eq 1 is exact at zero tilt; only the detector tilt leaks"},
    "rotation_order": {
        "physical": "the order effect is as stated, but it is not what limits the simplified method",
        "paper": "the paper's loop is linear in tan of the XYZ angles: the simplified method inverts it exactly, so "
                 "the order effect does not arise in it"},
}


def claims(results: dict) -> list[dict]:
    """Each claim of the paper, the measured numbers and a verdict (see docs/boresight.md), under the
    loop model of ``results["_loop_model"]`` (default physical)."""
    lm = results.get("_loop_model", "physical")
    out = []
    f4 = results["fig4"]["rows"]
    sig = np.array([r["sigma_px"] for r in f4])
    worst = 0.0
    for m in ("dvad", "simplified"):
        for p in PARAMS:
            y = np.array([r[m][p]["std"] for r in f4])
            k = float(np.sum(sig * y) / np.sum(sig * sig))
            worst = max(worst, float(np.max(np.abs(y - k * sig) / (k * sig))))
    out.append({"claim": "errors grow linearly with the centroid error (Fig 4)",
                "measured": f"1σ errors / σ constant within {100 * worst:.1f} % over σ = {sig.min():g}…{sig.max():g} px "
                            "(Monte-Carlo sampling error ≈ 3 %)",
                "verdict": _verdict(worst < 0.08)})
    # 0.1 px for better than 1" (relative angle between the boresights, 3-sigma)
    rows = [r for r in f4 if "relative_dvad" in r]
    if rows:
        ss = np.array([r["sigma_px"] for r in rows])

        def sigma_at_1(vals):
            k = float(np.sum(ss * vals) / np.sum(ss * ss))
            return 1.0 / k, 0.1 * k
        xy = np.array([max(r["relative_dvad"]["x"]["three_sigma"], r["relative_dvad"]["y"]["three_sigma"]) for r in rows])
        zz = np.array([r["relative_dvad"]["z"]["three_sigma"] for r in rows])
        s_xy, at_xy = sigma_at_1(xy)
        s_z, at_z = sigma_at_1(zz)
        out.append({"claim": "a centroid error better than 0.1 px is needed for a relative angle between the boresights "
                             "better than 1″ (Fig 4)",
                    "measured": f"3σ at 0.1 px: boresight direction (x, y) {at_xy:.2f}″, about the boresight (z) {at_z:.2f}″; "
                                f"1″ is reached at σ ≈ {s_xy:.2f} px (x, y) and {s_z:.2f} px (z)",
                    "verdict": _verdict(None if s_xy > 0.12 else True),
                    "note": "0.1 px is sufficient, not necessary: the boresight angle allows ~5× more centroid error; "
                            "the rotation about the boresight (lever arm L, not F) is the tightest"})
    # eqs 19-22 vs Monte Carlo
    r01 = [r for r in f4 if abs(r["sigma_px"] - 0.1) < 1e-9][0]
    rat = {m: {p: r01[m][p]["three_sigma"] / r01["pred3"][p] for p in PARAMS} for m in ("simplified", "dvad")}
    short = {"delta_f_um": "Δf", "alpha_arcsec": "α", "beta_arcsec": "β", "gamma_arcsec": "γ"}
    ok_s = all(abs(v - 1) < 0.1 for v in rat["simplified"].values())
    ok_d = all(abs(v - 1) < 0.1 for v in rat["dvad"].values())
    out.append({"claim": "eqs 19–22 give the errors (3σ), for DVAD as for the simplified method (section 3.1)",
                "measured": "Monte Carlo / eq at 0.1 px — simplified: " + ", ".join(f"{short[p]} {v:.2f}" for p, v in rat["simplified"].items())
                            + "; DVAD: " + ", ".join(f"{short[p]} {v:.2f}" for p, v in rat["dvad"].items()),
                "verdict": _verdict(True if (ok_s and ok_d) else (None if ok_s else False)),
                "note": _NOTES["eqs19_22"][lm]})
    # focal length
    f6 = results["fig6"]["rows"]
    F = np.array([r["x"] for r in f6])
    thr = {}
    for m in ("simplified", "dvad"):
        ab = np.array([max(r[m]["alpha_arcsec"]["three_sigma"], r[m]["beta_arcsec"]["three_sigma"]) for r in f6])
        below = np.nonzero(ab < 0.1)[0]
        if len(below) == 0:
            Fx = float("nan")
        elif below[0] == 0:
            Fx = float(F[0])
        else:   # log-log interpolation between the last point above and the first below 0.1"
            i = below[0]
            w = (np.log(0.1) - np.log(ab[i - 1])) / (np.log(ab[i]) - np.log(ab[i - 1]))
            Fx = float(np.exp(np.log(F[i - 1]) + w * (np.log(F[i]) - np.log(F[i - 1]))))
        thr[m] = (Fx / 1000.0, ab[np.argmin(np.abs(F - 6000))])
    gm = np.array([r["dvad"]["gamma_arcsec"]["three_sigma"] for r in f6])
    eq20 = results.get("_eq20")
    eq20_text = (f"; eq 20 reaches 0.1″ at F = {eq20['F_mm'] / 1000:.2f} m ({eq20['label']}; "
                 f"{eq20['other']['F_mm'] / 1000:.2f} m with {eq20['other']['label']})" if eq20 else "")
    out.append({"claim": "a focal length ≥ 6 m is needed for better than 0.1″ (Fig 6)",
                "measured": f"α and β 3σ at 0.1 px fall below 0.1″ at F ≈ {thr['simplified'][0]:.1f} m (simplified) / "
                            f"{thr['dvad'][0]:.1f} m (DVAD); at 6 m: {thr['simplified'][1]:.3f}″ / {thr['dvad'][1]:.3f}″; "
                            f"γ stays at {gm.mean():.2f}″ for every F" + eq20_text,
                "verdict": _verdict(False),
                "note": "for α and β 6 m is more than needed; for γ no focal length gives 0.1″ (it depends on L, not F: "
                        "3σ, σ = 0.1 px, L = 1 m)"})
    # spacing
    f7 = results["fig7"]["rows"]
    L = np.array([r["x"] for r in f7])
    a7 = np.array([r["dvad"]["alpha_arcsec"]["three_sigma"] for r in f7])
    g7 = np.array([r["dvad"]["gamma_arcsec"]["three_sigma"] for r in f7])
    out.append({"claim": "L does not affect α, β; Δf and γ errors fall with L (Fig 7)",
                "measured": f"α 3σ {a7.min():.4f}…{a7.max():.4f}″ over L = {L.min():g}…{L.max():g} mm; "
                            f"γ 3σ {g7[0]:.2f}″ → {g7[-1]:.2f}″",
                "verdict": _verdict(bool(a7.max() / a7.min() < 1.15 and g7[0] > 3 * g7[-1]))})
    # Fig 8: >0.1" at ~200 px
    f8 = [r for r in results["fig8"]["rows"] if r["tilt_deg"] == 0.0]
    rng_px = np.array([r["range_px"] for r in f8])
    da = np.array([r["diff"]["alpha_arcsec"] for r in f8])
    dpa = np.array([r["diff_as_printed"]["alpha_arcsec"] for r in f8])
    at200 = float(np.interp(200.0, rng_px, da))
    first = float(np.interp(0.1, da, rng_px)) if da.max() > 0.1 else float("nan")
    out.append({"claim": "DVAD and the simplified method differ by more than 0.1″ in α once the range reaches ~200 px, "
                         "even with zero detector tilt (Fig 8b)",
                "measured": f"|Δα| = {at200:.3f}″ at 200 px (consistent DVAD), first above 0.1″ at {first:.0f} px; "
                            f"printed DVAD vs simplified: {float(np.interp(200.0, rng_px, dpa)):.3f}″ at 200 px",
                "verdict": _verdict(True if (at200 > 0.1 and float(np.interp(200.0, rng_px, dpa)) > 0.1)
                                    else (None if at200 > 0.1 else False)),
                "note": _NOTES["fig8"][lm]})
    f8df = [r for r in results["fig8"]["rows"] if r["tilt_deg"] <= 0.1 + 1e-9]
    dfs = max(abs(r["err_simplified"]["delta_f_um"]) for r in f8df if r["range_px"] <= 200)
    dfd = max(abs(r["err_dvad"]["delta_f_um"]) for r in f8df if r["range_px"] <= 200)
    out.append({"claim": "both methods measure Δf better than 0.02 mm (Fig 8a; tilt ≤ 0.1°)",
                "measured": f"up to 200 px: DVAD {dfd:.3g} µm, simplified {dfs:.1f} µm systematic error",
                "verdict": _verdict(dfs < 20.0 and dfd < 20.0),
                "note": _NOTES["delta_f"][lm]})
    g2 = max(r["diff"]["gamma_arcsec"] for r in results["fig8"]["rows"] if r["tilt_deg"] <= 0.1 + 1e-9 and r["range_px"] <= 200)
    out.append({"claim": "the γ difference stays below 2″ at the process level (tilt ≤ 0.1°) (Fig 8d)",
                "measured": f"max |Δγ| = {g2:.3f}″ for tilt ≤ 0.1°, range ≤ 200 px",
                "verdict": _verdict(g2 < 2.0)})
    ro = results["rotation_order"]
    out.append({"claim": "2′ rotations give ~0.1″ of rotation-order error (section 2.3)",
                "measured": f"orders of α = β = γ = 2′ differ by ≤ {ro['max_per_axis_arcsec']:.3f}″ per axis "
                            f"({ro['max_between_orders_arcsec']:.3f}″ between matrices); the simplified method's actual "
                            f"error at 2′ is {results['two_arcmin_simplified_error_arcsec']:.2f}″ (worst axis)",
                "verdict": _verdict(0.05 <= ro["max_per_axis_arcsec"] <= 0.2),
                "note": _NOTES["rotation_order"][lm]})
    orb = results.get("orbit")
    if orb:
        rms = orb["estimates"]["dvad"]["relative_rms_arcsec"]
        out.append({"claim": "thermal vacuum: relative angle measured to 0.1″ over two orbits (section 4)",
                    "measured": f"rendered frames, thresholded CoM, DVAD: RMS error x {rms[0]:.4f}″, y {rms[1]:.4f}″, "
                                f"z {rms[2]:.4f}″; fitted pitch amplitude {orb['estimates']['dvad']['pitch_fit']['amplitude_arcsec']:.3f}″ "
                                f"(true {orb['estimates']['dvad']['pitch_fit']['true_amplitude_arcsec']:.3f}″)",
                    "verdict": _verdict(max(rms[:2]) < 0.1),
                    "note": ("rendered with the physical loop whatever the loop model of the analyses; " if lm != "physical" else "")
                            + f"centroid noise of these frames {np.mean(orb['reference_centroid_std_px']):.4f} px, far "
                            "below the paper's 0.1 px"
                            + (f"; with an equivalent centroid error of {orb['jitter_px']:g} px added: RMS x "
                               f"{orb['estimates_jitter']['dvad']['relative_rms_arcsec'][0]:.3f}″, y "
                               f"{orb['estimates_jitter']['dvad']['relative_rms_arcsec'][1]:.3f}″, z "
                               f"{orb['estimates_jitter']['dvad']['relative_rms_arcsec'][2]:.3f}″" if "estimates_jitter" in orb else "")})
    return out


def _analyses(g: CameraGeometry, g2: CameraGeometry, st, seed: int, runs: int, sweep_runs: int, kw: dict,
              loop_model: str, fig5_methods=("dvad", "simplified")) -> dict:
    """Figs 4–8, rotation order and the simplified method's error at 2′ under one loop model."""
    kw = {**kw, "loop_model": loop_model}
    res = {}
    sigmas = [0.02, 0.05, 0.1, 0.2, 0.3, 0.5]
    res["fig4"] = sweep([g] * len(sigmas), sigmas, sigmas, sweep_runs, seed + 4, relative_with=g2, **kw)
    e5 = mc_errors(g, st.centroid_sigma_px, runs, np.random.default_rng(seed + 5), methods=fig5_methods, **kw)
    res["fig5"] = {"runs": runs, "sigma_px": st.centroid_sigma_px,
                   "errors": {m: {p: e5[m][p].tolist() for p in PARAMS} for m in ("dvad", "simplified")},
                   "stats": {m: {p: _stats(e5[m][p]) for p in PARAMS} for m in fig5_methods},
                   "pred3": predicted_3sigma(g, st.centroid_sigma_px)}
    focals = [1000, 2000, 3000, 4000, 6000, 8000, 10000, 12000]
    res["fig6"] = sweep([g.with_(focal_length_mm=float(f)) for f in focals], focals, st.centroid_sigma_px,
                        sweep_runs, seed + 6, **kw)
    Ls = [200, 400, 600, 800, 1000, 1400, 2000]
    res["fig7"] = sweep([g.with_(center_y_mm=(L / 2.0, -L / 2.0)) for L in Ls], Ls, st.centroid_sigma_px,
                        sweep_runs, seed + 7, **kw)
    res["fig8"] = fig8_residual(g, [0, 25, 50, 100, 150, 200, 300, 400, 600, 800, 1000], [0.0, 0.05, 0.1, 0.5, 1.0],
                                reading=kw["reading"], loop_model=loop_model)
    res["rotation_order"] = rotation_order(120.0)
    a = 120.0 / AS
    est = estimate(g, loop_spots_uv(g, loop_model=loop_model),
                   loop_spots_uv(g, rotation_xyz(a, a, a), loop_model=loop_model), "simplified", kw["reading"])
    res["two_arcmin_simplified_error_arcsec"] = float(np.abs(est.angles_arcsec - 120.0).max())
    return res


def loop_model_comparison(per_model: dict, primary: str, eq20: dict, beta_excess: float) -> dict:
    """The ``loop_models`` block: Fig 5 (1σ, mean, ratio to eqs 19–22 ÷ 3) and the claim verdicts under each
    loop model, eqs 19–22 ÷ 3, the first-order β excess of the physical loop's DVAD (``beta_excess``,
    :func:`beta_noise_excess`) and eq 20's thresholds (``eq20``).
    ``per_model``: {loop model: {"fig5": …, "claims": […]}}."""
    any_f5 = next(iter(per_model.values()))["fig5"]
    pred1 = {p: v / 3.0 for p, v in any_f5["pred3"].items()}
    out = {"primary": primary, "rendered_orbit": "physical", "sigma_px": any_f5["sigma_px"], "runs": any_f5["runs"],
           "eq19_22_1sigma": pred1, "eq20_threshold": eq20, "beta_excess_first_order": beta_excess}
    for lm, r in per_model.items():
        st = r["fig5"]["stats"]
        out[lm] = {
            "fig5_1sigma": {m: {p: st[m][p]["std"] for p in PARAMS} for m in st},
            "fig5_mean": {m: {p: st[m][p]["mean"] for p in PARAMS} for m in st},
            "fig5_ratio_to_eq19_22": {m: {p: st[m][p]["std"] / pred1[p] for p in PARAMS} for m in st},
            "claims": [{"claim": c["claim"], "measured": c["measured"], "verdict": c["verdict"]} for c in r["claims"]],
        }
    return out


def run_study(rig: BoresightRig, *, seed: int | None = None, runs: int | None = None, reading: str = "consistent",
              orbit: bool = True, progress=None, orbit_kw: dict | None = None, sweep_runs: int | None = None,
              loop_model: str = "physical", eq20_cos2beta: str = "reevaluated") -> dict:
    """The default study: Figs 4–8, rotation order, orbit scenario, claims. ``progress(n, stage)``.

    ``loop_model`` (:data:`~rigsim.optics.loop_models.LOOP_MODELS`): the loop of the Monte-Carlo and
    noise-free analyses (the rendered orbit scenario is always physical); the other loop model's analyses
    are run too, for the ``loop_models`` comparison (Fig 5 and the claims under each). ``eq20_cos2beta``:
    which eq-20 focal-length threshold the Fig 6 claim quotes first (both are computed)."""
    check_loop_model(loop_model)
    if eq20_cos2beta not in EQ20_COS2BETA:
        raise ValueError(f"eq20_cos2beta = {eq20_cos2beta!r}: allowed {EQ20_COS2BETA}")
    st = rig.study
    seed = st.seed if seed is None else seed
    runs = st.monte_carlo_runs if runs is None else runs
    sweep_runs = sweep_runs or runs
    g = CameraGeometry.from_rig(rig.cameras[0])
    g2 = CameraGeometry.from_rig(rig.cameras[1]) if len(rig.cameras) > 1 else g
    kw = dict(arcsec=st.perturbation_arcsec, df_um=st.perturbation_delta_f_um, n_ref=st.reference_measurements,
              reading=reading)
    t0 = time.perf_counter()
    res = {"rig": rig.name, "seed": seed, "runs": runs, "reading": reading, "sigma_px": st.centroid_sigma_px,
           "camera": {"F_mm": g.F, "omega_deg": math.degrees(g.off_axis_rad), "Kf": g.telecentric_factor,
                      "pitch_um": g.pitch_mm * 1e3, "L_mm": g.L_mm,
                      "beta_half_angle_deg": math.degrees(g.beta_half_angle_rad)},
           "state": {"arcsec": st.perturbation_arcsec, "df_um": st.perturbation_delta_f_um,
                     "n_ref": st.reference_measurements}}
    eq20 = {c: eq20_focal_threshold(g, st.centroid_sigma_px, 0.1, cos2beta=c) for c in EQ20_COS2BETA}
    eq20["reevaluated"]["label"] = "cos²β re-evaluated with F"
    eq20["fixed"]["label"] = f"cos²β fixed at F = {g.F / 1000:g} m"
    other = next(c for c in EQ20_COS2BETA if c != eq20_cos2beta)
    eq20_claim = {**eq20[eq20_cos2beta], "other": eq20[other]}
    eq20_block = {"reading": eq20_cos2beta, "target_arcsec": 0.1, "sigma_px": st.centroid_sigma_px,
                  **{c: {"F_m": v["F_mm"] / 1000.0, "beta_half_angle_deg": v["beta_half_angle_deg"]}
                     for c, v in eq20.items()}}
    orbit_kw = dict(orbit_kw or {})
    # the orbit's render worker starts now: it compiles its kernels during the analyses
    pool = orbit_frame_pool(rig, orbit_kw.pop("workers", None), orbit_kw.get("spp")) if orbit else None
    try:
        per_model = {}
        for lm in [loop_model] + [m for m in LOOP_MODELS if m != loop_model]:
            methods = ("dvad", "simplified") + (("dvad_physical_loop",) if lm != "physical" else ())
            per_model[lm] = _analyses(g, g2, st, seed, runs, sweep_runs, kw, lm, methods)
            per_model[lm]["_loop_model"] = lm
            per_model[lm]["_eq20"] = eq20_claim
            if progress:
                progress(4 if lm == loop_model else 1, "analyses" if lm == loop_model else f"analyses ({lm} loop)")
        res.update({k: v for k, v in per_model[loop_model].items() if not k.startswith("_")})
        res["_loop_model"] = loop_model
        res["_eq20"] = eq20_claim
        res["analysis_seconds"] = time.perf_counter() - t0
        if orbit:
            res["orbit"] = run_orbit(rig, seed=seed, progress=(lambda n: progress(n, "orbit")) if progress else None,
                                     reading=reading, frame_pool=pool, **orbit_kw)
        res["claims"] = claims(res)
        per_model[loop_model]["claims"] = res["claims"]
        for lm in LOOP_MODELS:
            if lm != loop_model:
                per_model[lm]["claims"] = claims(per_model[lm])
        res["loop_models"] = loop_model_comparison(per_model, loop_model, eq20_block, beta_noise_excess(g))
        from rigsim.procedures.boresight.result_json import boresight_result_json, orbit_result_json

        if orbit:
            res["_result"] = orbit_result_json(rig, res["orbit"]["_spots"], seed=seed, reading=reading)
        else:  # the analyses only: the result's header, no sample measured
            res["_result"] = boresight_result_json(rig, {}, {}, [], [], np.zeros((0, 2, 2)), np.zeros((0, 4)), {},
                                                   reading=reading, mode="analytic", seed=seed)
        res["seconds"] = time.perf_counter() - t0
        return res
    finally:
        if pool is not None:
            pool.close()
