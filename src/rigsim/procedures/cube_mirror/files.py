"""The cube-mirror stages on a user's files (seeds 000/001): the sun-sensor calibration from an angle
log and a centroid table, TRIAD from the readings at the two face nulls, and R(cube←sun) with its
covariance. Observations and the nominal rig only; the in-process campaign calls the same
estimators (:mod:`rigsim.procedures.cube_mirror.pipeline`).

Rotations are written as matrices with a covariance of the small rotation δ (arcsec²) in
``R_true ≈ exp([δ]×)·R``, δ about the target frame's axes (the convention of the comparison step)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.errors import InputError
from rigsim.estimation.cube_attitude import AXIS_ORDERS_2AXIS, AXIS_ORDERS_3AXIS, cube_from_rot_triad, normal_in_mount
from rigsim.estimation.fit_quality import POOR_CHI2_DOF, FitQuality, judge_chi2, judge_residuals, not_judged
from rigsim.estimation.sun_calibration import SunCalibration
from rigsim.files import Column, covariance_block, read_json, read_table, symmetric_covariance
from rigsim.frames import ARCSEC_PER_RAD, angle_between
from rigsim.imaging.frame_spots import REJECT
from rigsim.optics.cube import FACE_NORMALS
from rigsim.procedures.cube_mirror.pipeline import fit_sun_sensor
from rigsim.procedures.results import ROTATION_CONVENTION, rotation_block
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import TurntableModel, TurntableReading, as_reading

__all__ = [
    "ROTATION_CONVENTION",
    "SunSensorInputs",
    "SweepTables",
    "angle_columns",
    "axis_orders",
    "compose_rotations",
    "fit_sweep_tables",
    "join_sweep",
    "read_sweep_tables",
    "read_angle_log",
    "read_nulls",
    "read_spot_table",
    "sun_calibration_json",
    "sun_sensor_inputs",
    "triad_fit_quality",
    "triad_json",
    "triad_with_covariance",
    "write_opencv_camera",
]



def axis_orders(rig: CubeMirrorRig) -> dict[str, str]:
    """The axis-nesting readings allowed for the rig's turntable."""
    return AXIS_ORDERS_2AXIS if len(rig.turntable.axes) == 2 else AXIS_ORDERS_3AXIS


def angle_columns(rig: CubeMirrorRig) -> list[Column]:
    """One column per turntable axis: ``x_deg``, ``y_deg`` (and ``z_deg`` on a 3-axis table)."""
    return [Column(a.label.lower(), "deg") for a in rig.turntable.axes]


def _check_degrees(path, t: dict, rig: CubeMirrorRig) -> None:
    """Every axis column of table ``t`` within ±360°."""
    for a in rig.turntable.axes:
        x = t[f"{a.label.lower()}_deg"]
        bad = np.flatnonzero(np.abs(x) > 360.0)
        if bad.size:
            raise InputError(f"{path}: line {t['__line__'][bad[0]]}, column {a.label.lower()}_deg: {x[bad[0]]}; "
                             "expected -360 to 360 degrees")


def read_angle_log(path, rig: CubeMirrorRig) -> tuple[list[str], TurntableReading, np.ndarray]:
    """An angle log (``frame`` and one ``<axis>_deg`` column per axis): (frame names, the readings
    in radians, each row's line). Frame names are unique."""
    t = read_table(path, [Column("frame", kind="str"), *angle_columns(rig)], what="angle log")
    frames = [Path(f).name for f in t["frame"]]
    seen: dict[str, int] = {}
    for f, line in zip(frames, t["__line__"]):
        if f in seen:
            raise InputError(f"{path}: line {line}, column frame: {f!r} already on line {seen[f]}; one row per frame")
        seen[f] = int(line)
    _check_degrees(path, t, rig)
    reading = TurntableReading({a.label: np.radians(t[f"{a.label.lower()}_deg"]) for a in rig.turntable.axes})
    return frames, reading, t["__line__"]


