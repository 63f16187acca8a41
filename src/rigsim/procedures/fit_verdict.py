"""Every command that estimates from a user's files judges its own fit (docs/fit-judgement.md).

A command computes the :class:`~rigsim.estimation.fit_quality.FitQuality` of its estimate and calls
:func:`judge`. When the fit is poor, the alternatives it can test — the same files read another
way (angles in radians, a flipped sign, swapped columns, mirrored frames, a shifted row, duplicate
inputs) — are refitted, and the ones under which the data fit are named. Without
``--accept-poor-fit`` the command then stops with :class:`~rigsim.errors.PoorFitError` (exit
status 3) before it writes anything; with it, the result is written and marked.

Use in a command::

    add_accept_option(parser)                                   # --accept-poor-fit
    q = judge_residuals(res, sigma, n_params, "the table's centroid σ")
    v = judge(q, alternatives, accept=args.accept_poor_fit, what="sun-sensor calibration")
    result["fit"] = v.block()                                  # before writing
    for line in v.lines(): print(line)

``alternatives``: (name, refit) pairs, ``refit()`` → the FitQuality of the same estimator on the
files read that way, or None when it cannot be computed; refits run only for a poor fit.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from rigsim.errors import InputError, PoorFitError
from rigsim.estimation.fit_quality import FitQuality

__all__ = ["ACCEPT_HELP", "REFIT_ERRORS", "Cause", "Verdict", "add_accept_option", "diagnose", "inherited", "judge"]

Alternative = tuple[str, Callable[[], "FitQuality | None"]]

ACCEPT_HELP = ("write the result even when the data do not fit the model (χ²/dof above 25); the output and the "
               "summary then say so. Without it such a fit writes nothing and exits with status 3")

IMPROVEMENT = 4.0  # a cause is named when its refit fits and its χ²/dof is at least this many times smaller
REFIT_ERRORS = (ValueError, ArithmeticError, InputError, FloatingPointError, IndexError)
"""What a refit under an alternative reading may raise: that reading is then no cause."""


@dataclass(frozen=True)
class Cause:
    """An alternative reading of the inputs under which the data fit: its name and its refit's quality."""

    name: str
    quality: FitQuality

    def as_dict(self) -> dict:
        return {"cause": self.name, "chi2_dof": _finite(self.quality.chi2_dof), "verdict": self.quality.verdict}

    def text(self) -> str:
        return f"{self.name} (χ²/dof {self.quality.chi2_dof:.3g})" if self.quality.dof > 0 else self.name


@dataclass(frozen=True)
class Verdict:
    """What a command reports about its fit: the quality, the causes found (poor fits only), whether
    a poor fit was accepted with ``--accept-poor-fit``, and the inputs' own verdicts (``inputs``:
    name → their ``fit`` blocks, for a command that composes judged results)."""

    quality: FitQuality
    what: str
    causes: tuple[Cause, ...] = ()
    accepted: bool = False
    tested: tuple[str, ...] = ()
    inputs: dict = field(default_factory=dict)

    @property
    def covariance_scale(self) -> float:
        return self.quality.covariance_scale

    def block(self) -> dict:
        """The ``fit`` block of the JSON result."""
        out = self.quality.as_dict()
        out["accepted_poor_fit"] = bool(self.accepted)
        if self.quality.poor:
            out["causes_tested"] = list(self.tested)
            out["causes_that_fit"] = [c.as_dict() for c in self.causes]
        if self.inputs:
            out["inputs"] = dict(self.inputs)
        return out

    def lines(self) -> list[str]:
        """The printed summary (one or two lines)."""
        if self.inputs:
            out = ["fit: no fit of its own; its inputs': " + "; ".join(
                f"{k} {_block_text(b)}" for k, b in self.inputs.items())]
        else:
            out = [f"fit: {self.quality.describe()}"]
        if self.quality.poor:
            why = "; ".join(self.quality.problems) + "." if self.inputs else _causes_sentence(self.causes, self.tested)
            out.append(f"POOR FIT ACCEPTED (--accept-poor-fit): this {self.what} is not a measurement. {why}")
        return out


def add_accept_option(parser) -> None:
    """``--accept-poor-fit`` on a command's parser."""
    parser.add_argument("--accept-poor-fit", action="store_true", help=ACCEPT_HELP)


