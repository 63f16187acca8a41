"""Seed 004 on a user's files: star frames (PNG, TIFF or FITS) and an attitude log go through the
same :class:`~rigsim.procedures.star.pipeline.StarPipeline` as the in-process campaign (extraction,
identification from the commanded attitude, AD/ADS EKFs, batch least squares of f, u0, v0, k1,
k2), with the nominal rig only.

The attitude log has one row per frame: ``frame`` (file name), ``time_s`` and the commanded
attitude R(cam←ICRS) as a unit quaternion ``qw, qx, qy, qz`` (scalar first; the rotation that
takes ICRS vectors into the camera frame, x right, y down, z along the boresight)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.errors import InputError
from rigsim.estimation.star_calibration import THETA_NAMES
from rigsim.files import Column, covariance_block, read_image, read_table
from rigsim.optics.sky import SkyCatalogue
from rigsim.procedures.star.pipeline import PipelineOutput, StarObservation, StarPipeline
from rigsim.rig.star import NominalStarRig

__all__ = [
    "LOG_COLUMNS",
    "STAR_FORMAT",
    "attitude_covariance_rad2",
    "attitude_log_columns",
    "calibrate_star_files",
    "read_attitude_log",
    "star_observations",
    "star_result_json",
    "stars_table",
]

LOG_COLUMNS = [Column("frame", kind="str"), Column("time", "s"), Column("qw"), Column("qx"), Column("qy"), Column("qz")]
LIS_LOG_COLUMNS = [Column("frame", kind="str"), Column("time", "s")]  # lost in space: no attitude needed
THETA_UNITS = ("px", "px", "px", "1", "1")


def attitude_log_columns(frames: Sequence[str], times_s, R_cam_from_icrs) -> dict:
    """The attitude log's columns for frames, their times and commanded attitudes."""
    q = Rotation.from_matrix(np.asarray(R_cam_from_icrs)).as_quat(scalar_first=True)
    q = q * np.sign(q[:, :1] + (q[:, :1] == 0))  # qw ≥ 0: one of the two equal quaternions
    return {"frame": list(frames), "time_s": np.asarray(times_s, float), "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2],
            "qz": q[:, 3]}


def read_attitude_log(path, *, attitude: bool = True) -> dict[str, tuple[float, np.ndarray | None]]:
    """frame name → (time in s, commanded R(cam←ICRS)); every quaternion must be of unit norm
    (within 1e-6) and every frame named once. ``attitude=False``: only frame and time_s are needed
    (lost-in-space identification); the attitude is None."""
    t = read_table(path, LOG_COLUMNS if attitude else LIS_LOG_COLUMNS, what="attitude log")
    out: dict[str, tuple[float, np.ndarray]] = {}
    lines: dict[str, int] = {}
    for i, line in enumerate(t["__line__"]):
        f = Path(str(t["frame"][i])).name
        if f in out:
            raise InputError(f"{path}: line {line}, column frame: {f!r} already on line {lines[f]}; one row per frame")
        lines[f] = int(line)
        if not attitude:
            out[f] = (float(t["time_s"][i]), None)
            continue
        q = np.array([t["qw"][i], t["qx"][i], t["qy"][i], t["qz"][i]])
        n = float(np.linalg.norm(q))
        if abs(n - 1.0) > 1e-6:
            raise InputError(f"{path}: line {line}, columns qw..qz: |q| = {n:.9g}; expected a unit quaternion (R(cam←ICRS), "
                             "scalar first)")
        out[f] = (float(t["time_s"][i]), Rotation.from_quat(q / n, scalar_first=True).as_matrix())
    return out


def star_observations(paths: Sequence, log_path, nominal: NominalStarRig, *, attitude: bool = True
                      ) -> tuple[list[StarObservation], list[str]]:
    """The frames as the pipeline takes them, in the order of their times, and their names; each
    frame's size is checked against the rig's detector and each must have a row in the log. With no
    log (``log_path`` None) the frames keep the order given, one second apart, with no attitude. Each
    frame once (by file and by name), and all of them must fit in memory together: checked first."""
    from rigsim.files.inputs import check_distinct
    from rigsim.files.memory import check_frames_kept

    if not paths:
        raise InputError(f"{log_path or 'star calibrate'}: no frames given")
    check_distinct(paths, "FRAME", what="star frame")
    W, H = nominal.sensor.resolution_px
    check_frames_kept(len(paths), W, H, 8, what="star calibrate")
    if log_path is None:
        return ([StarObservation(k, float(k), read_image(p, shape=(H, W), what="star frame"), None)
                 for k, p in enumerate(paths)], [Path(p).name for p in paths])
    log = read_attitude_log(log_path, attitude=attitude)
    rows = []
    for p in paths:
        name = Path(p).name
        if name not in log:
            raise InputError(f"{p}: frame {name!r} has no row in the attitude log {log_path}")
        dn = read_image(p, shape=(H, W), what="star frame")
        rows.append((log[name][0], name, dn, log[name][1]))
    rows.sort(key=lambda r: r[0])
    return [StarObservation(k, t, dn, R) for k, (t, _, dn, R) in enumerate(rows)], [r[1] for r in rows]