def read_spot_table(path) -> dict[str, tuple[float, float, int, int, float, float]]:
    """A centroid table (``frame``, ``u_px``, ``v_px``, optional ``spot``, ``flags``, ``sigma_u_px``
    and ``sigma_v_px``): per frame its first spot (``spot`` 0, the brightest in ``rigsim centroid``'s
    tables), as (u, v, flags, line, σu, σv); σ is NaN when the table has none. A NaN position is a
    failed measurement (kept, flagged INVALID)."""
    t = read_table(path, [Column("frame", kind="str"), Column("u", "px", allow_nan=True),
                          Column("v", "px", allow_nan=True), Column("spot", kind="int", required=False),
                          Column("flags", kind="int", required=False),
                          Column("sigma_u", "px", required=False, allow_nan=True),
                          Column("sigma_v", "px", required=False, allow_nan=True)], what="centroid table")
    n = len(t["__line__"])
    spot = t.get("spot", np.zeros(n, np.int64))
    flags = t.get("flags", np.zeros(n, np.int64))
    nan = np.full(n, np.nan)
    su, sv = t.get("sigma_u_px", nan), t.get("sigma_v_px", nan)
    for key, s in (("sigma_u_px", su), ("sigma_v_px", sv)):
        bad = np.flatnonzero(s < 0.0)
        if bad.size:
            raise InputError(f"{path}: line {t['__line__'][bad[0]]}, column {key}: {s[bad[0]]}; expected ≥ 0 px or empty")
    out: dict[str, tuple[float, float, int, int, float, float]] = {}
    seen: dict[tuple[str, int], int] = {}
    for i in np.argsort(spot, kind="stable"):
        f = Path(str(t["frame"][i])).name
        key, line = (f, int(spot[i])), int(t["__line__"][i])
        if key in seen:
            raise InputError(f"{path}: line {line}, column frame: {f!r} spot {key[1]} already on line {seen[key]}; one row "
                             "per frame and spot (a frame listed twice is not new data)")
        seen[key] = line
        if f in out:
            continue
        fl = int(flags[i]) | (int(REJECT) if not (np.isfinite(t["u_px"][i]) and np.isfinite(t["v_px"][i])) else 0)
        out[f] = (float(t["u_px"][i]), float(t["v_px"][i]), fl, int(t["__line__"][i]), float(su[i]), float(sv[i]))
    return out


@dataclass
class SunSensorInputs:
    """The sweep as the estimator sees it, joined from the two files."""

    frames: list[str]
    readings: TurntableReading
    uv: np.ndarray
    rejected: list[str] = field(default_factory=list)  # frames whose spot is flagged or missing
    sigma_uv: np.ndarray | None = None  # the centroids' 1σ (N, 2), NaN where the table gives none


@dataclass(frozen=True)
class SweepTables:
    """The angle log and the centroid table as read, before they are joined: the log's frames and
    readings (rad) in its row order, and the table's first spot per frame (:func:`read_spot_table`).
    The fit's causes (:mod:`rigsim.procedures.cube_mirror.input_causes`) read them other ways."""

    frames: list[str]
    readings: dict[str, np.ndarray]
    spots: dict[str, tuple[float, float, int, int, float, float]]
    angles_path: str
    centroids_path: str


def read_sweep_tables(rig: CubeMirrorRig, angles_path, centroids_path) -> SweepTables:
    """Read an angle log and a centroid table; every frame of the centroid table must be in the log."""
    frames, reading, _ = read_angle_log(angles_path, rig)
    spots = read_spot_table(centroids_path)
    known = set(frames)
    W, H = rig.sun_sensor.resolution_px
    for f, (u, v, _, line, _, _) in spots.items():
        if f not in known:
            raise InputError(f"{centroids_path}: line {line}, column frame: {f!r} has no row in the angle log {angles_path}")
        if np.isfinite(u) and np.isfinite(v) and not (-1.0 <= u <= W and -1.0 <= v <= H):
            raise InputError(f"{centroids_path}: line {line}, columns u_px, v_px: ({u:.6g}, {v:.6g}) px lies off the sun "
                             f"sensor's {W}×{H} px detector (u from -0.5 to {W - 0.5}, v from -0.5 to {H - 0.5})")
    return SweepTables(frames, {k: np.asarray(v, float) for k, v in reading.items()}, spots, str(angles_path),
                       str(centroids_path))


