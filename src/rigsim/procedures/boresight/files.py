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
from rigsim.files import Column, read_image, read_table
from rigsim.imaging import NoiseModel
from rigsim.imaging.rois import centroid_rois
from rigsim.optics.line_camera import CameraGeometry
from rigsim.rig.boresight import BoresightRig

__all__ = ["SIGMA_COLUMNS", "SPOT_COLUMNS", "camera_geometry", "spot_sigmas", "centroid_roi_files", "read_spot_rows", "reference_spots",
           "solve_rows", "estimate_columns", "streaming_solver"]

SPOT_COLUMNS = [Column("camera", kind="str"), Column("u_m1", "px"), Column("v_m1", "px"), Column("u_m2", "px"),
                Column("v_m2", "px"), Column("sample", kind="str", required=False)]


def camera_geometry(rig: BoresightRig, camera: str) -> CameraGeometry:
    """The nominal geometry of the rig's camera named ``camera``."""
    names = [c.name for c in rig.cameras]
    if camera not in names:
        raise InputError(f"camera {camera!r}: this rig ({rig.name}) has cameras {', '.join(names)}")
    return CameraGeometry.from_rig(rig.cameras[names.index(camera)])


def centroid_roi_files(rig: BoresightRig, camera: str, m1: Sequence, m2: Sequence, *, method: str = "tcom") -> dict:
    """The spot table of pairs of ROI files (i-th M1 with i-th M2) of one camera."""
    if len(m1) != len(m2):
        raise InputError(f"--m1 has {len(m1)} frames and --m2 {len(m2)}; expected one M2 frame per M1 frame")
    from rigsim.files.inputs import check_distinct

    check_distinct([*m1, *m2], "--m1/--m2", by_name=False, what="ROI frame")
    geom = camera_geometry(rig, camera)
    w = rig.orbit.window_px
    noise = NoiseModel.from_detector(rig.detector)
    cols: dict[str, list] = {k: [] for k in ("sample", "camera", "m1_frame", "m2_frame", "u_m1_px", "v_m1_px",
                                             "u_m2_px", "v_m2_px", "sigma_u_m1_px", "sigma_v_m1_px", "sigma_u_m2_px",
                                             "sigma_v_m2_px")}
    for i, pair in enumerate(zip(m1, m2)):
        uv, sig = [], []
        for j, p in enumerate(pair):
            dn = read_image(p, shape=(w, w), what=f"M{j + 1} ROI")
            m = centroid_rois(dn, [geom.roi_origin(j, w)], method=method, noise=noise)
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
