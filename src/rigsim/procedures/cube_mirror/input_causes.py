"""The mistakes a cube-mirror stage can test when its data do not fit: the same files read another
way and fitted again (:func:`rigsim.procedures.fit_verdict.judge` names those under which the data
fit; docs/fit-judgement.md).

Sweep (``calibrate sun-sensor``): angles in radians under the ``_deg`` columns, one axis's sign
flipped, two angle columns swapped, ``u_px``/``v_px`` swapped, frames mirrored (u → W−1−u; a flip
of v is the same up to the sensor's roll, which the fit absorbs), the angle log's rows shifted by
one frame against the frame names, and frames or readings that repeat another's exactly (the same
image saved twice, a reading logged twice). Null log (``triad``): radians, a flipped sign, swapped
columns, the other axis nesting."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from rigsim.errors import InputError
from rigsim.estimation.fit_quality import FitQuality
from rigsim.estimation.sun_calibration import SunCalibration
from rigsim.procedures.cube_mirror.files import SunSensorInputs, SweepTables, fit_sweep_tables, read_sweep_tables
from rigsim.procedures.cube_mirror.pipeline import default_axis_order
from rigsim.procedures.fit_verdict import REFIT_ERRORS
from rigsim.rig.cube_mirror import CubeMirrorRig

__all__ = ["SweepCauses", "calibrate_sun_sensor_files", "null_alternatives"]

Alternative = tuple[str, Callable[[], "FitQuality | None"]]


def _cols(labels) -> dict[str, str]:
    return {a: f"{a.lower()}_deg" for a in labels}


def _plausible_radians(values) -> bool:
    """Every angle (as written in the file) within ±2π, and not all within ±1e-9: the log may hold radians."""
    v = np.concatenate([np.abs(np.asarray(x, float)).ravel() for x in values])
    return bool(v.size and np.all(v <= 2 * math.pi + 1e-9) and np.any(v > 1e-9))


def _shifted(t: SweepTables, k: int) -> SweepTables:
    """Each frame takes the reading ``k`` rows below its own (k = ±1); the frame left without one is dropped."""
    n = len(t.frames)
    idx = np.arange(max(0, -k), n - max(0, k))
    frames = [t.frames[i] for i in idx]
    keep = set(frames)
    return replace(t, frames=frames, readings={a: v[idx + k] for a, v in t.readings.items()},
                   spots={f: s for f, s in t.spots.items() if f in keep})


def _without_repeats(t: SweepTables) -> tuple[SweepTables, list[str]]:
    """The tables without the frames whose centroid or whose reading repeats an earlier frame's
    exactly (the first of each is kept), and the frames dropped."""
    seen_uv: dict[tuple, str] = {}
    seen_r: dict[tuple, str] = {}
    drop = []
    labels = list(t.readings)
    for i, f in enumerate(t.frames):
        s = t.spots.get(f)
        key_r = tuple(float(t.readings[a][i]) for a in labels)
        key_uv = (s[0], s[1]) if s is not None and math.isfinite(s[0]) and math.isfinite(s[1]) else None
        if key_r in seen_r or (key_uv is not None and key_uv in seen_uv):
            drop.append(f)
            continue
        seen_r[key_r] = f
        if key_uv is not None:
            seen_uv[key_uv] = f
    keep = [i for i, f in enumerate(t.frames) if f not in set(drop)]
    frames = [t.frames[i] for i in keep]
    return replace(t, frames=frames, readings={a: v[keep] for a, v in t.readings.items()},
                   spots={f: s for f, s in t.spots.items() if f in set(frames)}), drop


def _sweep_readings(rig: CubeMirrorRig, t: SweepTables) -> list[tuple[str, SweepTables]]:
    """(name, the tables read that way) for every reading of the sweep that this module tests."""
    labels = list(t.readings)
    cols = _cols(labels)
    out: list[tuple[str, SweepTables]] = []
    if _plausible_radians(np.degrees(v) for v in t.readings.values()):
        out.append((f"angles in radians under {', '.join(cols.values())}",
                    replace(t, readings={a: np.degrees(v) for a, v in t.readings.items()})))
    for a in labels:
        out.append((f"the sign of {cols[a]} flipped", replace(t, readings={**t.readings, a: -t.readings[a]})))
    for a, b in itertools.combinations(labels, 2):
        out.append((f"{cols[a]} and {cols[b]} swapped",
                    replace(t, readings={**t.readings, a: t.readings[b], b: t.readings[a]})))
    out.append(("u_px and v_px swapped", replace(t, spots={f: (s[1], s[0], *s[2:]) for f, s in t.spots.items()})))
    W = rig.sun_sensor.resolution_px[0]
    out.append((f"frames mirrored (u → {W - 1} − u)", replace(t, spots={f: (W - 1 - s[0], *s[1:]) for f, s in t.spots.items()})))
    out.append(("the angle log's rows one frame late (each frame's angles on the next row)", _shifted(t, 1)))
    out.append(("the angle log's rows one frame early (each frame's angles on the row before)", _shifted(t, -1)))
    dedup, dropped = _without_repeats(t)
    if dropped:
        out.append((f"duplicate inputs: {len(dropped)} frame(s) repeat another frame's centroid or reading exactly "
                    f"({', '.join(dropped[:3])}{', …' if len(dropped) > 3 else ''}); without them", dedup))
    return out


class SweepCauses:
    """The sweep's alternative readings, each fitted at most once: :meth:`alternatives` for
    :func:`~rigsim.procedures.fit_verdict.judge`, and :meth:`outliers_explained`, which asks whether
    the frames the outlier test left out are a wrong reading of the files rather than spoilt frames."""

    def __init__(self, rig: CubeMirrorRig, t: SweepTables, axis_order: str):
        self.rig, self.axis_order = rig, axis_order
        self.readings = _sweep_readings(rig, t)
        self._fits: dict[str, tuple] = {}
        self._most_left_out: int | None = None  # set when the given files' outliers are a wrong reading's

    def fit(self, name: str, tt: SweepTables):
        """(calibration or None, fit quality) of the tables read as ``name`` (cached)."""
        if name not in self._fits:
            cal, _, q = fit_sweep_tables(self.rig, tt, self.axis_order)
            self._fits[name] = (cal, q)
        return self._fits[name]

    def alternatives(self) -> list[Alternative]:
        """(name, refit) pairs; after :meth:`outliers_explained` has made the given files' fit poor, a
        reading that leaves out too many frames itself (more than half as many) does not fit either."""
        def refit(name, tt) -> Callable[[], FitQuality | None]:
            def run():
                cal, q = self.fit(name, tt)
                if cal is None:
                    return None
                if self._most_left_out is not None and len(cal.outliers) > self._most_left_out:
                    q = replace(q, problems=(*q.problems, f"{len(cal.outliers)} frames left out by the outlier test"))
                return q
            return run
        return [(name, refit(name, tt)) for name, tt in self.readings]

    def outliers_explained(self, cal, q: FitQuality) -> FitQuality:
        """``q``, made poor when the outlier test left out frames that another reading of the files
        explains: a reading whose fit is not poor and leaves out at most half as many frames, and at
        least :data:`MIN_EXPLAINED` fewer. Spoilt frames are few and scattered; a log one row late
        leaves out exactly the frames where the outer axis steps, and the rest of the sweep absorbs
        the shift into R(sun←rot) (docs/campaign.md)."""
        n = 0 if cal is None else len(cal.outliers)
        if n < MIN_EXPLAINED:
            return q
        for name, tt in self.readings:
            try:
                alt, qa = self.fit(name, tt)
            except REFIT_ERRORS:
                continue
            if alt is None or qa.poor or len(alt.outliers) > min(n // 2, n - MIN_EXPLAINED):
                continue
            self._most_left_out = min(n // 2, n - MIN_EXPLAINED)
            return replace(q, problems=(*q.problems, (
                f"{n} frames left out by the outlier test (beyond {self.rig.procedure.sweep_outlier_sigma:g}× the robust "
                f"scale) are not spoilt frames: read as {name}, {len(alt.outliers)} are left out")))
        return q


MIN_EXPLAINED = 3
"""Fewer frames than this left out by the outlier test are never taken for a wrong reading of the files."""


def calibrate_sun_sensor_files(rig: CubeMirrorRig, angles_path, centroids_path, axis_order: str | None = None
                               ) -> tuple[SunCalibration, SunSensorInputs]:
    """Step 1 / B on files: intrinsics, distortion and R(sun←rot) by least squares (its fit quality
    in ``SunCalibration.fit``; ``rigsim calibrate sun-sensor`` refuses a poor one). Frames left out by
    the outlier test that another reading of the files explains make the quality poor
    (:meth:`SweepCauses.outliers_explained`)."""
    order = axis_order or default_axis_order(rig)
    tables = read_sweep_tables(rig, angles_path, centroids_path)
    cal, inp, q = fit_sweep_tables(rig, tables, order)
    if cal is None:
        raise InputError(f"{centroids_path}: {q.describe()}")
    if cal.fit is not None:
        cal.fit = SweepCauses(rig, tables, order).outliers_explained(cal, cal.fit)
    return cal, inp


def null_alternatives(labels, readings_rad: list[dict], judge_readings: Callable[[list[dict], str | None], FitQuality],
                      other_orders=(), cols: dict[str, str] | None = None) -> list[Alternative]:
    """(name, refit) for the null log's readings read another way; ``judge_readings(readings,
    axis_order)`` → the quality of TRIAD on them (``axis_order`` None: the command's own).
    ``cols``: axis label → the readings' name in the messages (default the log's ``x_deg``…)."""
    cols = cols or _cols(labels)
    out: list[Alternative] = []

    def with_(f) -> list[dict]:
        return [f(dict(r)) for r in readings_rad]

    if _plausible_radians([math.degrees(v) for r in readings_rad for v in r.values()]):
        out.append((f"angles in radians under {', '.join(cols.values())}",
                    lambda: judge_readings(with_(lambda r: {a: math.degrees(v) for a, v in r.items()}), None)))
    for a in labels:
        out.append((f"the sign of {cols[a]} flipped", lambda a=a: judge_readings(with_(lambda r: {**r, a: -r[a]}), None)))
    for a, b in itertools.combinations(labels, 2):
        out.append((f"{cols[a]} and {cols[b]} swapped",
                    lambda a=a, b=b: judge_readings(with_(lambda r: {**r, a: r[b], b: r[a]}), None)))
    for o in other_orders:
        out.append((f"the other axis nesting (--axis-order {o})", lambda o=o: judge_readings(readings_rad, o)))
    return out
