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

from rigsim.estimation.fit_quality import FitQuality
from rigsim.procedures.cube_mirror.files import SweepTables, fit_sweep_tables
from rigsim.rig.cube_mirror import CubeMirrorRig

__all__ = ["null_alternatives", "sweep_alternatives"]

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


def sweep_alternatives(rig: CubeMirrorRig, t: SweepTables, axis_order: str) -> list[Alternative]:
    """(name, refit) for every reading of the sweep's two tables that :mod:`this module <.input_causes>`
    tests; ``refit()`` → the fit quality of the sun-sensor calibration of the tables read that way."""

    def refit(tt: SweepTables) -> Callable[[], FitQuality | None]:
        def run():
            cal, _, q = fit_sweep_tables(rig, tt, axis_order)
            return q if cal is not None else None
        return run

    labels = list(t.readings)
    cols = _cols(labels)
    out: list[Alternative] = []
    if _plausible_radians(np.degrees(v) for v in t.readings.values()):
        out.append((f"angles in radians under {', '.join(cols.values())}",
                    refit(replace(t, readings={a: np.degrees(v) for a, v in t.readings.items()}))))
    for a in labels:
        out.append((f"the sign of {cols[a]} flipped", refit(replace(t, readings={**t.readings, a: -t.readings[a]}))))
    for a, b in itertools.combinations(labels, 2):
        out.append((f"{cols[a]} and {cols[b]} swapped",
                    refit(replace(t, readings={**t.readings, a: t.readings[b], b: t.readings[a]}))))
    out.append(("u_px and v_px swapped", refit(replace(t, spots={f: (s[1], s[0], *s[2:]) for f, s in t.spots.items()}))))
    W = rig.sun_sensor.resolution_px[0]
    out.append((f"frames mirrored (u → {W - 1} − u)",
                refit(replace(t, spots={f: (W - 1 - s[0], *s[1:]) for f, s in t.spots.items()}))))
    out.append(("the angle log's rows one frame late (each frame's angles on the next row)", refit(_shifted(t, 1))))
    out.append(("the angle log's rows one frame early (each frame's angles on the row before)", refit(_shifted(t, -1))))
    dedup, dropped = _without_repeats(t)
    if dropped:
        out.append((f"duplicate inputs: {len(dropped)} frame(s) repeat another frame's centroid or reading exactly "
                    f"({', '.join(dropped[:3])}{', …' if len(dropped) > 3 else ''}); without them", refit(dedup)))
    return out


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
