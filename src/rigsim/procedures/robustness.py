"""Robustness of a pipeline to a rig's ``[effects]``: the same trials (same seeds) run on ideal
frames, with each effect alone and with all of them; every recovered quantity is compared with
the truth, and the paired difference to the ideal run isolates what the effect adds.

Family-neutral: a family supplies its quantities and a trial function (``procedures/<family>/
robustness.py``); this module summarises, judges, plots and writes the report. The verdict rule
is in docs/effects.md.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "ADDED_LIMIT",
    "ALL",
    "IDEAL",
    "MUST_LIMIT",
    "BoundTrial",
    "Quantity",
    "RobustnessResult",
    "configs_for",
    "rig_with",
    "run_configs",
    "run_family",
    "summarise",
    "verdicts",
    "write_robustness_files",
]

IDEAL, ALL = "ideal", "all effects"
ADDED_LIMIT = 0.5
"""An effect is marginal when the error it adds (RMS of the paired difference to the ideal run)
exceeds this fraction of the reference (the quantity's budget, else the ideal run's RMS error):
in quadrature the RMS grows by more than 12 %."""
MUST_LIMIT = 1.0
"""…and must be handled beyond this fraction: the RMS grows by more than 41 %."""
COUNT_LOSS_MARGINAL, COUNT_LOSS_LIMIT = 0.01, 0.05
"""Shares of a count of the ideal run (identified stars or frames, sweep frames, converged runs) whose
loss is marginal / must be handled."""


@dataclass(frozen=True)
class Quantity:
    key: str
    label: str
    unit: str
    kind: str = "error"            # "error": recovered − truth; "count": a tally (more is better unless ``lower_is_better``)
    budget: float | None = None    # the allowed RMS error, in ``unit`` (None: the ideal run is the reference)
    lower_is_better: bool = False  # for counts (e.g. wrong identifications)


@dataclass
class RobustnessResult:
    family: str
    rig_name: str
    seed: int
    trials: int
    quantities: tuple[Quantity, ...]
    configs: tuple[str, ...]                          # IDEAL first, then each effect, then ALL
    values: dict[str, dict[str, np.ndarray]]          # config -> quantity key -> (trials,)
    render_ms_per_frame: dict[str, float]             # config -> mean render time of a frame
    effects: dict = field(default_factory=dict)       # the parameters of every effect (as in the rig file)
    times: dict = field(default_factory=dict)
    pipeline: str = ""                                # the pipeline variant these values come from


def configs_for(names) -> tuple[str, ...]:
    """IDEAL, each named effect alone, and ALL when there is more than one."""
    names = tuple(names)
    return (IDEAL, *names, *((ALL,) if len(names) > 1 else ()))


def rig_with(rig, config: str, names):
    """``rig`` with the effects of ``config`` switched on and every other effect off: none for IDEAL,
    all of ``names`` for ALL, else the one named."""
    on = () if config == IDEAL else (tuple(names) if config == ALL else (config,))
    return rig.model_copy(update={"effects": rig.effects.only(on)})


class BoundTrial:
    """A picklable ``trial(config, seed)`` for :func:`run_configs`: the module-level function
    ``fn(rig, names, config, seed)`` with the rig and the effect names bound."""

    def __init__(self, fn, rig, names):
        self.fn, self.rig, self.names = fn, rig, tuple(names)

    def __call__(self, config, seed):
        return self.fn(self.rig, self.names, config, seed)


def run_configs(trial, configs, seeds, *, workers: int = 1, progress=None, store=None) -> dict:
    """``trial(config, seed) -> dict`` for every config and seed (same seeds for every config), in
    ``workers`` processes (:mod:`rigsim.render.workers`; results do not depend on the worker count). With a
    :class:`~rigsim.procedures.trial_store.TrialStore`, the trials it holds are taken from it and
    every new one is written to it as soon as it finishes."""
    out: dict = {}
    jobs = []
    for c in configs:
        for s in seeds:
            kept = store.get(c, s) if store is not None else None
            if kept is None:
                jobs.append((c, s))
            else:
                out[(c, s)] = kept
    if progress is not None and len(out):
        progress.update(len(out))

    def done(c, s, values):
        out[(c, s)] = values
        if store is not None:
            store.put(c, s, values)
        if progress is not None:
            progress.update(1)

    if workers <= 1 or len(jobs) <= 1:
        for c, s in jobs:
            done(c, s, trial(c, s))
        return out
    from concurrent.futures import as_completed

    from rigsim.render.workers import process_pool

    # workers die with this process (a killed run must not leave them behind)
    with process_pool(workers, "rigsim.dataset.runner:_die_with_parent", (os.getpid(),)) as ex:
        futs = {ex.submit(trial, c, s): (c, s) for c, s in jobs}
        for f in as_completed(futs):
            done(*futs[f], f.result())
    return out


def run_family(family: str, trial_fn, rig, names, seeds, qs, variants, *, workers: int = 1, progress=None,
               store=None) -> list[RobustnessResult]:
    """A family's robustness run: ``trial_fn(rig, names, config, seed)`` (module level, picklable;
    it returns {variant: {quantity key: value}} and ``_render_ms_per_frame``) for every configuration
    of :func:`configs_for` and every seed, through :func:`run_configs`; one
    :class:`RobustnessResult` per pipeline variant, in the order of ``variants``."""
    names, seeds = tuple(names), [int(s) for s in seeds]
    configs = configs_for(names)
    t0 = time.perf_counter()
    raw = run_configs(BoundTrial(trial_fn, rig, names), configs, seeds, workers=workers, progress=progress, store=store)
    wall = time.perf_counter() - t0
    render = {c: float(np.mean([raw[(c, s)]["_render_ms_per_frame"] for s in seeds])) for c in configs}
    effects = {n: getattr(rig.effects, n).model_dump(exclude={"enabled"}) for n in names}
    out = []
    for v in variants:
        values = {c: {q.key: np.array([raw[(c, s)][v][q.key] for s in seeds], dtype=float) for q in qs}
                  for c in configs}
        out.append(RobustnessResult(family, rig.name, seeds[0], len(seeds), tuple(qs), configs, values, render,
                                    effects, {"wall": wall}, pipeline=v))
    return out


def _rms(x) -> float:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if x.size else math.nan


def summarise(res: RobustnessResult) -> list[dict]:
    """One row per (config, quantity): bias, σ and RMS over the trials; for errors the error the
    config adds to the ideal run (RMS of the paired difference) and its ratio to the reference."""
    rows = []
    ideal = res.values[IDEAL]
    for c in res.configs:
        for q in res.quantities:
            x = np.asarray(res.values[c][q.key], dtype=float)
            row = {"config": c, "quantity": q.key, "label": q.label, "unit": q.unit, "kind": q.kind,
                   "mean": float(np.nanmean(x)), "sigma": float(np.nanstd(x, ddof=1)) if x.size > 1 else math.nan}
            if q.kind == "error":
                ref = q.budget if q.budget is not None else _rms(ideal[q.key])
                added = _rms(x - np.asarray(ideal[q.key], dtype=float))
                row.update(rms=_rms(x), added_rms=added, reference=ref,
                           added_over_reference=added / ref if ref > 0 else math.inf)
            else:
                row.update(change=float(np.nanmean(x) - np.nanmean(np.asarray(ideal[q.key], dtype=float))))
            rows.append(row)
    return rows


def _level(ratio: float) -> str | None:
    return "must" if ratio > MUST_LIMIT else ("marginal" if ratio > ADDED_LIMIT else None)


def verdicts(res: RobustnessResult, rows: list[dict] | None = None) -> dict[str, dict]:
    """Per config: ``level`` ("none", "marginal" or "must"), ``must_handle`` and the reasons.
    An error quantity is marginal when the error the effect adds exceeds ``ADDED_LIMIT`` × its
    reference and must be handled beyond ``MUST_LIMIT`` ×; a count of stars or frames likewise when
    it loses more than ``COUNT_LOSS_MARGINAL`` / ``COUNT_LOSS_LIMIT`` of the ideal run's; wrong
    identifications must be handled when they rise by more than 0.5 per trial."""
    rows = summarise(res) if rows is None else rows
    qs = {q.key: q for q in res.quantities}
    ideal = {r["quantity"]: r for r in rows if r["config"] == IDEAL}
    out = {}
    for c in res.configs:
        if c == IDEAL:
            continue
        found = []
        for r in (r for r in rows if r["config"] == c):
            q = qs[r["quantity"]]
            if q.kind == "error":
                lvl = _level(r["added_over_reference"])
                if lvl:
                    ref = "budget" if q.budget else "ideal error"
                    text = f"{q.label}: adds {r['added_rms']:.3g} {q.unit} rms ({r['added_over_reference']:.2f}× the {ref})"
                    found.append((lvl, text))
            elif q.lower_is_better:
                if r["change"] > 0.5:
                    found.append(("must", f"{q.label}: {r['change']:+.3g} per trial"))
            else:
                base = ideal[q.key]["mean"]
                loss = -r["change"] / base if base > 0 else 0.0
                lvl = "must" if loss > COUNT_LOSS_LIMIT else ("marginal" if loss > COUNT_LOSS_MARGINAL else None)
                if lvl:
                    found.append((lvl, f"{q.label}: {r['change']:+.3g} per trial ({-100 * loss:+.1f} %)"))
        level = "must" if any(lv == "must" for lv, _ in found) else ("marginal" if found else "none")
        order = sorted(found, key=lambda f: f[0] != "must")
        out[c] = {"level": level, "must_handle": level == "must", "reasons": [f"[{lv}] {t}" for lv, t in order]}
    return out


def _plot(results: list[RobustnessResult], rows: list[list[dict]], path: Path) -> Path:
    """One panel per recovered quantity: the error each effect adds (paired RMS) over the reference,
    a bar per pipeline variant, with the marginal and must-handle lines; a last panel with the
    identified stars lost."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rigsim.files.atomic import save_figure

    res0 = results[0]
    errs = [q for q in res0.quantities if q.kind == "error"]
    counts = [q for q in res0.quantities if q.kind == "count" and not q.lower_is_better][:1]
    panels = errs + counts
    cols = min(3, len(panels))
    nrows = math.ceil(len(panels) / cols)
    fig, axs = plt.subplots(nrows, cols, figsize=(5.0 * cols, 3.3 * nrows + 0.9), squeeze=False)
    configs = [c for c in res0.configs if c != IDEAL]
    x = np.arange(len(configs))
    w = 0.8 / len(results)
    handles = []
    for ax, q in zip(axs.flat, panels):
        for j, (res, rr) in enumerate(zip(results, rows)):
            rs = {r["config"]: r for r in rr if r["quantity"] == q.key}
            if q.kind == "error":
                y = [rs[c]["added_over_reference"] for c in configs]
            else:
                y = [100.0 * -rs[c]["change"] / rs[IDEAL]["mean"] for c in configs]
            h = ax.bar(x + (j - (len(results) - 1) / 2) * w, y, w * 0.95, color=f"C{j}",
                       label=res.pipeline or "pipeline")
            if len(handles) < len(results):
                handles.append(h)
        if q.kind == "error":
            ax.axhline(ADDED_LIMIT, color="C1", lw=1, ls="--")
            ax.axhline(MUST_LIMIT, color="C3", lw=1, ls="--")
            ax.set_ylabel("added error / reference")
            ax.set_title(f"{q.label} ({q.unit})" + ("" if q.budget else ": over the ideal rms"), fontsize=9)
        else:
            ax.axhline(100 * COUNT_LOSS_MARGINAL, color="C1", lw=1, ls="--")
            ax.axhline(100 * COUNT_LOSS_LIMIT, color="C3", lw=1, ls="--")
            ax.set_ylabel("lost (% of the ideal run's)")
            ax.set_title(q.label, fontsize=9)
        ax.set_xticks(x, configs, rotation=20, ha="right", fontsize=8)
        ax.set_ylim(bottom=min(0.0, ax.get_ylim()[0]))
    for ax in list(axs.flat)[len(panels):]:
        ax.axis("off")
    fig.suptitle(f"{res0.rig_name}: what each effect adds, {res0.trials} paired trials per configuration "
                 "(dashed: marginal, must be handled)", fontsize=10)
    fig.legend(handles=handles, loc="lower center", ncol=min(2, len(handles)), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.03 + 0.03 * math.ceil(len(handles) / 2), 1, 0.97))
    out = save_figure(fig, path, dpi=110)
    plt.close(fig)
    return out


