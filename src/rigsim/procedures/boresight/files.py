"""Seed 003 on a user's files: ROI frames of the two CMOS detectors (M1, M2) of a camera →
centroid table → (Δf, α, β, γ) per sample against a reference, with the same centroider and DVAD
solver as the in-process orbit scenario.

A ROI file carries no origin: its place on the detector is the rig's nominal ROI, a window of
``orbit.window_px`` centred on the design reference spot (``CameraGeometry.roi_origin``). Spot tables hold one
sample per row: ``camera, u_m1_px, v_m1_px, u_m2_px, v_m2_px`` (optional ``sample``)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from rigsim.errors import InputError
from rigsim.estimation.dvad import BoresightEstimate, DVADSolver, estimate
from rigsim.estimation.fit_quality import FitQuality, judge_residuals, not_judged
from rigsim.files import Column, read_image, read_table
from rigsim.imaging import NoiseModel
from rigsim.optics.line_camera import CameraGeometry
from rigsim.procedures.boresight.model_spot import roi_centroids
from rigsim.rig.boresight import BoresightRig

__all__ = ["SIGMA_COLUMNS", "SPOT_COLUMNS", "camera_geometry", "spot_sigmas", "centroid_roi_files", "read_spot_rows", "reference_spots",
           "solve_rows", "estimate_columns", "streaming_solver", "solve_fit_quality", "solve_alternatives", "window_problems"]

SPOT_COLUMNS = [Column("camera", kind="str"), Column("u_m1", "px"), Column("v_m1", "px"), Column("u_m2", "px"),
                Column("v_m2", "px"), Column("sample", kind="str", required=False)]


def camera_geometry(rig: BoresightRig, camera: str) -> CameraGeometry:
    """The nominal geometry of the rig's camera named ``camera``."""
    names = [c.name for c in rig.cameras]
    if camera not in names:
        raise InputError(f"camera {camera!r}: this rig ({rig.name}) has cameras {', '.join(names)}")
    return CameraGeometry.from_rig(rig.cameras[names.index(camera)])


def centroid_roi_files(rig: BoresightRig, camera: str, m1: Sequence, m2: Sequence, *, method: str = "tcom") -> dict:
    """The spot table of pairs of ROI files (i-th M1 with i-th M2) of one camera. ``method``: a
    centroider of :func:`rigsim.imaging.centroid`, or ``"model"`` (the core's image fitted:
    :mod:`rigsim.procedures.boresight.model_spot`)."""
    if len(m1) != len(m2):
        raise InputError(f"--m1 has {len(m1)} frames and --m2 {len(m2)}; expected one M2 frame per M1 frame")
    from rigsim.files.inputs import check_distinct

    check_distinct([*m1, *m2], "--m1/--m2", by_name=False, what="ROI frame")
    geom = camera_geometry(rig, camera)
    cam_index = [c.name for c in rig.cameras].index(camera)
    w = rig.orbit.window_px
    noise = NoiseModel.from_detector(rig.detector)
    cols: dict[str, list] = {k: [] for k in ("sample", "camera", "m1_frame", "m2_frame", "u_m1_px", "v_m1_px",
                                             "u_m2_px", "v_m2_px", "sigma_u_m1_px", "sigma_v_m1_px", "sigma_u_m2_px",
                                             "sigma_v_m2_px")}
    for i, pair in enumerate(zip(m1, m2)):
        uv, sig = [], []
        for j, p in enumerate(pair):
            dn = read_image(p, shape=(w, w), what=f"M{j + 1} ROI")
            m = roi_centroids(rig, dn, [geom.roi_origin(j, w)], method=method, noise=noise, camera=cam_index)
            if not m.valid.all():
                from rigsim.imaging import Flag

                raise InputError(f"{p}: no usable laser spot ({Flag(int(m.flags[0])).name})")
            uv.append(m.uv[0])
            sig.append(m.sigma_uv[0])
        cols["sample"].append(str(i))
        cols["camera"].append(camera)
        cols["m1_frame"].append(Path(pair[0]).name)
        cols["m2_frame"].append(Path(pair[1]).name)
        for j in range(2):
            cols[f"u_m{j + 1}_px"].append(uv[j][0])
            cols[f"v_m{j + 1}_px"].append(uv[j][1])
            cols[f"sigma_u_m{j + 1}_px"].append(sig[j][0])
            cols[f"sigma_v_m{j + 1}_px"].append(sig[j][1])
    return cols


