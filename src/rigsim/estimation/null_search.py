"""The null search of a cube face: measure, move the turntable, repeat (seed 000 Table 1, seed 001 step C).

The loop is the same for the diaphragm screen (measured: hole/spot centre offset in aiming-camera
pixels) and the autocollimator (measured: its two readings in arcsec):

1. at turntable *reading* r_k (what the operator commands and the display shows), the table sits
   at the true angles ``reading_to_true(r_k)`` (encoder bias and the encoder's error at this
   position; rigsim.truth.cube_mirror.realization);
2. ``measure(true_pose)`` returns the measured 2-vector (and the exact one, for the log);
3. if both components are below ``threshold`` the face is nulled and r_k is recorded (θ1, θ2);
4. otherwise the feedback rule moves the free axes by Δr = −J⁻¹·m_k, where J = ∂model/∂r is the
   Jacobian of the operator's *nominal* prediction of the measurement (ideal turntable, nominal
   beam, face normal estimated from the current pose; no truth), rounded to
   ``command_resolution_rad`` (Table 1 moves in 0.001° steps).

Relative moves are exact (a turntable's fine positioning is far better than its absolute
accuracy); the absolute error sits in the reading, constant over the few arcseconds a search
covers, as in the analytic campaign.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass
class SearchStep:
    iteration: int
    reading_deg: dict[str, float]
    measured: np.ndarray  # (2,) in SearchResult.unit
    true: np.ndarray | None  # (2,) the exact value of the same quantity (truth; for the log only)
    seconds: float = 0.0
    flags: dict = field(default_factory=dict)


@dataclass
class SearchResult:
    face: str
    unit: str  # "px" (diaphragm offset) or "arcsec" (autocollimator reading)
    free_axes: list[str]
    threshold: float
    steps: list[SearchStep]
    converged: bool
    final_reading_rad: dict[str, float]
    final_true_pose_rad: dict[str, float]
    message: str = ""

    @property
    def n_frames(self) -> int:
        return len(self.steps)

    @property
    def final_measured(self) -> np.ndarray:
        return self.steps[-1].measured

    @property
    def final_true(self) -> np.ndarray | None:
        return self.steps[-1].true

    def table_rows(self) -> list[list]:
        """One row per frame: readings of the free axes (deg), measured x, y, exact x, y."""
        rows = []
        for s in self.steps:
            t = s.true if s.true is not None else (math.nan, math.nan)
            rows.append([s.iteration] + [s.reading_deg[a] for a in self.free_axes]
                        + [float(s.measured[0]), float(s.measured[1]), float(t[0]), float(t[1])])
        return rows

    def as_dict(self) -> dict:
        return {"face": self.face, "unit": self.unit, "free_axes": self.free_axes, "threshold": self.threshold,
                "converged": self.converged, "message": self.message,
                "final_reading_deg": {k: math.degrees(v) for k, v in self.final_reading_rad.items()},
                "steps": [{"iteration": s.iteration, "reading_deg": s.reading_deg, "measured": s.measured.tolist(),
                           "true": None if s.true is None else np.asarray(s.true).tolist(), "seconds": s.seconds,
                           "flags": s.flags} for s in self.steps]}


def numerical_jacobian(model: Callable[[dict], np.ndarray], reading_rad: dict, free: list[str],
                       h_rad: float = 1e-6) -> np.ndarray:
    """∂model/∂reading (model units per rad) by central differences over the free axes."""
    J = np.empty((2, len(free)))
    for j, a in enumerate(free):
        p, m = dict(reading_rad), dict(reading_rad)
        p[a] += h_rad
        m[a] -= h_rad
        J[:, j] = (np.asarray(model(p)) - np.asarray(model(m))) / (2.0 * h_rad)
    return J


def _quantise(x: float, step: float, origin: float = 0.0) -> float:
    """Commands are whole steps from the start reading (a relative move of k increments)."""
    return x if step <= 0 else origin + round((x - origin) / step) * step


def null_search(
    measure: Callable[[dict], tuple[np.ndarray, np.ndarray | None, dict]],
    model: Callable[[dict], np.ndarray],
    start_reading_rad: dict[str, float],
    free: list[str],
    reading_to_true: Callable[[dict], dict],
    *,
    face: str,
    unit: str,
    threshold: float,
    command_resolution_rad: float = 0.0,
    max_iterations: int = 15,
    progress: Callable[[int], None] | None = None,
) -> SearchResult:
    """Run the feedback loop (module docstring). ``measure(true_pose_rad)`` → (measured (2,),
    exact (2,) or None, flags); it raises :class:`SearchError` when nothing can be measured.
    ``model(reading_rad)`` is the operator's nominal prediction (same units as ``measure``)."""
    if not (threshold > 0):
        raise ValueError(f"threshold = {threshold!r}: must be > 0")
    q = float(command_resolution_rad)
    r = dict(start_reading_rad)
    origin = dict(start_reading_rad)
    steps: list[SearchStep] = []
    converged = False
    message = ""
    visited = set()
    for it in range(int(max_iterations)):
        t0 = time.perf_counter()
        true_pose = reading_to_true(r)
        m, exact, flags = measure(true_pose)
        m = np.asarray(m, float)
        steps.append(SearchStep(it, {k: math.degrees(v) for k, v in r.items()}, m,
                                None if exact is None else np.asarray(exact, float), time.perf_counter() - t0,
                                dict(flags)))
        if progress:
            progress(1)
        if np.all(np.abs(m) < threshold):
            converged = True
            break
        J = numerical_jacobian(model, r, free)
        dx, *_ = np.linalg.lstsq(J, -m, rcond=None)
        new = dict(r)
        for a, d in zip(free, dx):
            new[a] = _quantise(r[a] + float(d), q, origin[a])
        key = tuple(round((new[a] - origin[a]) / q) if q > 0 else new[a] for a in free)
        if key in visited or all(new[a] == r[a] for a in free):
            # the rounded Newton step lands where we have been: step the axis whose predicted
            # effect is largest by one command increment in the right direction
            if q <= 0:
                message = "the feedback step vanished before the threshold was reached"
                break
            effect = np.abs(J * q).sum(axis=0)
            j = int(np.argmax(effect))
            new = dict(r)
            new[free[j]] = r[free[j]] + math.copysign(q, float(dx[j]) if dx[j] != 0 else 1.0)
        visited.add(tuple(round((r[a] - origin[a]) / q) if q > 0 else r[a] for a in free))
        r = new
    else:
        message = f"not below {threshold:g} {unit} after {max_iterations} frames"
    if not converged and not message:
        message = f"not below {threshold:g} {unit} after {len(steps)} frames"
    return SearchResult(face, unit, list(free), float(threshold), steps, converged, dict(r),
                        reading_to_true(r), message)


def encoder_reading_to_true(bias_rad: dict[str, float], error_rad: dict[str, float], free: list[str]):
    """Map readings to true angles for the axes in ``free``: true = reading − bias − error; the
    other axes are set to their value and read back exactly (as in the analytic campaign)."""

    def f(reading: dict) -> dict:
        return {k: (v - bias_rad.get(k, 0.0) - error_rad.get(k, 0.0)) if k in free else v for k, v in reading.items()}

    return f
