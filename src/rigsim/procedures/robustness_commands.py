"""``rigsim run robustness RIG``: what each of the rig's ``[effects]`` does to every recovered quantity."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rigsim.errors import CliError
from rigsim.files.options import SEED, integer

__all__ = ["add_cli", "cmd_run_robustness"]

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
                    "to keep its accuracy. Writes robustness.md, .json, .csv, .png and frames.png. Effects are "
                    "modelled so far for the star-sensor family.")
    p.add_argument("rig", nargs="?", default="star_sensor", help="rig file (path or default name)")
    p.add_argument("--trials", type=integer(2, 10_000), default=8, help="runs per configuration (default 8)")
    p.add_argument("--seed", type=SEED, default=0, help="seed of the first run (runs use seed … seed+trials−1)")
    p.add_argument("--effects", default=None, metavar="A,B",
                   help="effects to study (default: every effect of the family)")
    p.add_argument("--workers", type=integer(1, 64), default=None, help="processes (default: up to 2)")
    p.add_argument("--out", default=None, metavar="DIR", help="report folder (default renders/robustness/<rig name>)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_run_robustness)


def cmd_run_robustness(args) -> int:
    from tqdm import tqdm

    from rigsim.files.atomic import output_folder
    from rigsim.procedures.robustness import verdicts
    from rigsim.rig.effects import STAR_EFFECTS
    from rigsim.rig.load import load_any_rig
    from rigsim.rig.star import StarRig

    rig = load_any_rig(args.rig)
    if not isinstance(rig, StarRig):
        raise CliError(f"robustness: rig {args.rig!r} is a {type(rig).__name__}; effects are modelled so far for "
                       "star-sensor rigs only (seed 004)")
    names = STAR_EFFECTS
    if args.effects is not None:
        names = tuple(n.strip() for n in args.effects.split(",") if n.strip())
        bad = [n for n in names if n not in STAR_EFFECTS]
        if bad or not names or len(set(names)) != len(names):
            raise CliError(f"--effects = {args.effects!r}: give distinct names from {', '.join(STAR_EFFECTS)}")
    from rigsim.procedures.robustness import write_robustness_files
    from rigsim.procedures.star.robustness import configs_for, frames_figure, run_star_robustness
    from rigsim.render.threads import cores

    out = output_folder(Path(args.out) if args.out else Path("renders") / "robustness" / rig.name)
    workers = args.workers if args.workers is not None else min(2, cores())
    configs = configs_for(names)
    print(f"robustness of the star pipeline, rig '{rig.name}': {', '.join(configs)}; {args.trials} trials each, "
          f"{workers} process{'es' if workers > 1 else ''}")
    t0 = time.perf_counter()
    with tqdm(total=len(configs) * args.trials, desc="runs", unit="run", disable=True if args.quiet else None,
              file=sys.stderr, dynamic_ncols=True) as bar:
        res = run_star_robustness(rig, trials=args.trials, seed=args.seed, names=names, workers=workers, progress=bar)
    frames = frames_figure(rig, out / "frames.png", seed=args.seed, names=names)
    files = write_robustness_files(out, res, frames_png=frames)
    for r in res:
        print(f"pipeline {r.pipeline}:")
        for c, v in verdicts(r).items():
            head = {"must": "MUST BE HANDLED — ", "marginal": "marginal — ", "none": "no action needed at these values"}
            print(f"  {c}: " + head[v["level"]] + "; ".join(v["reasons"][:3])
                  + (f" (+{len(v['reasons']) - 3} more)" if len(v["reasons"]) > 3 else ""))
    print(f"wall time {time.perf_counter() - t0:.1f} s; report: {files['report']}")
    return 0