def read_spot_rows(path, rig: BoresightRig, *, what: str = "spot table") -> tuple[list[str], list[str], np.ndarray]:
    """(samples, cameras, spots (n, 2, 2): [M1, M2] × (u, v)) of a spot table."""
    t = read_table(path, SPOT_COLUMNS, what=what)
    names = {c.name for c in rig.cameras}
    for cam, line in zip(t["camera"], t["__line__"]):
        if cam not in names:
            raise InputError(f"{path}: line {line}, column camera: {cam!r}; this rig's cameras are {', '.join(sorted(names))}")
    uv = np.stack([np.column_stack([t["u_m1_px"], t["v_m1_px"]]), np.column_stack([t["u_m2_px"], t["v_m2_px"]])], axis=1)
    for k, (cam, line) in enumerate(zip(t["camera"], t["__line__"])):
        why = spot_problem(rig, str(cam), uv[k])
        if why:
            raise InputError(f"{path}: line {line}: {why}")
    samples = list(t["sample"]) if "sample" in t else [str(i) for i in range(len(uv))]
    return samples, [str(c) for c in t["camera"]], uv


def spot_problem(rig: BoresightRig, camera: str, uv: np.ndarray) -> str | None:
    """Why the spots ``uv`` ([M1, M2] × (u, v), detector px) of ``camera`` cannot be a measurement (off its
    detectors), or None."""
    c = next(c for c in rig.cameras if c.name == camera)
    W, H = c.detector_width_px, c.detector_height_px
    for j, (u, v) in enumerate(np.asarray(uv, float).reshape(2, 2)):
        if not (-0.5 <= u <= W - 0.5 and -0.5 <= v <= H - 0.5):
            return (f"u_m{j + 1}_px, v_m{j + 1}_px = ({u:.6g}, {v:.6g}): off camera {camera}'s detector (u from -0.5 to "
                    f"{W - 0.5}, v from -0.5 to {H - 0.5} px)")
    return None


SIGMA_COLUMNS = [Column(f"sigma_{a}_m{j}", "px", required=False) for j in (1, 2) for a in ("u", "v")]


def spot_sigmas(path) -> np.ndarray | None:
    """(n, 4) the per-row centroid σ (u1, v1, u2, v2 px) of a spot table that has all four sigma columns
    (``boresight centroid`` writes them), else None."""
    t = read_table(path, [Column("camera", kind="str"), *SIGMA_COLUMNS], what="spot table")
    keys = [c.key for c in SIGMA_COLUMNS]
    if not all(k in t for k in keys):
        return None
    return np.column_stack([t[k] for k in keys])


def reference_spots(path, rig: BoresightRig) -> dict[str, np.ndarray]:
    """camera → (2, 2) reference spots: the mean of that camera's rows (eqs 16–17)."""
    _, cams, uv = read_spot_rows(path, rig, what="reference table")
    return {c: uv[[k for k, x in enumerate(cams) if x == c]].mean(axis=0) for c in dict.fromkeys(cams)}


def solve_rows(rig: BoresightRig, ref: dict[str, np.ndarray], cams: Sequence[str], uv: np.ndarray, *,
               method: str = "dvad", reading: str = "consistent") -> dict[str, BoresightEstimate]:
    """Per camera, the estimate of its rows (vectorised), as the in-process orbit scenario does."""
    out = {}
    for c in dict.fromkeys(cams):
        if c not in ref:
            raise InputError(f"camera {c!r} has rows to solve but none in the reference table")
        rows = [k for k, x in enumerate(cams) if x == c]
        out[c] = estimate(camera_geometry(rig, c), ref[c], uv[rows], method, reading)
    return out


def estimate_columns(samples, cams, est: dict[str, BoresightEstimate]) -> dict[str, list]:
    """The result table: sample, camera, delta_f_um, alpha_arcsec, beta_arcsec, gamma_arcsec."""
    cols: dict[str, list] = {k: [] for k in ("sample", "camera", "delta_f_um", "alpha_arcsec", "beta_arcsec",
                                             "gamma_arcsec")}
    pos = {c: 0 for c in est}
    for s, c in zip(samples, cams):
        e, k = est[c], pos[c]
        pos[c] += 1
        d = e.as_dict(k)
        cols["sample"].append(s)
        cols["camera"].append(c)
        for key in ("delta_f_um", "alpha_arcsec", "beta_arcsec", "gamma_arcsec"):
            cols[key].append(d[key])
    return cols


