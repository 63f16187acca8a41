"""A null search as the simulated rig runs it: the estimator's loop (:func:`rigsim.estimation.null_search.null_search`,
readings and measurements only) driven by a measurer that sees the true turntable pose, with the
exact value of the measured quantity and the true pose logged beside every frame (for the log,
the reports and the tests; the loop never reads them)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from rigsim.estimation.null_search import SearchResult, SearchStep, null_search
from rigsim.rig.turntable import TruePose, TurntableReading

__all__ = ["TracedSearch", "TracedStep", "traced_search"]


@dataclass
class TracedStep(SearchStep):
    """A search step with the exact value of the measured quantity (truth; for the log only)."""

    true: np.ndarray | None = None  # (2,) in the search's unit


@dataclass
class TracedSearch(SearchResult):
    """A search result whose steps are TracedSteps, with the true pose the final reading stands for."""

    final_true_pose_rad: TruePose | None = None

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


def traced_search(measure_true: Callable[[TruePose], tuple[np.ndarray, np.ndarray | None, dict]],
                  model: Callable[[Mapping], np.ndarray], start_reading_rad: Mapping[str, float], free: list[str],
                  reading_to_true: Callable[[Mapping], TruePose], **search) -> TracedSearch:
    """Run :func:`~rigsim.estimation.null_search.null_search` on the simulated rig.

    ``measure_true(true_pose)`` → (measured (2,), exact (2,) or None, flags) is the rig's
    measurement at a true pose; ``reading_to_true`` maps the turntable's reading to its true pose
    (the encoder errors). ``search`` are null_search's keyword options."""
    exact: list = []

    def measure(reading: TurntableReading):
        if hasattr(measure_true, "last_reading"):  # a measurer that records its frames with their readings
            measure_true.last_reading = dict(reading)
        m, ex, flags = measure_true(reading_to_true(reading))
        exact.append(ex)
        return m, flags

    res = null_search(measure, model, start_reading_rad, free, **search)
    steps = [TracedStep(iteration=s.iteration, reading_deg=s.reading_deg, measured=s.measured, seconds=s.seconds,
                        flags=s.flags, true=None if e is None else np.asarray(e, float)) for s, e in zip(res.steps, exact)]
    return TracedSearch(face=res.face, unit=res.unit, free_axes=res.free_axes, threshold=res.threshold, steps=steps,
                        converged=res.converged, final_reading_rad=res.final_reading_rad, message=res.message,
                        final_true_pose_rad=reading_to_true(res.final_reading_rad))
