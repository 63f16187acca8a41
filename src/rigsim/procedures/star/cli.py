"""``rigsim run star-calibration``: seed 004 end to end (docs/star_calibration.md)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rigsim.errors import CliError

__all__ = ["add_cli", "cmd_run_star_calibration"]

RENDERERS = ("analytic", "mitsuba")


def add_cli(groups: dict) -> None:
    """Add the command to the parser groups {"top", "run", "render"} of ``rigsim``."""
    p = groups["run"].add_parser(
        "star-calibration", help="seed 004: star-sensor on-orbit calibration, AD vs ADS EKF, batch LSQ, study",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        description="Render a star-field sequence of the star-sensor rig, extract and identify the stars, "
                    "calibrate (f, u0, v0, k1, k2) by AD / ADS EKFs and batch least squares, compare with the "
                    "truth, run the Monte-Carlo AD-vs-ADS study and write a report.")
    p.add_argument("--rig", default="star_sensor", help="star-sensor rig file (path or default name)")
    p.add_argument("--seed", type=int, default=0, help="seed of the rendered run (same seed, same numbers)")
    p.add_argument("--trials", type=int, default=None, help="Monte-Carlo trials of the study (default: the rig's)")
    p.add_argument("--no-study", action="store_true", help="skip the Monte-Carlo study")
    p.add_argument("--renderer", default="analytic", help="frame renderer: analytic | mitsuba")
    p.add_argument("--mitsuba-spp", type=int, default=256, help="samples per pixel of the Mitsuba windows (power of 4)")
    p.add_argument("--out", default=None, help="report folder (default renders/star_calibration)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_run_star_calibration)


def _check(args) -> None:
    if args.renderer not in RENDERERS:
        raise CliError(f"--renderer = {args.renderer!r}: allowed one of {', '.join(RENDERERS)}")
    if args.trials is not None and not 2 <= args.trials <= 100000:
        raise CliError(f"--trials = {args.trials}: allowed range is 2 to 100000")
    if args.seed < 0:
        raise CliError(f"--seed = {args.seed}: allowed range is ≥ 0")
    spp = args.mitsuba_spp
    if spp < 1 or spp > 65536 or (spp & (spp - 1)) or (spp.bit_length() - 1) % 2:
        raise CliError(f"--mitsuba-spp = {spp}: must be a power of 4 between 1 and 65536 (e.g. 64, 256, 1024)")


def cmd_run_star_calibration(args) -> int:
    import os

    from tqdm import tqdm

    import rigsim
    from rigsim.procedures.star.report import summary_lines, write_report
    from rigsim.procedures.star.run import run_pipeline
    from rigsim.procedures.star.study import CentroidNoise, run_study
    from rigsim.rig.load import load_star_rig
    from rigsim.rig.load import resolve_rig_path as resolve_star_rig_path

    _check(args)
    rig = load_star_rig(args.rig)
    out = Path(args.out) if args.out else Path("renders") / "star_calibration"
    trials = rig.study.trials if args.trials is None else args.trials
    print(f"rigsim {rigsim.__version__} — seed 004 star-sensor calibration, rig '{rig.name}', seed {args.seed}, "
          f"renderer {args.renderer}")
    t0 = time.perf_counter()
    mitsuba = None
    if args.renderer == "mitsuba":
        from rigsim.render.star import MitsubaStarRenderer

        mitsuba = MitsubaStarRenderer(rig.sensor, spp=args.mitsuba_spp)
    with tqdm(total=rig.sequence.n_frames, desc="frames", unit="frame", disable=True if args.quiet else None,
              file=sys.stderr, dynamic_ncols=True) as bar:
        res = run_pipeline(rig, seed=args.seed, renderer=args.renderer, mitsuba=mitsuba, progress=bar)
    study = None
    if not args.no_study:
        from rigsim.truth.star import StarSky

        sky = StarSky(rig)
        noise = CentroidNoise.from_rig(rig, scale=res.noise_scale, background_photons_per_px=sky.background_photons_per_px)
        t1 = time.perf_counter()
        with tqdm(total=trials, desc="AD vs ADS study", unit="trial", disable=True if args.quiet else None,
                  file=sys.stderr, dynamic_ncols=True) as bar:
            study = run_study(rig, sky, trials=trials, noise=noise, progress=bar)
        res.times["study"] = time.perf_counter() - t1
    res.times["wall"] = time.perf_counter() - t0
    print()
    for line in summary_lines(res, study):
        print(line)
    try:
        rig_path = os.path.relpath(resolve_star_rig_path(args.rig))
    except Exception:
        rig_path = args.rig
    cmd = "rigsim " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("rigsim") else None
    files = write_report(out, res, study, command=cmd, rig_path=rig_path)
    print(f"\nwall time {res.times['wall']:.1f} s; report: {files['report']} (plots: "
          + ", ".join(p.name for k, p in files.items() if k not in ("report", "json")) + ")")
    return 0