def join_sweep(t: SweepTables) -> SunSensorInputs:
    """The frames of the log with a usable spot (flags INVALID, SATURATED, EDGE, or none: left out,
    as the in-process sweep does), their readings, centroids and σ."""
    keep, uv, sig, rejected = [], [], [], []
    for i, f in enumerate(t.frames):
        s = t.spots.get(f)
        if s is None or s[2] & int(REJECT):
            rejected.append(f)
            continue
        keep.append(i)
        uv.append(s[:2])
        sig.append(s[4:6])
    keep = np.array(keep, dtype=int)
    return SunSensorInputs([t.frames[i] for i in keep], TurntableReading({k: v[keep] for k, v in t.readings.items()}),
                           np.array(uv, float).reshape(-1, 2), rejected, np.array(sig, float).reshape(-1, 2))


def sun_sensor_inputs(rig: CubeMirrorRig, angles_path, centroids_path) -> SunSensorInputs:
    """Join an angle log and a centroid table on the frame name. Every frame of the centroid table
    must be in the log; frames without a usable spot (flags INVALID, SATURATED, EDGE, or none) are
    left out, as the in-process sweep does."""
    return join_sweep(read_sweep_tables(rig, angles_path, centroids_path))


def fit_sweep_tables(rig: CubeMirrorRig, t: SweepTables, axis_order: str
                     ) -> tuple[SunCalibration | None, SunSensorInputs, FitQuality]:
    """The sun-sensor calibration of joined tables and its fit quality. A least squares that ends
    at a non-physical camera (a focal length ≤ 0: data that no sun sensor could give) is no
    calibration (None) and a poor fit."""
    inp = join_sweep(t)
    if len(inp.frames) < 8:
        raise InputError(f"{t.centroids_path}: {len(inp.frames)} frames with a usable spot; the calibration needs at least 8")
    try:
        cal = fit_sun_sensor(rig, inp.readings, inp.uv, axis_order, sigma_uv=inp.sigma_uv)
    except ValueError as exc:
        if "at least 8" in str(exc):
            raise InputError(f"{t.centroids_path}: {exc}") from None
        return None, inp, judge_chi2(math.inf, 2 * len(inp.frames) - 12, "the centroids' σ",
                                     problems=(f"the least squares ends at a non-physical camera ({exc})",))
    return cal, inp, cal.fit or not_judged("no centroid σ: neither the table nor the rig gives one")


def covariance_source(q: FitQuality | None) -> str:
    """How a sun-sensor calibration's covariance was made (the JSON's ``sigma_source``)."""
    if q is None or q.dof <= 0:
        return "residual scatter of the fit (σ² = RSS / dof): no centroid σ to judge it against"
    if q.floor > 0.0:
        return (f"{q.noise_source}, each widened by a floor of {q.floor:.4g} px in quadrature (the fit's weights; the "
                f"residuals exceed the σ alone beyond chance: χ²/dof {q.chi2_dof:.3g} without the floor, 1 with it)")
    if q.covariance_scale != 1.0:
        return (f"{q.noise_source}, scaled by χ²/dof = {q.covariance_scale:.4g} (the residuals exceed the noise beyond "
                "chance)")
    return f"{q.noise_source} (χ²/dof {q.chi2_dof:.3g}, within chance of 1: not scaled)"


def sun_calibration_json(cal: SunCalibration, rig: CubeMirrorRig, axis_order: str, inputs: SunSensorInputs,
                         fit: dict | None = None) -> dict:
    """The calibration as one JSON object: intrinsics with their covariance, R(sun←rot) with its
    covariance, residual statistics, the frames used, and the fit's verdict (``fit``: the command's
    :meth:`~rigsim.procedures.fit_verdict.Verdict.block`; default the calibration's own quality)."""
    cam = cal.camera
    n_int = len(cal.param_names) - 3
    units = {"fx": "px", "fy": "px", "cx": "px", "cy": "px"}
    return {
        "format": "rigsim.sun-sensor-calibration/1", "procedure": "cube-mirror", "stage": "calibrate",
        "kind": "sun-sensor calibration", "rig": rig.name, "axis_order": axis_order,
        "intrinsics": {"fx_px": cam.fx, "fy_px": cam.fy, "cx_px": cam.cx, "cy_px": cam.cy,
                       "width_px": cam.width, "height_px": cam.height},
        "distortion": {"k1": cam.k1, "k2": cam.k2, "p1": cam.p1, "p2": cam.p2, "k3": cam.k3,
                       "model": "OpenCV (Brown), normalised coordinates"},
        "intrinsics_covariance": covariance_block(cal.param_names[:n_int], cal.covariance[:n_int, :n_int],
                                                  [units.get(a, "1") for a in cal.param_names[:n_int]]),
        "R_sun_from_rot": rotation_block(cal.R_sun_from_rot, cal.rotation_covariance_rad2),
        "residual_rms_px": cal.rms_px, "n_frames": cal.n_points, "n_rejected": len(inputs.rejected),
        "frames_rejected": inputs.rejected,
        "n_outliers": len(cal.outliers),
        "frames_outliers": [inputs.frames[i] for i in cal.outliers],
        "outlier_sigma": rig.procedure.sweep_outlier_sigma,
        "n_outside_field": len(cal.outside_field),
        "frames_outside_field": [inputs.frames[i] for i in cal.outside_field],
        "max_field_deg": rig.procedure.sweep_max_field_deg,
        "sigma_source": covariance_source(cal.fit),
        "fit": fit if fit is not None else (cal.fit.as_dict() if cal.fit is not None else None),
    }


