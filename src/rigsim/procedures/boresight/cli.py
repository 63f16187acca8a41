"""``rigsim run boresight``: seed 003's analyses and the rendered orbit scenario, with a report.

Registered by rigsim.cli through ``add_cli(run_subparsers, top=...)``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rigsim.errors import CliError

__all__ = ["add_cli", "cmd_run_boresight"]


def add_cli(groups: dict) -> None:
    """Add the command to the parser groups {"top", "run", "render"} of ``rigsim``."""
    p = groups["run"].add_parser(
        "boresight", help="seed 003: dual line-array camera + central prism (DVAD vs simplified, orbit scenario)",
        description="Reproduce seed 003's analyses (Figs 4-8, rotation order) on the exact model, render the "
                    "thermal-vacuum orbit scenario (CMOS ROIs through Mitsuba + detector model), recover the relative "
                    "angle between the cameras, check the paper's claims and write a Markdown + PNG report.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--rig", default="dual_line_array_prism", help="seed-003 rig file path or default rig name")
    p.add_argument("--out", default="renders/boresight", metavar="DIR", help="report directory")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: the rig's study.seed)")
    p.add_argument("--runs", type=int, default=None, help="Monte-Carlo runs per point (default: the rig's, 1200)")
    p.add_argument("--reading", default="consistent", choices=["consistent", "as_printed"],
                   help="reading of the paper's equations used as 'the' method (both are always compared)")
    p.add_argument("--no-orbit", action="store_true", help="skip the rendered orbit scenario")
    p.add_argument("--measurements", type=int, default=None, help="orbit measurements (default: the rig's, 19)")
    p.add_argument("--spp", type=int, default=None, help="light paths per ROI pixel (default: the rig's)")
    p.add_argument("--jitter-px", type=float, default=0.1,
                   help="also evaluate the orbit frames with this equivalent centroid error added (0: off)")
    p.add_argument("--json-out", default=None, metavar="FILE", help="also write the key numbers as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_run_boresight)
    return p


def cmd_run_boresight(args) -> int:
    import json

    from tqdm import tqdm

    import rigsim
    from rigsim.procedures.boresight.report import key_numbers, write_report
    from rigsim.procedures.boresight.studies import run_study
    from rigsim.rig.load import load_boresight_rig, resolve_rig_path

    rig = load_boresight_rig(args.rig)
    if args.runs is not None and not 10 <= args.runs <= 1_000_000:
        raise CliError(f"--runs = {args.runs}: allowed range is 10 to 1000000")
    if args.measurements is not None and not 3 <= args.measurements <= 1000:
        raise CliError(f"--measurements = {args.measurements}: allowed range is 3 to 1000")
    if args.spp is not None and not 16 <= args.spp <= 65536:
        raise CliError(f"--spp = {args.spp}: allowed range is 16 to 65536")
    if not 0.0 <= args.jitter_px <= 5.0:
        raise CliError(f"--jitter-px = {args.jitter_px}: allowed range is 0 to 5 px")
    if args.seed is not None and args.seed < 0:
        raise CliError(f"--seed = {args.seed}: must be >= 0")
    if not args.no_orbit and len(rig.cameras) < 2:
        raise CliError(f"the orbit scenario needs two cameras; {args.rig} has {len(rig.cameras)} (use --no-orbit)")
    rig_path = resolve_rig_path(args.rig)
    n_meas = args.measurements or rig.orbit.measurements
    total = 5 + (0 if args.no_orbit else 4 * (rig.orbit.reference_frames + n_meas))
    print(f"rigsim {rigsim.__version__} — seed 003 boresight study, rig '{rig.name}' ({rig_path.name}), "
          f"reading '{args.reading}'")
    t0 = time.perf_counter()
    with tqdm(total=total, desc="boresight", unit="step", disable=True if args.quiet else None, file=sys.stderr,
              dynamic_ncols=True) as bar:
        def progress(n, stage):
            bar.set_postfix_str(stage)
            bar.update(n)

        orbit_kw = {"spp": args.spp, "measurements": args.measurements, "jitter_px": args.jitter_px}
        res = run_study(rig, seed=args.seed, runs=args.runs, reading=args.reading, orbit=not args.no_orbit,
                        progress=progress, orbit_kw=orbit_kw)
    cmd = "rigsim run boresight" + "".join(f" {a}" for a in sys.argv[3:]) if sys.argv[1:3] == ["run", "boresight"] else ""
    rel = rig_path.relative_to(Path.cwd()) if rig_path.is_relative_to(Path.cwd()) else rig_path
    report = write_report(res, args.out, rig_path=str(rel), command=cmd)
    f5 = res["fig5"]
    print(f"\nFig 5: {f5['runs']} runs at σ = {f5['sigma_px']} px (3σ; eqs 19–22 in brackets)")
    for p, u in (("delta_f_um", "µm"), ("alpha_arcsec", "″"), ("beta_arcsec", "″"), ("gamma_arcsec", "″")):
        print(f"  {p.split('_')[0]:6s} DVAD {f5['stats']['dvad'][p]['three_sigma']:8.4f}{u}   simplified "
              f"{f5['stats']['simplified'][p]['three_sigma']:8.4f}{u} (mean {f5['stats']['simplified'][p]['mean']:+.4f})   "
              f"[{f5['pred3'][p]:.4f}]")
    if "orbit" in res:
        o = res["orbit"]
        rms = o["estimates"]["dvad"]["relative_rms_arcsec"]
        print(f"\nOrbit scenario: {o['frames_rendered']} rendered ROIs, relative angle RMS error (DVAD) "
              f"x {rms[0]:.4f}″  y {rms[1]:.4f}″  z {rms[2]:.4f}″; Δf RMS "
              f"{o['estimates']['dvad']['delta_f_rms_um'][0]:.3f} / {o['estimates']['dvad']['delta_f_rms_um'][1]:.3f} µm; "
              f"render vs exact ≤ {o['render_fidelity_max_px']:.4f} px")
        if "estimates_jitter" in o:
            j = o["estimates_jitter"]["dvad"]["relative_rms_arcsec"]
            print(f"  with {o['jitter_px']:g} px equivalent centroid error: x {j[0]:.3f}″  y {j[1]:.3f}″  z {j[2]:.3f}″")
    print("\nClaims:")
    for c in res["claims"]:
        print(f"  [{c['verdict']:>13s}] {c['claim']}\n                  {c['measured']}")
    print(f"\nreport: {report}  ({time.perf_counter() - t0:.0f} s)")
    if args.json_out:
        Path(args.json_out).write_text(json.dumps(key_numbers(res), indent=1, default=float))
        print(f"wrote {args.json_out}")
    return 0
