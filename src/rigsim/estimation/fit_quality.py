"""How well data fit a model, judged against their noise: χ²/dof, the chance of it, a verdict, and
the factor a covariance is scaled by (docs/fit-judgement.md).

Every estimator that reads a user's data reports one :class:`FitQuality`. Its verdict:

* ``good`` — χ²/dof within chance of 1 (its p-value ≥ :data:`CHANCE_P`): the noise model explains
  the residuals, the covariance is the noise model's;
* ``scaled`` — χ²/dof above 1 beyond chance but not by a wide margin: model errors or noise the
  model does not know; the covariance is multiplied by χ²/dof (Birge's ratio);
* ``poor`` — χ²/dof above :data:`POOR_CHI2_DOF` (a residual rms five times the noise), not finite,
  or a model check failed outright (``problems``): the data do not fit the model, and the estimate
  is not a measurement;
* ``not judged`` — no redundancy (as many data as unknowns) and no model check that failed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["CHANCE_P", "POOR_CHI2_DOF", "VERDICTS", "FitQuality", "judge_chi2", "judge_residuals", "not_judged"]

POOR_CHI2_DOF = 25.0  # the data do not fit: a residual rms 5× the noise model's
CHANCE_P = 1e-3       # χ²/dof > 1 is beyond chance when a χ² this large has a smaller probability
VERDICTS = ("good", "scaled", "poor", "not judged")


@dataclass(frozen=True)
class FitQuality:
    """χ² of a fit's residuals against the noise model, its degrees of freedom and what the noise is
    (``noise_source``, a phrase for the reports); ``residual_rms`` and ``noise_rms`` per coordinate in
    ``unit``; ``problems``: model checks that failed outright (each makes the fit poor)."""

    chi2: float
    dof: int
    noise_source: str
    unit: str = "px"
    residual_rms: float = math.nan
    noise_rms: float = math.nan
    problems: tuple[str, ...] = field(default_factory=tuple)
    limit: float = POOR_CHI2_DOF
    floor: float = 0.0  # a weighted fit's σ floor (in ``unit``), added to every σ in quadrature: its covariance has it

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def p_value(self) -> float:
        """P(χ² ≥ the fit's) for a model that fits with this noise."""
        if self.dof <= 0 or not math.isfinite(self.chi2):
            return math.nan if self.dof <= 0 else 0.0
        from scipy.stats import chi2

        return float(chi2.sf(self.chi2, self.dof))

    @property
    def poor(self) -> bool:
        return bool(self.problems) or (self.dof > 0 and not self.chi2_dof <= self.limit)

    @property
    def beyond_chance(self) -> bool:
        return self.dof > 0 and (not math.isfinite(self.chi2) or (self.chi2_dof > 1.0 and self.p_value < CHANCE_P))

    @property
    def covariance_scale(self) -> float:
        """The factor the noise model's covariance is multiplied by: χ²/dof when it is above 1 beyond
        chance (and finite), else 1; 1 for a fit whose σ carry a floor (its covariance is the fit's with
        the floor)."""
        if self.floor > 0.0:
            return 1.0
        return self.chi2_dof if self.beyond_chance and math.isfinite(self.chi2_dof) else 1.0

    @property
    def verdict(self) -> str:
        if self.poor:
            return "poor"
        if self.dof <= 0:
            return "not judged"
        return "scaled" if self.beyond_chance else "good"

    def describe(self) -> str:
        """One phrase: χ²/dof, against what, the rms ratio, the verdict."""
        if self.dof <= 0:
            head = self.noise_source
        else:
            head = f"χ²/dof {_num(self.chi2_dof)} ({self.dof} dof, against {self.noise_source})"
            if math.isfinite(self.residual_rms) and math.isfinite(self.noise_rms) and self.noise_rms > 0:
                head += (f", residual rms {_num(self.residual_rms)} {self.unit} = {_num(self.residual_rms / self.noise_rms)}× "
                         "the noise")
        v = self.verdict
        scaled = (f"above the noise beyond chance: each σ widened by a floor of {_num(self.floor)} {self.unit} in "
                  "quadrature, the covariance with it" if self.floor > 0.0 else
                  f"above the noise beyond chance: covariance scaled ×{_num(self.covariance_scale)}")
        tail = {"good": "fits within the noise",
                "scaled": scaled,
                "poor": (f"POOR FIT (limit χ²/dof {_num(self.limit)})" if self.dof > 0 and not self.chi2_dof <= self.limit
                         else "POOR FIT"),
                "not judged": "no χ² to judge"}[v]
        probs = "; ".join(self.problems)
        return f"{head}: {tail}" + (f"; {probs}" if probs else "")

    def as_dict(self) -> dict:
        """The JSON block of every result (``fit``)."""
        return {"chi2": _finite(self.chi2), "dof": int(self.dof), "chi2_dof": _finite(self.chi2_dof),
                "p_value": _finite(self.p_value), "noise": self.noise_source, "unit": self.unit,
                "residual_rms": _finite(self.residual_rms), "noise_rms": _finite(self.noise_rms),
                "problems": list(self.problems), "limit_chi2_dof": self.limit, "verdict": self.verdict,
                "covariance_scale": self.covariance_scale, "covariance_scaled": self.covariance_scale != 1.0,
                "sigma_floor": self.floor}


def judge_residuals(residuals, sigma, n_params: int, noise_source: str, *, unit: str = "px",
                    problems=(), limit: float = POOR_CHI2_DOF) -> FitQuality:
    """The quality of a least-squares fit: residuals (any shape) over their 1σ (broadcast to them),
    ``n_params`` unknowns fitted. A σ that is not finite and > 0 is an error of the caller."""
    r = np.asarray(residuals, float).ravel()
    s = np.broadcast_to(np.asarray(sigma, float), np.shape(residuals)).ravel()
    if not (np.all(np.isfinite(s)) and np.all(s > 0)):
        raise ValueError("judge_residuals: every σ must be finite and > 0")
    with np.errstate(over="ignore", invalid="ignore"):
        chi2 = float(np.sum((r / s) ** 2)) if np.all(np.isfinite(r)) else math.inf
        rms = float(np.sqrt(np.mean(r**2))) if r.size else math.nan
    return FitQuality(chi2, int(r.size - n_params), noise_source, unit, rms, float(np.sqrt(np.mean(s**2))) if s.size else math.nan,
                      tuple(problems), limit)


def judge_chi2(chi2: float, dof: int, noise_source: str, *, unit: str = "", problems=(),
               limit: float = POOR_CHI2_DOF) -> FitQuality:
    """The quality of a fit whose χ² (whitened residual sum of squares) is already known."""
    return FitQuality(float(chi2), int(dof), noise_source, unit, problems=tuple(problems), limit=limit)


def not_judged(why: str, *, problems=()) -> FitQuality:
    """An estimate with no redundancy (``why`` says so); ``problems`` still make it poor."""
    return FitQuality(0.0, 0, why, problems=tuple(problems))


def _num(x: float) -> str:
    if not math.isfinite(x):
        return "∞" if x > 0 else str(x)
    return f"{x:.3g}" if abs(x) < 1e4 else f"{x:.2e}"


def _finite(x: float):
    return float(x) if math.isfinite(x) else None