def calibrate_star_files(paths: Sequence, log_path, nominal: NominalStarRig, *, identification: str = "commanded",
                         site=None, utc=None) -> tuple[PipelineOutput, list[str]]:
    """The whole pipeline on files: (its output, the frame names in time order). ``identification``:
    ``"commanded"`` (the log's attitude is the prior) or ``"lost-in-space"`` (no prior; the log
    needs only frame and time_s, and may be None: the frames alone). ``site``
    (:class:`rigsim.optics.refraction.Site`) and ``utc`` (the first frame's time; the others follow by
    their time_s): the stars are refracted by the air before the joint fit. Raises InputError when no
    frame can be identified (each frame's reason in the message)."""
    obs, names = star_observations(paths, log_path, nominal, attitude=identification == "commanded")
    sky = SkyCatalogue.load(nominal.sky.magnitude_limit, nominal.sky.epoch_year)
    refraction = None
    if site is not None:
        import astropy.units as u
        from astropy.time import Time

        t0 = Time(utc, scale="utc")
        times = [t0 + (o.time_s - obs[0].time_s) * u.s for o in obs]
        refraction = (site, lambda k: times[k])
    pipe = StarPipeline(nominal, sky, identification=identification, refraction=refraction)
    if nominal.calibration.fixed_pattern == "sequence" and identification == "commanded":
        pipe.set_sequence_pattern(obs)
    elif nominal.calibration.fixed_pattern == "sequence":
        pipe.fixed_pattern_note = "none: no commanded attitudes to check that the stars move"
    check = identification == "commanded" and log_path is not None
    for k, o in enumerate(obs):
        pipe.add(o)
        if check and k + 1 == CONVENTION_SAMPLE < len(obs) and not any(i.ok for i in pipe.ident):
            # none of the first frames identifies from the log: a log in another convention is named now, not after
            # every frame's stars are extracted
            check_attitude_convention(obs[:k + 1], names[:k + 1], log_path, nominal, sky, [False] * (k + 1),
                                      first=True)
    ok = [i.ok for i in pipe.ident]
    if check and sum(ok) < 0.5 * len(ok):
        check_attitude_convention(obs, names, log_path, nominal, sky, ok)  # a log in another convention is named
    if not any(ok):
        why = "; ".join(f"{n}: {i.reason}" for n, i in zip(names, pipe.ident))
        raise InputError(f"none of the {len(names)} frames could be identified{_likely_cause(pipe)} ({why})")
    return pipe.calibrate(), names


CONVENTIONS = {
    "scalar last": "the columns qw, qx, qy, qz hold (x, y, z, w): the scalar is written last",
    "conjugated": "the quaternions are R(ICRS←cam), the inverse of R(cam←ICRS): conjugate them (negate qx, qy, qz)",
    "scalar last and conjugated": "the scalar is written last and the quaternions are R(ICRS←cam): reorder the "
                                  "columns to w, x, y, z and negate x, y, z",
}
CONVENTION_SAMPLE = 3  # frames tried (first, middle, last) without a prior


def _convention_attitudes(R_log: np.ndarray) -> dict[str, np.ndarray]:
    """The attitude the log's quaternion gives under each convention it might have been written in."""
    q = Rotation.from_matrix(R_log).as_quat(scalar_first=True)  # the four columns as written (w, x, y, z); ± alike
    last = Rotation.from_quat(q, scalar_first=False).as_matrix()
    return {"as written": R_log, "scalar last": last, "conjugated": R_log.T, "scalar last and conjugated": last.T}


