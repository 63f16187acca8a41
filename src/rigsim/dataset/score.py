"""``rigsim dataset score DIR predictions.csv``: score an external pipeline against the truth.

Predictions CSV (header row required, one row per frame, extra columns ignored):

=================  ==========================================================================
mode               columns
=================  ==========================================================================
``centroid``       ``frame, u, v`` — the spot centre in pixels (OpenCV convention: the centre
                   of pixel (0, 0) is (0, 0), u right, v down)
``direction``      ``frame, x, y, z`` — the sun's direction in the sensor frame (any length;
                   normalised here)
=================  ==========================================================================

The mode is detected from the columns (``--mode`` forces it). ``frame`` is the index in the
dataset (``truth.csv``'s ``frame``). Centroids are compared with ``spot_u, spot_v`` — the exact
projection of the sun's centre — or, with ``--truth-ref pixel-centroid``, with the exact first
moment of the pixel-integrated spot (what a perfect centre-of-mass returns on these pixels).
Frames whose truth is not valid (spot cut by the edge, saturated) are left out and counted.

Reported: n, RMS, mean (bias), percentiles 50/90/95/99, max, the outliers (error > max(5 × the robust
2-D rms = 6.0 × the median error, ``--outlier``)), and the frames with no prediction.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rigsim.dataset.reader import open_dataset
from rigsim.errors import DatasetError

TRUTH_REFS = {"centre": ("spot_u", "spot_v"), "pixel-centroid": ("spot_centroid_u", "spot_centroid_v")}


@dataclass
class Score:
    mode: str
    unit: str
    n: int
    rms: float
    mean: list[float]
    percentiles: dict[str, float]
    max: float
    outliers: list[tuple[int, float]]
    missing: list[int]
    excluded_invalid: int
    outlier_threshold: float
    per_frame: dict = field(repr=False, default_factory=dict)
    columns: list[str] = field(default_factory=list)
    failed: list[int] = field(default_factory=list)
    hints: list[str] = field(default_factory=list)
    rows: list[dict] = field(repr=False, default_factory=list)

    def text(self) -> str:
        p = self.percentiles
        what = "matched stars" if self.mode.startswith("star") else "frames"
        lines = [f"{self.mode} errors over {self.n} {what} ({self.unit}; columns {', '.join(self.columns)}):",
                 f"  RMS {self.rms:.4g}   mean {', '.join(f'{m:+.4g}' for m in self.mean)}   max {self.max:.4g}",
                 "  percentiles " + "  ".join(f"{k} {v:.4g}" for k, v in p.items()),
                 f"  outliers (> {self.outlier_threshold:.3g} {self.unit}): {len(self.outliers)}"
                 + ("" if not self.outliers else " — " + ", ".join(f"{i}: {e:.3g}" for i, e in self.outliers[:10]))]
        if self.missing:
            lines.append(f"  frames without a prediction: {len(self.missing)} (first {self.missing[:10]})"
                         + (f", of which {len(self.failed)} NaN (failed fits)" if self.failed else ""))
        det = getattr(self, "detection", None)
        if det:
            lines.append(f"  stars: {det['matched']} of {det['valid_stars']} valid stars matched within "
                         f"{det['match_radius_px']:g} px, {det['missed']} missed, {det['false_detections']} false detections")
        if self.excluded_invalid:
            lines.append(f"  frames left out (truth not valid: spot cut by the edge or saturated): {self.excluded_invalid}")
        lines += [f"  hint: {h}" for h in self.hints]
        return "\n".join(lines)

    def as_dict(self) -> dict:
        """The JSON result (without the per-row table, which goes to a CSV)."""
        return {k: v for k, v in self.__dict__.items() if k not in ("per_frame", "rows")}


CENTROID_COLUMNS = (("u", "v"), ("u_px", "v_px"), ("x_centroid", "y_centroid"), ("xcentroid", "ycentroid"), ("x", "y"))
"""rigsim/OpenCV; photutils ≥ 3 (x_centroid) and before (xcentroid); sep."""
DIRECTION_COLUMNS = ("x", "y", "z")


def _columns(path, header: list[str], mode: str | None) -> tuple[str, tuple[str, ...]]:
    """The mode and the value columns used (after ``frame``), from the header."""
    if mode not in (None, "centroid", "direction"):
        raise DatasetError(f"--mode {mode!r}: allowed centroid, direction")
    if mode in (None, "direction") and all(c in header for c in DIRECTION_COLUMNS):
        return "direction", DIRECTION_COLUMNS
    if mode in (None, "centroid"):
        for pair in CENTROID_COLUMNS:
            if all(c in header for c in pair):
                return "centroid", pair
    want = ("'x, y, z' (direction)" if mode == "direction" else
            " or ".join(f"'{', '.join(c)}'" for c in CENTROID_COLUMNS) + " (centroid)"
            + ("" if mode == "centroid" else " or 'x, y, z' (direction)"))
    raise DatasetError(f"{path}: columns {header[:12]} hold no {mode or 'known'} prediction; expected 'frame' and {want}")


def read_predictions(path, mode: str | None = None, multi: bool = False, names: dict[str, int] | None = None):
    """(mode, {frame: values}, columns used, frames whose prediction is NaN or empty: a failed fit, counted as
    missing). With ``multi`` (star frames) several rows per frame: {frame: (k, d) array}. ``frame`` is the
    dataset's index, or (``names``: file name → index) the frame's file name, as ``rigsim centroid``
    writes it; with a ``spot`` column (``rigsim centroid``'s tables) a one-spot frame is scored on its
    spot 0, the brightest."""
    path = Path(path)
    if not path.exists():
        raise DatasetError(f"{path}: no such predictions file")
    if not path.is_file():
        raise DatasetError(f"{path}: not a regular file (a folder, FIFO or device); expected the predictions CSV")
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{path}: not UTF-8 text (byte {exc.start}); expected the predictions CSV") from None
    try:
        return _read_predictions(path, text, mode, multi, names)
    except csv.Error as exc:  # a field longer than the csv module's limit (131072 characters), a stray NUL
        raise DatasetError(f"{path}: not a readable CSV ({str(exc)[:100]})") from None


def _read_predictions(path, text: str, mode, multi, names=None):
    from rigsim.files.numbers import parse_float, parse_int

    rd = csv.reader(io.StringIO(text, newline=""))
    try:
        header = [h.strip() for h in next(rd)]
    except StopIteration:
        raise DatasetError(f"{path}: empty file (expected a header row)") from None
    if "frame" not in header:
        raise DatasetError(f"{path}: no 'frame' column (the dataset's frame index, truth.csv's 'frame')")
    mode, cols = _columns(path, header, mode)
    idx = [header.index("frame")] + [header.index(c) for c in cols]
    spot_col = header.index("spot") if "spot" in header and not multi else None
    out: dict[int, list | np.ndarray] = {}
    failed: list[int] = []
    for line, row in enumerate(rd, start=2):
        if not row or all(not x.strip() for x in row):
            continue
        try:
            vals = [row[i].strip() for i in idx]
        except IndexError:
            raise DatasetError(f"{path}:{line}: {len(row)} fields, header has {len(header)}") from None
        if spot_col is not None and spot_col < len(row) and row[spot_col].strip() not in ("0", ""):
            continue  # a fainter spot of a one-spot frame
        try:
            fr = parse_int(vals[0])
        except ValueError:
            fr = (names or {}).get(Path(vals[0]).name)
            if fr is None:
                raise DatasetError(f"{path}:{line}: column 'frame' = {vals[0][:40]!r} is neither a frame index nor a frame "
                                   "file of the dataset (frames/frame_NNNNNN.EXT)") from None
        try:
            v = np.array([parse_float(x) if x else math.nan for x in vals[1:]])
        except ValueError:
            bad = next(c for c, x in zip(cols, vals[1:]) if x and not _isfloat(x))
            raise DatasetError(f"{path}:{line}: column '{bad}' = {vals[1 + cols.index(bad)][:40]!r} is not a number in "
                               "ASCII digits") from None
        if np.any(np.isnan(v)):  # a failed fit: the frame has no prediction
            failed.append(fr)
            continue
        if not np.all(np.isfinite(v)):
            raise DatasetError(f"{path}:{line}: infinite value in {list(cols)}")
        if mode == "centroid" and np.max(np.abs(v)) > 1e7:
            raise DatasetError(f"{path}:{line}: ({', '.join(cols)}) = {tuple(float(x) for x in v)}: a pixel "
                               "position must lie within ±1e7 px")
        if mode == "direction" and not (1e-12 < float(np.linalg.norm(v)) < 1e150):
            raise DatasetError(f"{path}:{line}: direction ({', '.join(cols)}) = {tuple(float(x) for x in v)} has "
                               "no usable length (allowed 1e-12 to 1e150)")
        if multi:
            out.setdefault(fr, []).append(v)
            continue
        if fr in out:
            raise DatasetError(f"{path}:{line}: frame {fr} appears twice")
        out[fr] = v
    if multi:
        out = {k: np.array(v) for k, v in out.items()}
    if not out:
        raise DatasetError(f"{path}: no prediction rows" + (f" ({len(failed)} rows are NaN)" if failed else ""))
    return mode, out, cols, sorted(set(failed) - set(out))


def _frame_names(ds) -> dict[str, int]:
    """The dataset's frame file names → their index (what ``rigsim centroid frames/*`` writes as ``frame``)."""
    from rigsim.dataset.store import frame_files

    return {frame_files(ds.root, i, ds.fmt)[0].name: i for i in range(len(ds))}


def _isfloat(x) -> bool:
    from rigsim.files.numbers import parse_float

    try:
        parse_float(x)
        return True
    except ValueError:
        return False


def score(root, predictions, *, mode: str | None = None, truth_ref: str = "centre",
          outlier: float | None = None, match_radius_px: float = 2.0, outlier_abs: float | None = None) -> Score:
    """Score predictions against the dataset's truth. ``outlier``: a floor under the robust threshold (5 × the
    robust 2-D rms); ``outlier_abs``: an absolute threshold instead of it."""
    ds = open_dataset(root)
    if ds.rows_per_frame:
        return _score_stars(ds, predictions, outlier, match_radius_px, outlier_abs)
    mode, pred, cols, failed = read_predictions(predictions, mode, names=_frame_names(ds))
    t = ds.truth_numpy()
    n = len(ds)
    unknown = sorted(k for k in [*pred, *failed] if not (0 <= k < n))
    if unknown:
        raise DatasetError(f"{predictions}: frame(s) {unknown[:10]} not in the dataset (0 to {n - 1})")
    valid = t["valid"].astype(bool) if "valid" in t else np.ones(n, bool)
    if mode == "centroid":
        if truth_ref not in TRUTH_REFS:
            raise DatasetError(f"--truth-ref {truth_ref!r}: allowed {', '.join(TRUTH_REFS)}")
        cu, cv = TRUTH_REFS[truth_ref]
        if cu not in t and truth_ref == "centre" and "spot_u_px" in t:
            # aiming-camera and autocollimator kinds: units in the column names; aiming pairs score the spot frames
            cu, cv = "spot_u_px", "spot_v_px"
            if "image" in t:
                valid = valid & (t["image"] == "spot")
        if cu not in t:
            raise DatasetError(f"{ds.root}: truth has no '{cu}' column (generator {ds.manifest['generator']})")
        truth = np.stack([t[cu], t[cv]], axis=1)
        unit = "px"
    else:
        if "sun_x" not in t:
            raise DatasetError(f"{ds.root}: truth has no sun direction (generator {ds.manifest['generator']})")
        truth = np.stack([t["sun_x"], t["sun_y"], t["sun_z"]], axis=1)
        unit = "arcsec"
    frames = [i for i in sorted(pred) if valid[i]]
    excluded = sum(1 for i in pred if not valid[i])
    missing = [i for i in range(n) if valid[i] and i not in pred]
    if not frames:
        raise DatasetError("no prediction for any valid frame")
    P = np.array([pred[i] for i in frames])
    T = truth[frames]
    hints: list[str] = []
    if mode == "centroid":
        d = P - T
        err = np.hypot(d[:, 0], d[:, 1])
        mean = d.mean(axis=0).tolist()
        hints = convention_hints(P, T)
        rows = [{"frame": f, "u_pred_px": p[0], "v_pred_px": p[1], "u_true_px": q[0], "v_true_px": q[1],
                 "du_px": e[0], "dv_px": e[1], "error_px": r} for f, p, q, e, r in zip(frames, P, T, d, err)]
    else:
        Pn = P / np.linalg.norm(P, axis=1, keepdims=True)
        Tn = T / np.linalg.norm(T, axis=1, keepdims=True)
        err = np.degrees(np.arctan2(np.linalg.norm(np.cross(Pn, Tn), axis=1), np.sum(Pn * Tn, axis=1))) * 3600.0
        mean = [float(err.mean())]
        rows = [{"frame": f, "error_arcsec": r} for f, r in zip(frames, err)]
    sc = _summary(mode, unit, [f"frame {f}" for f in frames], err, mean, outlier, missing, excluded,
                  outlier_abs=outlier_abs)
    sc.per_frame = dict(zip(frames, err.tolist()))
    sc.columns, sc.failed, sc.hints, sc.rows = ["frame", *cols], [f for f in failed if f in missing], hints, rows
    return sc


def convention_hints(P: np.ndarray, T: np.ndarray) -> list[str]:
    """Likely causes of a systematic error: a constant offset near ±1 px (1-based pixels: FITS, MATLAB, IRAF) or
    ±0.5 px (a corner-origin convention), or u and v swapped (the error shrinks when they are exchanged)."""
    out = []
    d = P - T
    err = np.hypot(d[:, 0], d[:, 1])
    rms = float(np.sqrt(np.mean(err**2)))
    m = d.mean(axis=0)
    spread = float(np.sqrt(np.mean(np.sum((d - m) ** 2, axis=1))))
    if len(d) >= 3 and spread < 0.25 * float(np.hypot(*m)):
        causes = {1.0: ("1-based pixel indices (FITS, MATLAB, IRAF)", "an index shifted the wrong way (1 subtracted "
                                                                         "twice, or 0-based read as 1-based)"),
                  0.5: ("a corner-origin convention (pixel (0, 0) spans 0 to 1)", "a corner-origin convention the other "
                                                                                  "way (pixel (0, 0) spans -1 to 0)")}
        for target, (high, low) in causes.items():
            near = [abs(abs(x) - target) < 0.15 for x in m]
            if not any(near):
                continue
            parts = []
            for ax, x, n in zip("uv", m, near):
                if n:
                    parts.append(f"{ax} by {np.sign(x) * target:+g} px ({'subtract' if x > 0 else 'add'} {target:g})")
            cause = high if all(m[k] > 0 for k in (0, 1) if near[k]) else (
                low if all(m[k] < 0 for k in (0, 1) if near[k]) else f"{high}, or {low}")
            out.append(f"the error is a constant offset of ({m[0]:+.3f}, {m[1]:+.3f}) px (scatter {spread:.3f} px): "
                       f"shifted {' and '.join(parts)} — {cause} (rigsim's pixel centres are integers, 0-based, OpenCV's "
                       "convention)")
            break
    swapped = P[:, ::-1] - T
    rms_sw = float(np.sqrt(np.mean(np.sum(swapped**2, axis=1))))
    if len(d) >= 2 and rms_sw < 0.1 * rms:
        out.append(f"u and v look swapped: with them exchanged the RMS would be {rms_sw:.3g} px instead of {rms:.3g} px "
                   "(u is the column, v the row)")
    return out


def _summary(mode, unit, frames, err, mean, outlier, missing, excluded, extra: dict | None = None,
             outlier_abs: float | None = None) -> Score:
    # robust scale: for a 2-D Gaussian error of σ per axis the error *magnitude* has median
    # 1.1774 σ; an outlier is beyond 5 × the 2-D rms (5·√2·σ ≈ 6.0 × the median)
    med = float(np.median(err))
    thr = float(outlier_abs) if outlier_abs is not None else max(5.0 * math.sqrt(2.0) * med / 1.1774, outlier or 0.0)
    outl = sorted(((fr, float(e)) for fr, e in zip(frames, err) if e > thr), key=lambda x: -x[1])
    pct = {f"p{q}": float(np.percentile(err, q)) for q in (50, 90, 95, 99)}
    sc = Score(mode, unit, len(frames), float(math.sqrt(np.mean(err**2))), [float(m) for m in mean], pct,
               float(err.max()), outl, missing, excluded, thr)
    return sc


def _score_stars(ds, predictions, outlier, match_radius_px: float, outlier_abs: float | None = None) -> Score:
    """Star frames: each predicted (u, v) is matched to the nearest true star of its frame within
    ``match_radius_px``; the unmatched predictions are false detections, the unmatched valid stars
    are missed. Errors are over the matched valid stars (px)."""
    from scipy.spatial import cKDTree

    mode, pred, cols, failed = read_predictions(predictions, "centroid", multi=True, names=_frame_names(ds))
    t = ds.truth_numpy()
    n = len(ds)
    unknown = sorted(k for k in pred if not (0 <= k < n))
    if unknown:
        raise DatasetError(f"{predictions}: frame(s) {unknown[:10]} not in the dataset (0 to {n - 1})")
    fr_col = t["frame"].astype(int)
    errs, labels, d_all, rows = [], [], [], []
    false_det = missed = n_valid = 0
    for f in range(n):
        sel = np.flatnonzero((fr_col == f) & (t["star"] >= 0))
        truth_uv = np.stack([t["u"][sel], t["v"][sel]], axis=1) if len(sel) else np.zeros((0, 2))
        valid = t["valid"][sel].astype(bool)
        n_valid += int(valid.sum())
        P = pred.get(f, np.zeros((0, 2)))
        matched = np.zeros(len(sel), bool)
        if len(P) and len(sel):
            dist, j = cKDTree(truth_uv).query(P, distance_upper_bound=match_radius_px)
            for p_i, (dd, jj) in enumerate(zip(dist, j)):
                if np.isfinite(dd) and not matched[jj]:
                    matched[jj] = True
                    if valid[jj]:
                        errs.append(dd)
                        d_all.append(P[p_i] - truth_uv[jj])
                        star = int(t["star"][sel[jj]])
                        labels.append(f"frame {f} star {star}")
                        rows.append({"frame": f, "star": star, "u_pred_px": P[p_i][0], "v_pred_px": P[p_i][1],
                                     "u_true_px": truth_uv[jj][0], "v_true_px": truth_uv[jj][1],
                                     "du_px": d_all[-1][0], "dv_px": d_all[-1][1], "error_px": dd})
                else:
                    false_det += 1
        else:
            false_det += len(P)
        missed += int((valid & ~matched).sum())
    n_pred = sum(len(p) for p in pred.values())
    better = _star_convention_hint(pred, t, n, match_radius_px, len(errs), n_pred)
    if not errs:
        raise DatasetError(f"no predicted centroid lies within {match_radius_px} px of a valid true star"
                           + (f"; {better}" if better else ""))
    d_all = np.array(d_all)
    extra = {"valid_stars": n_valid, "matched": len(errs), "missed": missed, "false_detections": false_det,
             "match_radius_px": match_radius_px}
    sc = _summary("star centroid", "px", labels, np.array(errs), d_all.mean(axis=0).tolist(), outlier,
                  [f for f in range(n) if f not in pred], 0, extra, outlier_abs=outlier_abs)
    sc.per_frame = {"_detection": extra}
    sc.detection = extra
    sc.columns, sc.failed, sc.rows = ["frame", *cols], failed, rows
    P = np.array([[r["u_pred_px"], r["v_pred_px"]] for r in rows])
    T = np.array([[r["u_true_px"], r["v_true_px"]] for r in rows])
    sc.hints = ([better] if better else []) + convention_hints(P, T)
    return sc


STAR_TRANSFORMS = {"u and v exchanged": lambda P: P[:, ::-1], "1 subtracted from u and v": lambda P: P - 1.0,
                   "1 added to u and v": lambda P: P + 1.0, "0.5 subtracted from u and v": lambda P: P - 0.5,
                   "0.5 added to u and v": lambda P: P + 0.5}
"""Corrections tried when few star predictions match: the commonest convention mistakes undone."""


def _star_convention_hint(pred, t, n, radius, matched: int, n_pred: int) -> str | None:
    """When fewer than half the predictions match a true star: the correction of :data:`STAR_TRANSFORMS` under
    which most would (more than half, and twice as many as now), as a sentence; else None."""
    from scipy.spatial import cKDTree

    if n_pred == 0 or matched >= 0.5 * n_pred:
        return None
    fr_col = t["frame"].astype(int)
    trees = {}
    for f in pred:
        sel = np.flatnonzero((fr_col == f) & (t["star"] >= 0) & t["valid"].astype(bool))
        if len(sel):
            trees[f] = cKDTree(np.stack([t["u"][sel], t["v"][sel]], axis=1))
    counts = {}
    for name, fn in STAR_TRANSFORMS.items():
        k = 0
        for f, P in pred.items():
            if f in trees and len(P):
                d, _ = trees[f].query(fn(np.asarray(P, float)), distance_upper_bound=radius)
                k += int(np.isfinite(d).sum())
        counts[name] = k
    best = max(counts, key=counts.get)
    if counts[best] > 0.5 * n_pred and counts[best] > 2 * matched:
        return (f"only {matched} of {n_pred} predictions lie within {radius:g} px of a true star, {counts[best]} with "
                f"{best}: " + ("u and v look swapped (u is the column, v the row)" if "exchanged" in best else
                               "the predictions look shifted by a pixel convention (rigsim's pixel centres are integers, "
                               "0-based, OpenCV's convention)"))
    return None