def _table(res: RobustnessResult, rows: list[dict]) -> str:
    from rigsim.reporting import text_table

    tab = []
    for r in rows:
        if r["kind"] == "error":
            tab.append([r["config"], r["label"], r["unit"], f"{r['mean']:+.4g}", f"{r['sigma']:.4g}", f"{r['rms']:.4g}",
                        "" if r["config"] == IDEAL else f"{r['added_rms']:.3g}", f"{r['reference']:.3g}"])
        else:
            tab.append([r["config"], r["label"], r["unit"], f"{r['mean']:.4g}", f"{r['sigma']:.3g}", "",
                        "" if r["config"] == IDEAL else f"{r['change']:+.3g}", ""])
    return text_table(["config", "quantity", "unit", "bias/mean", "σ", "rms", "added", "reference"], tab)


def _markdown(results: list[RobustnessResult], rows: list[list[dict]], verdict: list[dict], frames_png) -> str:
    import json

    from rigsim.reporting import text_table

    res = results[0]
    lines = [f"# Robustness of the {res.family} pipeline to the rig's effects — {res.rig_name}", "",
             f"{res.trials} trials per configuration (seeds {res.seed} … {res.seed + res.trials - 1}, the same for "
             "every configuration), each a full rendered run compared with its truth"
             + (f"; every configuration goes through {len(results)} pipeline variants" if len(results) > 1 else "")
             + ". *added* is the RMS of the paired difference to the ideal run: the error the effect itself adds. "
             f"An effect is *marginal* when it adds more than {ADDED_LIMIT:g}× the reference (the budget, or the "
             f"ideal run's RMS error: the RMS grows by 12 %) or loses more than {100 * COUNT_LOSS_MARGINAL:g} % of the "
             f"count (identified stars or frames, sweep frames, converged runs); it *must be handled* beyond "
             f"{MUST_LIMIT:g}× (the RMS grows by 41 %), beyond {100 * COUNT_LOSS_LIMIT:g} % lost"
             + (", or with more than 0.5 more wrong counts (wrong identifications) per run"
                if any(q.lower_is_better for q in res.quantities) else "") + ".", ""]
    if frames_png:
        lines += [f"![a frame, ideal and with every effect]({frames_png})", ""]
    lines += ["## Verdict", ""]
    for r, v in zip(results, verdict):
        if len(results) > 1:
            lines += [f"### pipeline: {r.pipeline}", ""]
        for c, d in v.items():
            lines.append(f"* **{c}** — " + {"must": "must be handled: ", "marginal": "marginal: ",
                                             "none": "no action needed at these values"}[d["level"]]
                         + "; ".join(d["reasons"]))
        lines.append("")
    lines += ["## Recovered quantities", "", "![what each effect adds, per pipeline](robustness.png)", ""]
    for r, rr in zip(results, rows):
        if len(results) > 1:
            lines += [f"### pipeline: {r.pipeline}", ""]
        lines += ["```", _table(r, rr), "```", ""]
    ms = res.render_ms_per_frame
    lines += ["## Render cost", "", "```",
              text_table(["config", "ms per frame", "× ideal"],
                         [[c, f"{ms[c]:.1f}", f"{ms[c] / ms[IDEAL]:.2f}"] for c in res.configs]),
              "```", "", "## Effect parameters", "", "```json", json.dumps(res.effects, indent=1), "```", ""]
    return "\n".join(lines)