def check_attitude_convention(obs, names, log_path, nominal: NominalStarRig, sky: SkyCatalogue,
                              identified: Sequence[bool], *, first: bool = False) -> None:
    """When most frames do not identify from the log (``identified``: each frame's identification with the log's
    attitude as the prior): up to :data:`CONVENTION_SAMPLE` of the frames that did not (first, middle, last) are
    identified lost in space (no prior), and their attitudes from the stars are compared with the log's quaternion
    read under each convention it might have been written in (scalar first or last, R(cam←ICRS) or its inverse). A
    log that matches under another convention is refused with one line naming it; a log that matches under none is
    refused as not describing these frames. When the stars agree with the log as written, or no frame identifies
    lost in space either, nothing can be said here. ``first``: ``obs`` are the first frames of a longer sequence (the
    check runs before the other frames are read; the message says so)."""
    from rigsim.frames import rotation_angle

    failing = [i for i, ok in enumerate(identified) if not ok]
    if not failing:
        return
    pick = sorted({failing[0], failing[len(failing) // 2], failing[-1]})[:CONVENTION_SAMPLE]
    lis = StarPipeline(nominal, sky, identification="lost-in-space")
    tol = max(5.0 * nominal.identification.attitude_error_deg, 1.0)
    seen = []
    for i in pick:
        ident = lis.add(obs[i])
        if not ident.ok:
            continue
        err = {c: float(np.degrees(rotation_angle(R, ident.R_cam_from_icrs)))
               for c, R in _convention_attitudes(obs[i].R_commanded).items()}
        seen.append((names[i], err))
    if not seen:
        return
    name, err = seen[0]
    best = min(err, key=err.get)
    if best == "as written" and err[best] <= tol:
        return  # the log is right; the frames fail to identify for another reason
    if best != "as written" and err[best] <= tol and all(min(e, key=e.get) == best for _, e in seen):
        counted = f"the first {len(identified)}" if first else f"{len(identified)}"
        raise InputError(f"{log_path}: {sum(identified)} of {counted} frames identify with its attitudes as "
                         "written (R(cam←ICRS), scalar first); "
                         f"read {best}, they agree with the stars of {len(seen)} frame(s) identified without a prior "
                         f"({name}: {err[best]:.3g}° instead of {err['as written']:.3g}°): {CONVENTIONS[best]}")
    raise InputError(f"{log_path}: its attitudes are {err['as written']:.3g}° from the attitude the stars of {name} give "
                     f"(identified without a prior), and {min(err[c] for c in CONVENTIONS):.3g}° at best read scalar "
                     "last or conjugated: is the log for these frames (rows, times, frame names)?")


def _likely_cause(pipe) -> str:
    """When no frame identifies: whether the frames identify once mirrored (left to right or top to
    bottom), the commonest way a frame reaches a pipeline flipped; '' when that does not help either."""
    from rigsim.estimation.star_lis import identify_lost_in_space

    W, H = pipe.nominal.sensor.resolution_px
    kw = pipe.nominal.identification.lost_in_space_settings()
    for usable in pipe.usable[:3]:
        order = np.argsort(-usable.flux, kind="stable")
        uv = usable.uv[order]
        for flip, what in (((W - 1, None), "left to right (u → W − 1 − u)"), ((None, H - 1), "top to bottom (v → H − 1 − v)")):
            m = uv.copy()
            if flip[0] is not None:
                m[:, 0] = flip[0] - m[:, 0]
            else:
                m[:, 1] = flip[1] - m[:, 1]
            if identify_lost_in_space(m, pipe.sky, pipe.camera, **kw).ok:
                return f": mirrored {what} they identify: are the frames flipped?"
    return ""


def stars_table(out: PipelineOutput, names: Sequence[str]) -> dict[str, list]:
    """Every usable star of every frame: position, σ, flux, flags and its catalogue identity."""
    cols: dict[str, list] = {k: [] for k in ("frame", "u_px", "v_px", "sigma_u_px", "sigma_v_px", "flux_dn", "flags",
                                             "identified", "hip")}
    for name, usable, ident in zip(names, out.usable, out.ident):
        hip = dict(zip(ident.obs_index.tolist(), ident.hip.tolist())) if ident.ok else {}
        for j in range(len(usable)):
            cols["frame"].append(name)
            cols["u_px"].append(usable.uv[j, 0])
            cols["v_px"].append(usable.uv[j, 1])
            cols["sigma_u_px"].append(usable.sigma_uv[j, 0])
            cols["sigma_v_px"].append(usable.sigma_uv[j, 1])
            cols["flux_dn"].append(usable.flux[j])
            cols["flags"].append(int(usable.flags[j]))
            cols["identified"].append(int(j in hip))
            cols["hip"].append(int(hip.get(j, -1)))
    return cols


STAR_FORMAT = "rigsim.star-calibration/1"
POOR_FIT_CHI2 = 25.0
"""A fit whose χ²/dof under the centroider's own σ exceeds this is not explained by the noise model
(the σ floor the joint fit needed is then many times the centroid σ)."""


def batch_fit_quality(b):
    """The batch fit's χ² against the centroid σ it was given (with the joint fit's floor)."""
    from rigsim.estimation.fit_quality import judge_chi2

    return judge_chi2(b.chi2, b.n_eq - len(b.names), "the centroid σ propagated to the angular distances")


def ekf_fit(e):
    """An EKF's innovations against their predicted covariance: Σ NIS over Σ its dimensions."""
    from rigsim.estimation.fit_quality import judge_chi2

    ok = np.isfinite(e.nis)
    dof = int(np.sum(np.asarray(e.dof if e.dof is not None else e.n_eq)[ok]))
    return judge_chi2(float(np.sum(e.nis[ok])), dof, "the innovations' predicted covariance (NIS)")


def joint_fit_quality(b):
    """The joint fit judged against the centroider's own σ (before the floor widens them)."""
    from rigsim.estimation.fit_quality import judge_chi2, not_judged

    if not b.success or b.dof <= 0:
        return not_judged("the joint fit did not converge", problems=(f"not converged: {b.message}",))
    return judge_chi2(b.chi2_reduced_model * b.dof, b.dof, "the centroider's σ (its inverse Fisher matrix)", unit="px")


def _finite(x):
    return float(x) if x is not None and np.isfinite(x) else None


def joint_verdict(b) -> str:
    """One sentence on how well the noise model explains the joint fit."""
    dof = max(b.dof, 1)
    if not b.success:
        return f"not converged: {b.message}"
    if b.chi2_reduced_model <= 1.0 + 3.0 * np.sqrt(2.0 / dof):
        return "the centroid σ explain the residuals (χ²/dof within 3σ of 1); covariances as fitted"
    if b.chi2_reduced_model > POOR_FIT_CHI2:
        return (f"poor: χ²/dof {b.chi2_reduced_model:.1f} under the centroid σ; a floor of {b.sigma_floor_px:.3f} px "
                "was needed: wrong stars, a wrong camera model or mis-set detector settings; check before use")
    return (f"the residuals exceed the centroid σ (χ²/dof {b.chi2_reduced_model:.2f}): every centroid σ was widened "
            f"by a floor of {b.sigma_floor_px:.3f} px in quadrature, estimated from the residuals, and the covariances "
            "are those of the widened fit")


def joint_block(out: PipelineOutput, names: Sequence[str], true_theta=None) -> dict:
    """The joint fit of the intrinsics and every attitude as JSON: θ, its covariance, the noise floor,
    χ²/dof under the centroider's σ and with the floor, the verdict, the field of view and the
    held-out check."""
    from rigsim.estimation.star_bundle import field_of_view_deg

    j = out.joint
    b = j.bundle
    cam = b.camera(out.nominal.sensor.camera())
    fov = field_of_view_deg(cam)
    ho = j.held_out
    r2 = sum(h.rms_px**2 * h.n_stars for h in ho)
    z2 = sum(h.z_rms**2 * h.n_stars for h in ho)
    n = sum(h.n_stars for h in ho)
    units = [THETA_UNITS[THETA_NAMES.index(k)] for k in b.names]
    return {
        "method": "intrinsics and every frame's attitude fitted together to the identified stars (weighted least "
                  "squares, nominal values as priors with their σ); centroid σ widened in quadrature by a floor "
                  "estimated from the residuals when the centroider's σ do not explain them",
        "estimated": list(b.names), "theta": np.asarray(b.theta, float).tolist(),
        "covariance": covariance_block(list(b.names), b.cov, units),
        "error": None if true_theta is None else (np.asarray(b.theta) - true_theta).tolist(),
        "fit": {**joint_fit_quality(b).as_dict(), "covariance_scale": 1.0, "covariance_scaled": False,
                "sigma_floor_px": b.sigma_floor_px,
                "covariance_note": "the covariance is that of the fit with every centroid σ widened by sigma_floor_px in "
                                   "quadrature (χ²/dof 1 with it), not the noise model's scaled"},
        "chi2_reduced_noise_model": b.chi2_reduced_model, "chi2_reduced": b.chi2_reduced,
        "sigma_floor_px": b.sigma_floor_px, "dof": b.dof, "n_stars": b.n_stars, "n_rejected": b.n_rejected,
        "residual_rms_px": b.residual_rms_px, "verdict": joint_verdict(b), "converged": bool(b.success),
        "k2_delta_chi2": j.k2_delta_chi2,
        "field_of_view_deg": {"horizontal": fov[0], "vertical": fov[1],
                              "definition": "angle between the rays through the middles of the detector's outer "
                                            "edges, on the principal point's row (horizontal) and column (vertical)"},
        "held_out": None if not ho else {
            "rms_px": float(np.sqrt(r2 / n)), "z_rms": float(np.sqrt(z2 / n)), "n_stars": int(n),
            "note": "each frame (or group of frames) left out of the joint fit in turn; its stars predicted with the "
                    "calibration (its attitude refitted to them); z = error / σ with σ from the centroid σ, the floor "
                    "and the calibration's covariance",
            "frames": [{"frame": names[h.frame], "n_stars": h.n_stars, "rms_px": h.rms_px, "z_rms": h.z_rms}
                       for h in ho]},
    }


def attitude_covariance_rad2(dirs_cam: np.ndarray, sigma_rad: np.ndarray) -> np.ndarray:
    """Covariance (rad², about the camera axes) of an attitude fitted to unit vectors ``dirs_cam``
    measured with isotropic angular noise ``sigma_rad`` each: [Σ (I − b bᵀ)/σ²]⁻¹ (Shuster's QUEST
    covariance). Measurement noise only: the nominal intrinsics' error is not in it."""
    b = np.asarray(dirs_cam, float)
    w = 1.0 / np.asarray(sigma_rad, float) ** 2
    F = np.einsum("n,nij->ij", w, np.eye(3)[None] - b[:, :, None] * b[:, None, :])
    return np.linalg.inv(F) if len(b) >= 2 else np.full((3, 3), np.nan)


def star_result_json(out: PipelineOutput, names: Sequence[str], ekf_models: Sequence[str] = ("ad", "ads"), *,
                     mode: str = "files", seed=None, rig_file=None, true_theta=None, true_R=None) -> dict:
    """The calibration as one JSON object (schema ``star-calibration.schema.json``): the batch (f, u0, v0,
    k1, k2) with its covariance and χ², each EKF's final state with its covariance, each frame's attitude
    R(cam←ICRS) with its covariance, the identification statistics. With ``true_theta`` (and ``true_R``,
    one matrix per frame), rigsim's own campaigns put the truth and the error beside each estimate; the
    estimators never saw them."""
    from rigsim.frames import ARCSEC_PER_RAD
    from rigsim.procedures.results import result_header, rotation_block

    b = out.batch
    t = None if true_theta is None else np.asarray(true_theta, float)
    batch_fit = batch_fit_quality(b)

    def err(theta):
        return None if t is None else (np.asarray(theta) - t).tolist()

    res = {**result_header(STAR_FORMAT, "star-calibration", mode, out.nominal, seed=seed, rig_file=rig_file),
           "seed_document": "004", "frames": list(names),
           "theta_names": list(THETA_NAMES), "theta_units": list(THETA_UNITS),
           "nominal_theta": list(out.nominal.sensor.theta), "true_theta": None if t is None else t.tolist(),
           "batch": {"theta": b.theta.tolist(), "estimated": list(b.names),
                     "covariance": covariance_block(list(b.names), np.asarray(b.cov) * batch_fit.covariance_scale,
                                                    [THETA_UNITS[THETA_NAMES.index(n)] for n in b.names]),
                     "chi2_reduced": b.chi2_reduced, "n_equations": b.n_eq, "converged": bool(b.success),
                     "fit": batch_fit.as_dict(), "error": err(b.theta)},
           "ekf": {}, "identification": out.ident_stats}
    for (case, model), e in out.ekf.items():
        if model not in ekf_models:
            continue
        q = ekf_fit(e)
        res["ekf"][f"{case}/{model}"] = {
            "case": case, "model": model, "estimated": list(e.names), "state": e.x.tolist(), "theta": e.theta.tolist(),
            "covariance": covariance_block(list(e.names), np.asarray(e.P) * q.covariance_scale,
                                           [THETA_UNITS[THETA_NAMES.index(n)] for n in e.names]),
            "mean_nis": float(np.nanmean(e.nis)) if np.isfinite(e.nis).any() else None,
            "fit": q.as_dict(), "error": err(e.theta)}
    if out.joint is not None:
        res["joint"] = joint_block(out, names, t)
    res["ekf_cases"] = {"f_nominal": "state (u0, v0), f fixed at the nominal value",
                        "f_joint": "state (f, u0, v0)"}
    # each frame's attitude refitted with the batch-calibrated camera (weighted Wahba, scipy's SVD), beside the
    # identification's (the nominal camera); its covariance = centroid noise + the batch θ's covariance (J Σθ Jᵀ,
    # J by central differences of the refit)
    th = np.asarray(b.theta, float)
    idx = [THETA_NAMES.index(n) for n in b.names]
    steps = np.array([1e-3, 1e-3, 1e-3, 1e-6, 1e-6])

    def fit(fo, theta, sig):
        cam = out.nominal.sensor.camera(f_px=theta[0], principal_point_px=theta[1:3], k1=theta[3], k2=theta[4])
        bc = cam.unproject(fo.uv)
        return Rotation.align_vectors(bc, fo.dirs_icrs, weights=1.0 / sig**2)[0].as_matrix(), bc

    att = []
    for k, (name, ident, fo) in enumerate(zip(names, out.ident, out.frames_obs)):
        rec = {"frame": name, "identified": bool(ident.ok), "n_stars": len(fo),
               "residual_rms_px": float(ident.residual_rms_px) if ident.ok else None,
               "reason": None if ident.ok else ident.reason}
        lis = out.lis[k] if k < len(out.lis) else None
        if lis is not None:  # what the frame's lost-in-space solution said before the joint fit
            rec["lost_in_space"] = {"identified": bool(lis.ok), "f_px": _finite(getattr(lis, "f_px", None)),
                                    "false_match_probability": _finite(getattr(lis, "false_match_probability", None)),
                                    "stars": len(lis) if lis.ok else 0, "reason": None if lis.ok else lis.reason}
        true_k = None if true_R is None else true_R[k]
        if ident.ok and len(fo) >= 3:
            sig = fo.sigma_uv.mean(axis=1) / th[0]
            R, bc = fit(fo, th, sig)
            J = np.zeros((3, len(idx)))
            for j, i in enumerate(idx):
                d = np.zeros(5)
                d[i] = steps[i]
                Rp, Rm = fit(fo, th + d, sig)[0], fit(fo, th - d, sig)[0]
                J[:, j] = Rotation.from_matrix(Rp @ Rm.T).as_rotvec() / (2 * steps[i])
            cov = attitude_covariance_rad2(bc, sig) + J @ np.asarray(b.cov) @ J.T
            rec["R_cam_from_icrs"] = rotation_block(R, cov, true_k)
            rec["R_cam_from_icrs_nominal"] = rotation_block(ident.R_cam_from_icrs, attitude_covariance_rad2(
                fo.dirs_icrs @ ident.R_cam_from_icrs.T, fo.sigma_uv.mean(axis=1) / out.nominal.sensor.theta[0]), true_k)
            if out.joint is not None and np.all(np.isfinite(out.joint.bundle.R[k])):
                jb = out.joint.bundle
                rec["R_cam_from_icrs_joint"] = rotation_block(jb.R[k], jb.R_cov[k], true_k)
        else:
            rec["identified"] = False
        att.append(rec)
    res["attitudes"] = att
    res["attitude_note"] = ("R_cam_from_icrs_joint: each frame's R(cam←ICRS) from the joint fit (intrinsics and attitudes "
                            "together), its covariance the joint fit's marginal; "
                            "R_cam_from_icrs: each frame's R(cam←ICRS) refitted with the batch-calibrated camera "
                            "(weighted Wahba), covariance = centroid noise + the batch θ covariance propagated; "
                            "R_cam_from_icrs_nominal: the identification's with the nominal camera, covariance from the "
                            "centroid noise only (it is biased by the nominal intrinsics' error). Covariances in arcsec² "
                            f"about the camera axes (1 px ≈ {ARCSEC_PER_RAD / th[0]:.1f}″).")
    return res