def write_opencv_camera(path, cal_camera, *, poor_fit: bool = False) -> Path:
    """OpenCV's FileStorage camera of a calibrated :class:`~rigsim.optics.camera.PinholeBrown`, YAML, JSON or XML by
    the suffix (:func:`rigsim.files.opencv.write_opencv_camera`); a poor fit written anyway is marked
    (``rigsim_fit_verdict: poor``)."""
    from rigsim.files.opencv import write_opencv_camera as write

    c = cal_camera
    return write(path, c.fx, c.fy, c.cx, c.cy, [c.k1, c.k2, c.p1, c.p2, c.k3], c.width, c.height,
                 fit_verdict="poor" if poor_fit else None)


def plot_residuals(cal: SunCalibration, path, title: str = "") -> Path:
    """Residuals (measured − model, px) of the sweep over the detector, magnified, and their histogram."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rigsim.files import atomic_write_bytes

    r, uv = cal.residuals_px, cal.uv
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.8), gridspec_kw={"width_ratios": [1.3, 1]})
    scale = 0.1 * max(cal.camera.width, cal.camera.height) / max(float(np.max(np.linalg.norm(r, axis=1))), 1e-12)
    a.quiver(uv[:, 0], uv[:, 1], r[:, 0], r[:, 1], angles="xy", scale_units="xy", scale=1.0 / scale, width=0.003)
    a.set_xlim(0, cal.camera.width)
    a.set_ylim(cal.camera.height, 0)
    a.set_aspect("equal")
    a.set_xlabel("u (px)")
    a.set_ylabel("v (px)")
    a.set_title(f"residuals × {scale:.0f}")
    b.hist(r[:, 0], bins=30, alpha=0.6, label=f"u: rms {np.sqrt(np.mean(r[:, 0] ** 2)):.4f} px")
    b.hist(r[:, 1], bins=30, alpha=0.6, label=f"v: rms {np.sqrt(np.mean(r[:, 1] ** 2)):.4f} px")
    b.set_xlabel("residual (px)")
    b.set_ylabel("frames")
    b.legend()
    fig.suptitle(title or f"sun-sensor calibration: {cal.n_points} frames, rms {cal.rms_px:.4f} px")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return atomic_write_bytes(path, buf.getvalue())


# ------------------------------------------------------------------------------ TRIAD and compose

def read_nulls(path, rig: CubeMirrorRig) -> tuple[list[str], list[TurntableReading]]:
    """The readings at the two face nulls: two rows of ``face`` (e.g. +Z) and ``<axis>_deg``."""
    t = read_table(path, [Column("face", kind="str"), *angle_columns(rig)], what="null log")
    if len(t["face"]) != 2:
        raise InputError(f"{path}: {len(t['face'])} rows; expected 2 (one per nulled face)")
    for f, line in zip(t["face"], t["__line__"]):
        if f not in FACE_NORMALS:
            raise InputError(f"{path}: line {line}, column face: {f!r}; expected one of {', '.join(FACE_NORMALS)}")
    _check_degrees(path, t, rig)
    if t["face"][0] == t["face"][1]:
        raise InputError(f"{path}: line {t['__line__'][1]}, column face: {t['face'][1]!r} again; expected the nulls of two "
                         "different faces")
    readings = [TurntableReading({a.label: float(np.radians(t[f"{a.label.lower()}_deg"][i])) for a in rig.turntable.axes})
                for i in range(2)]
    return [str(f) for f in t["face"]], readings


def reading_sigma_rad(rig: CubeMirrorRig, free_axes: Sequence[str] = ("X", "Y")) -> dict[str, float]:
    """1σ of each null reading: the encoder's, and on the two axes the null search drives, the
    null's own pointing σ (the rig's aiming-camera or autocollimator accuracy) in quadrature."""
    out = {}
    for a in rig.turntable.axes:
        s2 = (a.encoder_sigma_arcsec / ARCSEC_PER_RAD) ** 2
        if a.label in free_axes:
            s2 += rig.null_sigma_rad**2
        out[a.label] = float(np.sqrt(s2))
    return out


def triad_with_covariance(readings: Sequence, faces: Sequence[str], axis_order: str, sigma_rad: dict[str, float],
                          d_rot=(0.0, 0.0, 1.0), step_rad: float = 1e-6, eq8: str = "beam") -> tuple[np.ndarray, np.ndarray]:
    """TRIAD R(cube←rot) and the covariance (rad²) of its small rotation δ, propagated from
    independent reading errors of σ ``sigma_rad`` per axis (central differences). ``eq8``: the reading of
    the normals (:data:`rigsim.estimation.cube_attitude.EQ8_READINGS`)."""
    R0, _, _ = cube_from_rot_triad(readings, faces, axis_order, d_rot, eq8)

    def delta(rr):
        R, _, _ = cube_from_rot_triad([TurntableReading(x) for x in rr], faces, axis_order, d_rot, eq8)
        return Rotation.from_matrix(R @ R0.T).as_rotvec()

    cols = _reading_columns(readings, sigma_rad, delta, step_rad)
    J = np.array(cols).T if cols else np.zeros((3, 0))
    return R0, J @ J.T


def _reading_columns(readings: Sequence, sigma_rad: dict[str, float], f, step_rad: float) -> list:
    """σ·∂f/∂θ for each reading's each axis of σ > 0 (central differences): the columns of f's error
    propagation from independent reading errors."""
    cols = []
    for i in range(len(readings)):
        for lab, s in sigma_rad.items():
            if s <= 0:
                continue
            d = []
            for sgn in (1.0, -1.0):
                rr = [dict(r) for r in readings]
                rr[i][lab] = rr[i].get(lab, 0.0) + sgn * step_rad
                d.append(np.asarray(f(rr), float))
            cols.append((d[0] - d[1]) / (2 * step_rad) * s)
    return cols


CUBE_ALLOWANCE_ARCSEC = 60.0  # normals this far from a perfect cube's angle are still a cube on a real table


def triad_fit_quality(readings: Sequence, faces: Sequence[str], axis_order: str, sigma_rad: dict[str, float],
                      d_rot=(0.0, 0.0, 1.0), step_rad: float = 1e-6) -> FitQuality:
    """TRIAD's one redundant datum judged: the angle between the two measured face normals (the beam
    direction read back through each null's reading, nominal turntable of nesting ``axis_order``)
    against the angle between the two faces of a perfect cube, over its σ propagated from
    independent reading errors of σ ``sigma_rad`` per axis (central differences); χ² with 1 dof.
    It is poor beyond 5σ *and* :data:`CUBE_ALLOWANCE_ARCSEC` (a real cube's faces and a real table's
    axes are not perfect: a deviation below it scales the covariance, e.g. seed 000 Table 1's
    43″). A flipped sign or swapped columns keep the angle, so this datum cannot reveal them."""
    model = TurntableModel.nominal(list(axis_order))

    def angle(rr) -> float:
        r1, r2 = (normal_in_mount(model, as_reading(r), d_rot) for r in rr)
        return float(angle_between(r1, r2))

    rr = [dict(r) for r in readings]
    a = angle(rr)
    a_faces = float(angle_between(FACE_NORMALS[faces[0]], FACE_NORMALS[faces[1]]))
    var = float(sum(c**2 for c in _reading_columns(rr, sigma_rad, angle, step_rad)))
    dev = (a - a_faces) * ARCSEC_PER_RAD
    sig = float(np.sqrt(var)) * ARCSEC_PER_RAD
    if not sig > 0:
        return not_judged("no reading σ to judge the normals' angle against")
    return judge_residuals([dev], sig, 0, f"the readings' σ through the normals' angle, {sig:.3g}″", unit="arcsec",
                           problems=(() if np.degrees(a) >= 1.0 else
                                     (f"the two nulls give the same normal ({np.degrees(a):.4f}° apart)",)),
                           limit=max(POOR_CHI2_DOF, (CUBE_ALLOWANCE_ARCSEC / sig) ** 2))


def triad_json(R: np.ndarray, cov_rad2: np.ndarray, faces, axis_order: str, readings, sigma_rad: dict, rig_name="",
               eq8: str = "beam") -> dict:
    return {"format": "rigsim.triad/1", "procedure": "cube-mirror", "stage": "triad", "kind": "TRIAD", "rig": rig_name,
            "faces": list(faces), "axis_order": axis_order, "eq8": eq8,
            "readings_deg": [{k: float(np.degrees(v)) for k, v in r.items()} for r in readings],
            "reading_sigma_arcsec": {k: v * ARCSEC_PER_RAD for k, v in sigma_rad.items()},
            "R_cube_from_rot": rotation_block(R, cov_rad2)}


def _rotation_from(path, key: str) -> tuple[np.ndarray, np.ndarray, dict | None]:
    """A rotation block of a JSON result: the matrix, its covariance (rad², symmetrised within
    :func:`rigsim.files.symmetric_covariance`'s tolerance) and the result's ``fit`` block (None if it has none)."""
    obj = read_json(path, required=(key,), what=f"result with {key}")
    blk = obj[key]
    try:
        R = np.array(blk["matrix"], float)
        C = np.array(blk["covariance"]["matrix"], float) / ARCSEC_PER_RAD**2
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{path}: {key} needs 'matrix' (3×3) and 'covariance': {{'matrix': 3×3 in arcsec²}}") from None
    if R.shape != (3, 3) or C.shape != (3, 3) or not (np.all(np.isfinite(R)) and np.all(np.isfinite(C))):
        raise InputError(f"{path}: {key}: matrix {R.shape}, covariance {C.shape}; expected finite 3×3 each")
    if abs(np.linalg.det(R) - 1.0) > 1e-6 or np.max(np.abs(R @ R.T - np.eye(3))) > 1e-6:
        raise InputError(f"{path}: {key}.matrix is not a rotation (det {np.linalg.det(R):.6f}); expected R·Rᵀ = I, det +1")
    C = symmetric_covariance(C, where=f"{path}: {key}.covariance")
    fit = obj.get("fit")
    return R, C, fit if isinstance(fit, dict) else None


def compose_rotations(cube_path, sun_path, *, accept_poor_fit: bool = False) -> dict:
    """R(cube←sun) = R(cube←rot)·R(sun←rot)ᵀ (seed 001 eq 9) with Σ = Σ_cube + R·Σ_sun·Rᵀ (independent
    inputs; δ_cube←sun = δ_cube←rot − R(cube←sun)·δ_sun←rot). The inputs' fit verdicts are carried
    in ``fit``; an input marked as a poor fit is refused (:class:`~rigsim.errors.PoorFitError`)
    unless ``accept_poor_fit``."""
    return compose_with_verdict(cube_path, sun_path, accept_poor_fit=accept_poor_fit)[0]


def compose_with_verdict(cube_path, sun_path, *, accept_poor_fit: bool = False):
    """:func:`compose_rotations` and its :class:`~rigsim.procedures.fit_verdict.Verdict`."""
    from rigsim.procedures.fit_verdict import inherited

    Rc, Cc, fc = _rotation_from(cube_path, "R_cube_from_rot")
    Rs, Cs, fs = _rotation_from(sun_path, "R_sun_from_rot")
    verdict = inherited({"cube_from_rot": fc, "sun_from_rot": fs}, accept=accept_poor_fit, what="R(cube←sun)")
    R = Rc @ Rs.T
    C = Cc + R @ Cs @ R.T
    return {"format": "rigsim.compose/1", "procedure": "cube-mirror", "stage": "compose", "kind": "compose", "inputs": {"cube_from_rot": str(cube_path), "sun_from_rot": str(sun_path)},
            "R_cube_from_sun": rotation_block(R, C), "fit": verdict.block()}, verdict