def _column(q: Quantity, stat: str) -> str:
    """CSV column of a statistic of ``q``: ``<name>_<stat>_<unit>`` (the unit last, as every rigsim
    table), or ``<key>_<stat>`` for a count."""
    suffix = "_" + q.unit
    if q.kind == "count" or not q.key.endswith(suffix):
        return f"{q.key}_{stat}"
    return f"{q.key[: -len(suffix)]}_{stat}{suffix}"


def write_robustness_files(out: Path, results, *, frames_png: Path | None = None) -> dict[str, Path]:
    """robustness.json (every trial, the summary, the verdict), robustness.csv (the summary, units in
    the column names), robustness.png and robustness.md in ``out``. ``results``: one
    :class:`RobustnessResult` per pipeline variant (same configurations and seeds)."""
    from rigsim.files import write_json, write_table
    from rigsim.files.atomic import atomic_write_text

    results = [results] if isinstance(results, RobustnessResult) else list(results)
    rows = [summarise(r) for r in results]
    verdict = [verdicts(r, rr) for r, rr in zip(results, rows)]
    files = {"png": _plot(results, rows, out / "robustness.png")}
    table: dict[str, list] = {"pipeline": [], "config": []}
    for res, rr in zip(results, rows):
        table["pipeline"] += [res.pipeline] * len(res.configs)
        table["config"] += list(res.configs)
        for q in res.quantities:  # one column per quantity and statistic, the unit last
            rs = {r["config"]: r for r in rr if r["quantity"] == q.key}
            stats = ("mean", "sigma", "rms", "added_rms") if q.kind == "error" else ("mean", "sigma")
            for st in stats:
                table.setdefault(_column(q, st), []).extend(rs[c][st] for c in res.configs)
        table.setdefault("render_per_frame_ms", []).extend(res.render_ms_per_frame[c] for c in res.configs)
    files["csv"] = write_table(out / "robustness.csv", table)
    res0 = results[0]
    files["json"] = write_json(out / "robustness.json", {
        "format": "rigsim.robustness/1", "procedure": f"robustness ({res0.family})", "mode": "rendered",
        "family": res0.family, "rig": res0.rig_name, "seed": res0.seed, "trials": res0.trials,
        "configs": list(res0.configs), "added_limit": ADDED_LIMIT, "effects": res0.effects,
        "quantities": [q.__dict__ for q in res0.quantities], "render_ms_per_frame": res0.render_ms_per_frame,
        "times_s": res0.times,
        "pipelines": [{"pipeline": r.pipeline, "summary": rr, "verdict": v,
                       "trials_values": {c: {k: np.asarray(x).tolist() for k, x in r.values[c].items()}
                                         for c in r.configs}}
                      for r, rr, v in zip(results, rows, verdict)]})
    files["report"] = atomic_write_text(out / "robustness.md",
                                        _markdown(results, rows, verdict, frames_png.name if frames_png else None))
    if frames_png is not None:
        files["frames"] = frames_png
    return files