def diagnose(quality: FitQuality, alternatives: Iterable[Alternative]) -> list[Cause]:
    """Refit under each alternative; the ones whose refit is not poor and (when the data as given fail
    by their χ² alone) whose χ²/dof is at least :data:`IMPROVEMENT` times smaller, best first. A refit that fails
    (too few frames left, a non-physical solution) is no cause."""
    found = []
    for name, refit in alternatives:
        try:
            q = refit()
        except REFIT_ERRORS:
            continue
        if q is None or q.poor or (q.dof > 0 and not math.isfinite(q.chi2_dof)):
            continue
        if (not quality.problems and q.dof > 0 and math.isfinite(quality.chi2_dof)
                and not q.chi2_dof * IMPROVEMENT <= quality.chi2_dof):
            continue  # a failed model check is fixed by passing it; a χ² only by a much better one
        found.append(Cause(name, q))
    # equal fits (to 6 digits) are the same explanation read several ways (one reflection is another
    # up to a rotation the fit absorbs): best first, equals in the order they were tested
    return sorted(found, key=lambda c: float(f"{c.quality.chi2_dof:.6g}") if c.quality.dof > 0 else 0.0)


def judge(quality: FitQuality, alternatives: Iterable[Alternative] = (), *, accept: bool, what: str,
          inputs: dict | None = None) -> Verdict:
    """The verdict of a command's fit; a poor fit raises :class:`PoorFitError` (nothing written)
    unless ``accept``. ``what``: the estimate's name in the messages ("sun-sensor calibration")."""
    alternatives = list(alternatives)
    causes: list[Cause] = []
    if quality.poor:
        causes = diagnose(quality, alternatives)
        if not accept:
            raise PoorFitError(f"{what}: the data do not fit the model: {quality.describe()}. "
                               + _causes_sentence(causes, [n for n, _ in alternatives])
                               + " Nothing was written; fix the input, or give --accept-poor-fit to write the result "
                                 "marked as a poor fit")
    return Verdict(quality, what, tuple(causes), bool(accept and quality.poor), tuple(n for n, _ in alternatives),
                   dict(inputs or {}))


def inherited(blocks: dict[str, dict | None], *, accept: bool, what: str) -> Verdict:
    """The verdict of a command that composes judged results (``compose``): no fit of its own; poor
    when an input is marked poor (it was written with --accept-poor-fit), which needs
    ``accept`` again. ``blocks``: input name → its ``fit`` block (None: the file has none)."""
    from rigsim.estimation.fit_quality import not_judged

    poor = [k for k, b in blocks.items() if isinstance(b, dict) and b.get("verdict") == "poor"]
    none = [k for k, b in blocks.items() if not isinstance(b, dict)]
    why = "composes judged results" + (f"; {', '.join(none)} carries no fit verdict" if none else "")
    q = not_judged(why, problems=tuple(f"{k} is a poor fit (written with --accept-poor-fit)" for k in poor))
    if q.poor and not accept:
        raise PoorFitError(f"{what}: {'; '.join(q.problems)}. Nothing was written; give --accept-poor-fit to compose "
                           "it anyway, marked as a poor fit")
    return Verdict(q, what, (), bool(accept and q.poor), (), {k: b for k, b in blocks.items()})


def _causes_sentence(causes, tested) -> str:
    if causes:
        groups: dict[str, list[Cause]] = {}
        for c in causes:
            groups.setdefault(f"{c.quality.chi2_dof:.6g}" if c.quality.dof > 0 else c.name, []).append(c)
        parts = []
        for g in groups.values():
            if len(g) == 1:
                parts.append(g[0].text())
            else:
                parts.append("one of " + ", ".join(c.name for c in g[:-1]) + f" or {g[-1].name} (χ²/dof "
                             f"{g[0].quality.chi2_dof:.3g} each: the same fit, the data cannot tell them apart)")
        return "The data fit when read as: " + "; or ".join(parts) + "."
    if tested:
        return ("None of the causes rigsim can test makes them fit (" + ", ".join(tested)
                + "); check the rig file (--rig) and that the inputs belong together.")
    return "Check the rig file (--rig) and that the inputs belong together."


def _block_text(b) -> str:
    if not isinstance(b, dict):
        return "not judged (no fit block)"
    c = b.get("chi2_dof")
    return f"{b.get('verdict', '?')}" + (f" (χ²/dof {c:.3g})" if isinstance(c, (int, float)) else "")


def _finite(x: float):
    return float(x) if math.isfinite(x) else None