def streaming_solver(rig: BoresightRig, ref: dict[str, np.ndarray]) -> dict[str, DVADSolver]:
    """The cached DVAD solver per camera for a real-time loop (one row at a time)."""
    return {c: DVADSolver(camera_geometry(rig, c), r) for c, r in ref.items()}


# ------------------------------------------------------------------------------ the solve's fit

def window_problems(rig: BoresightRig, cams: Sequence[str], uv: np.ndarray, what: str) -> list[str]:
    """The spots that lie outside their detector's nominal ROI window (``orbit.window_px`` centred
    on the design reference spot): a camera that reads out ROIs cannot have measured them."""
    w = rig.orbit.window_px
    bad = []
    for k, c in enumerate(cams):
        g = camera_geometry(rig, c)
        for j in range(2):
            o = np.asarray(g.roi_origin(j, w), float)
            p = uv[k, j]
            if not (np.all(np.isfinite(p)) and np.all(p >= o - 0.5) and np.all(p <= o + w - 0.5)):
                bad.append((k, j, p, o))
    if not bad:
        return []
    k, j, p, o = bad[0]
    return [f"{len(bad)} {what} spot(s) outside the nominal {w}-px ROI windows (first: row {k + 1}, camera {cams[k]}, "
            f"M{j + 1} at ({p[0]:.6g}, {p[1]:.6g}) px, window u {o[0]:g}…{o[0] + w - 1:g}, v {o[1]:g}…{o[1] + w - 1:g})"]


def solve_fit_quality(rig: BoresightRig, ref_cams: Sequence[str], ref_uv: np.ndarray, ref_sigma, cams: Sequence[str],
                      uv: np.ndarray, noise_source: str) -> FitQuality:
    """DVAD is exactly determined (four spot coordinates, four unknowns), so what is judged is the
    rest: the reference rows' scatter about each camera's mean over the centroid σ (``ref_sigma``,
    (n, 4) or a scalar; χ² with 4·(rows − 1) dof per camera) and every spot inside its nominal ROI
    window (a failed check makes the fit poor)."""
    ref_cams = list(ref_cams)
    sig = np.broadcast_to(np.asarray(ref_sigma, float), (len(ref_cams), 4)).reshape(-1, 2, 2)
    res, s = [], []
    for c in dict.fromkeys(ref_cams):
        rows = [k for k, x in enumerate(ref_cams) if x == c]
        if len(rows) > 1:
            res.append(ref_uv[rows] - ref_uv[rows].mean(axis=0))
            s.append(sig[rows])
    problems = window_problems(rig, ref_cams, ref_uv, "reference") + window_problems(rig, cams, uv, "measured")
    if not res:
        return not_judged("DVAD is exactly determined and each camera has one reference row", problems=problems)
    r, s = np.concatenate(res), np.concatenate(s)
    n_means = 4 * len(res)
    ok = np.isfinite(s) & (s > 0)
    s = np.where(ok, s, np.median(s[ok]) if ok.any() else 1.0)
    return judge_residuals(r, s, n_means, f"{noise_source}: the reference rows' scatter", problems=problems)


def solve_alternatives(rig: BoresightRig, ref_cams, ref_uv, ref_sigma, cams, uv, noise_source: str) -> list:
    """(name, refit) for the spot tables read another way — u and v swapped, M1 and M2 swapped, the
    detectors mirrored (u → W−1−u) — in the reference tables, the measured ones, or both."""
    W = {c.name: CameraGeometry.from_rig(c).width_px for c in rig.cameras}

    def mirror(a, cs):
        a = a.copy()
        a[..., 0] = np.array([W[c] for c in cs], float)[:, None] - 1.0 - a[..., 0]
        return a

    transforms = [("u and v swapped (u_m1_px with v_m1_px, u_m2_px with v_m2_px)", lambda a, cs: a[..., ::-1]),
                  ("M1 and M2 swapped", lambda a, cs: a[:, ::-1]),
                  ("the detectors mirrored (u → W − 1 − u)", mirror)]
    out = []
    for name, f in transforms:
        for where, on_ref, on_meas in (("the reference tables", True, False), ("the measured tables", False, True),
                                       ("every table", True, True)):
            if on_meas and not len(cams):
                continue

            def refit(f=f, on_ref=on_ref, on_meas=on_meas):
                return solve_fit_quality(rig, ref_cams, f(ref_uv, ref_cams) if on_ref else ref_uv, ref_sigma, cams,
                                         f(uv, cams) if on_meas else uv, noise_source)

            out.append((f"{name} in {where}", refit))
    return out
