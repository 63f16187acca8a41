"""``rigsim run robustness RIG``: what each of the rig's ``[effects]`` does to every recovered quantity."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rigsim.errors import CliError
from rigsim.files.options import SEED, integer

__all__ = ["FAMILY_MODULES", "add_cli", "cmd_run_robustness", "family_module"]

EPILOG = """examples:
  rigsim run robustness star_sensor                       every effect alone and all together, 8 trials each
  rigsim run robustness star_sensor --effects hot_pixels --trials 20
  rigsim run robustness my_star_rig.toml --out robustness/ --workers 1
"""


def add_cli(groups: dict) -> None:
    p = groups["run"].add_parser(
        "robustness", help="bias and σ of every recovered quantity with each of the rig's [effects], against ideal frames",
        formatter_class=argparse.RawDescriptionHelpFormatter, epilog=EPILOG,
        description="Run the rig's whole pipeline on rendered frames, ideal and with each effect of the rig file's "
                    "[effects] table switched on alone and all together (the same seeds for every configuration), "
                    "compare every recovered quantity with the truth and say which effects the pipeline must handle "
                    "to keep its accuracy. Writes robustness.md, .json, .csv, .png and frames.png. Each finished run "
                    "is kept in robustness-trials/ of the report folder until the report is written: the same "
                    "command after a kill resumes from them.")
    p.add_argument("rig", nargs="?", default="star_sensor", help="rig file (path or default name)")
    p.add_argument("--trials", type=integer(2, 10_000), default=None,
                   help="runs per configuration (default: 8 for star sensors, 4 for the slower rigs)")
    p.add_argument("--seed", type=SEED, default=0, help="seed of the first run (runs use seed … seed+trials−1)")
    p.add_argument("--effects", default=None, metavar="A,B",
                   help="effects to study (default: every effect of the family)")
    p.add_argument("--workers", type=integer(1, 64), default=None, help="processes (default: up to 2)")
    p.add_argument("--out", default=None, metavar="DIR", help="report folder (default renders/robustness/<rig name>)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_run_robustness)
    from rigsim.files.outputs import declare

    declare(p, "out", folder=True)


FAMILY_MODULES = {
    "StarRig": "rigsim.procedures.star.robustness",
    "CubeMirrorRig": "rigsim.procedures.cube_mirror.robustness",
    "BoresightRig": "rigsim.procedures.boresight.robustness",
}
"""Rig class → the module of its family's robustness trials. Each module gives ``DESCRIPTION``,
``DEFAULT_TRIALS``, ``effect_names(rig)``, ``run_robustness(rig, *, trials, seed, names, workers,
progress)`` (a list of :class:`~rigsim.procedures.robustness.RobustnessResult`, the configured
pipeline first) and ``frames_figure(rig, path, *, seed, names)``."""


def family_module(rig):
    """The robustness module of ``rig``'s family (CliError when it has none or no effects yet)."""
    import importlib

    name = FAMILY_MODULES.get(type(rig).__name__)
    if name is None:
        raise CliError(f"robustness: no effects are modelled for {type(rig).__name__} rigs")
    mod = importlib.import_module(name)
    if not mod.effect_names(rig):
        raise CliError(f"robustness: rig {rig.name!r} has no effects modelled yet for its family")
    return mod


def cmd_run_robustness(args) -> int:
    from tqdm import tqdm

    from rigsim.dataset.ownership import dataset_lock
    from rigsim.files.atomic import output_folder
    from rigsim.procedures.robustness import configs_for, verdicts, write_robustness_files
    from rigsim.procedures.trial_store import FOLDER, TrialStore, run_key
    from rigsim.render.threads import cores
    from rigsim.rig.load import load_any_rig

    rig = load_any_rig(args.rig)
    fam = family_module(rig)
    known = fam.effect_names(rig)
    names = known
    if args.effects is not None:
        names = tuple(n.strip() for n in args.effects.split(",") if n.strip())
        bad = [n for n in names if n not in known]
        if bad or not names or len(set(names)) != len(names):
            raise CliError(f"--effects = {args.effects!r}: give distinct names from {', '.join(known)}")
    trials = args.trials if args.trials is not None else fam.DEFAULT_TRIALS
    out = output_folder(Path(args.out) if args.out else Path("renders") / "robustness" / rig.name)
    workers = args.workers if args.workers is not None else min(2, cores())
    configs = configs_for(names)
    print(f"robustness of {fam.DESCRIPTION}, rig '{rig.name}': {', '.join(configs)}; {trials} trials each, "
          f"{workers} process{'es' if workers > 1 else ''}")
    t0 = time.perf_counter()
    store = TrialStore(out / FOLDER, run_key(rig, names, fam.run_robustness))
    store.create()
    with dataset_lock(store.folder, "rigsim run robustness", lock_file="run.lock", owner_file="run.lock.owner.json"):
        seeds = range(args.seed, args.seed + trials)
        kept = store.count(configs, seeds)
        if kept:
            print(f"resuming: {kept} of {len(configs) * trials} runs kept by an interrupted run in {store.folder}")
        # the frames first: a figure that cannot be drawn fails in seconds, not after hours of trials, and
        # every module the report needs is loaded before the trials start
        frames = fam.frames_figure(rig, out / "frames.png", seed=args.seed, names=names)
        with tqdm(total=len(configs) * trials, desc="runs", unit="run", disable=True if args.quiet else None,
                  file=sys.stderr, dynamic_ncols=True) as bar:
            try:
                res = fam.run_robustness(rig, trials=trials, seed=args.seed, names=names, workers=workers,
                                         progress=bar, store=store)
            except BaseException:
                n = store.count(configs, seeds)
                if n:
                    print(f"rigsim: {n} finished runs are kept in {store.folder}; the same command resumes from them",
                          file=sys.stderr)
                raise
        files = write_robustness_files(out, res, frames_png=frames)
        store.clear()
    for r in res:
        print(f"pipeline {r.pipeline}:")
        for c, v in verdicts(r).items():
            head = {"must": "MUST BE HANDLED — ", "marginal": "marginal — ", "none": "no action needed at these values"}
            print(f"  {c}: " + head[v["level"]] + "; ".join(v["reasons"][:3])
                  + (f" (+{len(v['reasons']) - 3} more)" if len(v["reasons"]) > 3 else ""))
    print(f"wall time {time.perf_counter() - t0:.1f} s; report: {files['report']}")
    return 0
