"""``rigsim run boresight``: seed 003's analyses and the rendered orbit scenario, with a report.

Registered by rigsim.cli through ``add_cli(run_subparsers, top=...)``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from rigsim.errors import CliError
from rigsim.files.options import SEED, SPP, integer, number
from rigsim.files.outputs import declare

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
    p.add_argument("--seed", type=SEED, default=None, help="random seed (default: the rig's study.seed)")
    p.add_argument("--runs", type=integer(10, 1_000_000), default=None, help="Monte-Carlo runs per point (default: the rig's, 1200)")
    p.add_argument("--reading", default="consistent", choices=["consistent", "as_printed"],
                   help="reading of the paper's equations used as 'the' method (both are always compared)")
    p.add_argument("--loop-model", default="physical", choices=["physical", "paper"],
                   help="loop of the Monte-Carlo and noise-free analyses: rigsim's exact ray trace, or the linear loop "
                        "eqs 1-4 invert exactly (the rendered orbit is always physical; both are compared in the report)")
    p.add_argument("--eq20-cos2beta", default="reevaluated", choices=["reevaluated", "fixed"],
                   help="eq 20's focal-length threshold for 0.1″ quoted first: cos²β re-evaluated with F, or "
                        "fixed at the rig's F (both are reported)")
    p.add_argument("--no-orbit", action="store_true", help="skip the rendered orbit scenario")
    p.add_argument("--measurements", type=integer(3, 100_000), default=None, help="orbit measurements (default: the rig's, 19)")
    p.add_argument("--spp", type=SPP, default=None, help="light paths per ROI pixel (default: the rig's)")
    p.add_argument("--jitter-px", type=number(0, 5), default=0.1,
                   help="also evaluate the orbit frames with this equivalent centroid error added (0: off)")
    p.add_argument("--json-out", default=None, metavar="FILE",
                   help="also write the result (boresight.json's shape, rigsim.boresight-result/1) to FILE")
    p.add_argument("--export-frames", default=None, metavar="DIR", help="also write the orbit's ROI frames as bare "
                   "image files (ref_/meas_<camera>_m1|m2_<k>.png, no truth) for `rigsim boresight centroid`")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_run_boresight)
    declare(p, "out", folder=True)
    declare(p, "json_out")
    declare(p, "export_frames", folder=True)
    from rigsim.procedures.boresight import render_commands

    render_commands.add_cli(groups)

    b = groups["top"].add_parser("boresight", help="seed 003 stages on your own ROI frames and spot tables")
    bs = b.add_subparsers(dest="boresight_command", metavar="ACTION")
    c = bs.add_parser("centroid", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
                      help="ROI frames of M1 and M2 → a spot table (one row per pair)",
                      description="Centroid pairs of ROI frames (the i-th --m1 file with the i-th --m2 file) of one "
                                  "camera. A ROI is the rig's nominal window (orbit.window_px, centred on the design "
                                  "reference spot); positions are detector pixels.")
    c.add_argument("--rig", default="dual_line_array_prism", help="seed-003 rig file or default name")
    c.add_argument("--camera", required=True, help="the camera's name in the rig file")
    c.add_argument("--m1", nargs="+", required=True, metavar="FRAME", help="ROI frames of detector M1")
    c.add_argument("--m2", nargs="+", required=True, metavar="FRAME", help="ROI frames of detector M2, in the same order")
    c.add_argument("--method", default="tcom", choices=["tcom", "tcom_peak", "wcom", "gauss", "model"],
                   help="centroider (seed 003: tcom; tcom_peak: the peak's blob only, leaves out a ghost; model: "
                        "the core's image fitted by maximum likelihood, docs/forward-model-spots.md)")
    c.add_argument("--out", required=True, metavar="FILE", help="spot table (.csv or .parquet)")
    c.set_defaults(func=cmd_boresight_centroid)
    declare(c, "out", suffixes=(".csv", ".parquet"))
    v = bs.add_parser("solve", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
                      help="(Δf, α, β, γ) per row of a spot table against a reference",
                      description="Solve every row (camera, u_m1_px, v_m1_px, u_m2_px, v_m2_px) against the reference "
                                  "spots (the mean of each camera's rows in --reference). --stream reads rows on stdin "
                                  "and writes each result row on stdout at once (a real-time loop).")
    v.add_argument("--rig", default="dual_line_array_prism", help="seed-003 rig file or default name")
    v.add_argument("--reference", nargs="+", required=True, metavar="FILE", help="reference spot table(s)")
    v.add_argument("--measured", nargs="+", default=None, metavar="FILE", help="spot table(s) to solve")
    v.add_argument("--out", default=None, metavar="FILE", help="result table (default: print)")
    v.add_argument("--method", default="dvad", choices=["dvad", "simplified"], help="DVAD or the simplified eqs")
    v.add_argument("--reading", default="consistent", choices=["consistent", "as_printed"], help="reading of the equations")
    v.add_argument("--stream", action="store_true", help="rows on stdin (a header line first) → rows on stdout (DVAD)")
    v.add_argument("--json-out", default=None, metavar="FILE",
                   help="also write the result as JSON (rigsim.boresight-result/1): each estimate with its covariance, "
                        "and the change of the angle between the cameras per sample measured by both")
    v.add_argument("--centroid-sigma-px", type=number(1e-6, 10), default=None, metavar="PX",
                   help="centroid σ per coordinate for the JSON's covariances (default: the tables' sigma_* columns "
                        "when every table has them, else the rig's study.centroid_sigma_px)")
    from rigsim.procedures.fit_verdict import add_accept_option

    add_accept_option(v)
    v.set_defaults(func=cmd_boresight_solve)
    declare(v, "out", suffixes=(".csv", ".parquet"))
    declare(v, "json_out")
    return p


def cmd_boresight_centroid(args) -> int:
    from rigsim.files import write_table
    from rigsim.procedures.boresight.files import centroid_roi_files
    from rigsim.rig.load import load_boresight_rig

    rig = load_boresight_rig(args.rig)
    t0 = time.perf_counter()
    cols = centroid_roi_files(rig, args.camera, args.m1, args.m2, method=args.method)
    write_table(args.out, cols)
    print(f"{len(cols['sample'])} M1/M2 pairs of camera {args.camera} → {args.out} [{time.perf_counter() - t0:.2f} s]")
    return 0


def _merged_rows(paths, rig, what):
    from rigsim.procedures.boresight.files import read_spot_rows

    from rigsim.files.inputs import check_distinct

    check_distinct(paths, f"--{what.split()[0]}" if what.startswith("reference") else "--measured", by_name=False,
                   what="table")
    samples, cams, uvs = [], [], []
    for p in paths:
        s, c, uv = read_spot_rows(p, rig, what=what)
        samples += s
        cams += c
        uvs.append(uv)
    return samples, cams, np.concatenate(uvs) if uvs else np.zeros((0, 2, 2))


def cmd_boresight_solve(args) -> int:
    from rigsim.files import write_table
    from rigsim.procedures.boresight import files as F
    from rigsim.rig.load import load_boresight_rig

    rig = load_boresight_rig(args.rig)
    _, rcams, ruv = _merged_rows(args.reference, rig, "reference table")
    ref = {c: ruv[[k for k, x in enumerate(rcams) if x == c]].mean(axis=0) for c in dict.fromkeys(rcams)}
    if args.stream:
        if args.measured or args.method != "dvad" or args.reading != "consistent" or args.json_out:
            raise CliError("--stream solves rows from stdin with DVAD (consistent reading); drop --measured/--method/--reading/--json-out")
        _judge_solve(args, rig, rcams, ruv, [], np.zeros((0, 2, 2)))
        return _stream(rig, ref)
    if not args.measured:
        raise CliError("--measured FILE... is required (or --stream)")
    samples, cams, uv = _merged_rows(args.measured, rig, "spot table")
    verdict, sig = _judge_solve(args, rig, rcams, ruv, cams, uv)
    est = F.solve_rows(rig, ref, cams, uv, method=args.method, reading=args.reading)
    cols = F.estimate_columns(samples, cams, est)
    if args.json_out:
        _write_solve_json(args, rig, rcams, ref, samples, cams, uv, sig, verdict)
    if args.out:
        write_table(args.out, cols)
        print(f"{len(samples)} rows solved ({args.method}, {args.reading}) → {args.out}")
    else:
        print(",".join(cols))
        for row in zip(*cols.values()):
            print(",".join(str(x) for x in row))
    for line in verdict.lines():
        print(line, file=sys.stderr if not args.out else sys.stdout)
    return 0


def _table_sigmas(paths):
    from rigsim.procedures.boresight.files import spot_sigmas

    got = [spot_sigmas(p) for p in paths]
    return None if any(g is None for g in got) else np.concatenate(got)


def _sigmas(args, rig, rcams, cams):
    """The centroid σ of the measured rows (n, 4) and of the reference rows (n_ref, 4) px, and their source:
    --centroid-sigma-px, the tables' sigma_* columns, or the rig's study value, in that order."""
    sig_m = None if args.stream else _table_sigmas(args.measured)
    sig_r = _table_sigmas(args.reference)
    if args.centroid_sigma_px is not None:
        s = float(args.centroid_sigma_px)
        return np.full((len(cams), 4), s), np.full((len(rcams), 4), s), f"--centroid-sigma-px {s:g}"
    if sig_r is not None and (sig_m is not None or args.stream):
        return sig_m, sig_r, "the spot tables' sigma_* columns (the centroider's per-spot σ)"
    s = rig.study.centroid_sigma_px
    return (np.full((len(cams), 4), s), np.full((len(rcams), 4), s),
            f"the rig's study.centroid_sigma_px = {s:g} (the tables have no sigma_* columns)")


def _judge_solve(args, rig, rcams, ruv, cams, uv):
    """The solve's verdict (:func:`rigsim.procedures.boresight.files.solve_fit_quality`) and the σ the JSON's
    covariances use, scaled by χ²/dof when the reference scatter exceeds them beyond chance."""
    from rigsim.procedures.boresight.files import solve_alternatives, solve_fit_quality
    from rigsim.procedures.fit_verdict import judge

    sig_m, sig_r, source = _sigmas(args, rig, rcams, cams)
    q = solve_fit_quality(rig, rcams, ruv, sig_r, cams, uv, source)
    verdict = judge(q, solve_alternatives(rig, rcams, ruv, sig_r, cams, uv, source), accept=args.accept_poor_fit,
                    what="boresight solve")
    k = float(np.sqrt(verdict.covariance_scale))
    return verdict, (None if sig_m is None else sig_m * k, sig_r * k, source)


def _write_solve_json(args, rig, rcams, ref, samples, cams, uv, sig, verdict) -> None:
    """The JSON result of ``boresight solve``: covariances from the centroid σ (option, the tables' columns, or
    the rig's study value, in that order; the source is written in the file), scaled by the fit's χ²/dof."""
    from rigsim.files import write_json
    from rigsim.procedures.boresight.files import camera_geometry
    from rigsim.procedures.boresight.result_json import boresight_result_json

    sig_m, sig_r_rows, source = sig
    sig_r = {c: np.sqrt(np.mean(sig_r_rows[[k for k, x in enumerate(rcams) if x == c]] ** 2, axis=0) / rcams.count(c))
             for c in ref}
    if verdict.covariance_scale != 1.0:
        source += f", scaled by χ²/dof = {verdict.covariance_scale:.4g} (the reference rows scatter beyond it)"
    geoms = {c: camera_geometry(rig, c) for c in dict.fromkeys([*cams, *ref])}
    data = boresight_result_json(rig, geoms, ref, samples, cams, uv, sig_m, sig_r, method=args.method,
                                 reading=args.reading, mode="files", rig_file=args.rig, sigma_source=source)
    data["fit"] = verdict.block()
    write_json(args.json_out, data)
    print(f"→ {args.json_out} (covariances from {source})")


def _stream(rig, ref) -> int:
    """Rows on stdin → rows on stdout, one at a time: camera,u_m1_px,v_m1_px,u_m2_px,v_m2_px[,sample]."""
    from rigsim.files.numbers import parse_float
    from rigsim.procedures.boresight.files import spot_problem, streaming_solver

    solvers = streaming_solver(rig, ref)
    need = ["camera", "u_m1_px", "v_m1_px", "u_m2_px", "v_m2_px"]
    header = [h.strip() for h in sys.stdin.readline().strip().split(",")]
    missing = [c for c in need if c not in header]
    if missing:
        raise CliError(f"stdin: line 1 (header): no column {missing[0]}; expected {','.join(need)}[,sample]")
    idx = [header.index(c) for c in need]
    si = header.index("sample") if "sample" in header else None
    out = sys.stdout
    out.write("sample,camera,delta_f_um,alpha_arcsec,beta_arcsec,gamma_arcsec\n")
    out.flush()
    uv = np.empty((2, 2))
    for n, line in enumerate(sys.stdin, start=2):
        if not line.strip():
            continue
        f = [x.strip() for x in line.rstrip("\r\n").split(",")]  # CRLF lines (a Windows program's) read as LF
        if len(f) != len(header):
            raise CliError(f"stdin: line {n}: {len(f)} fields; expected {len(header)} like the header")
        cam = f[idx[0]]
        sol = solvers.get(cam)
        if sol is None:
            raise CliError(f"stdin: line {n}, column camera: {cam!r} has no reference")
        try:
            uv[0, 0], uv[0, 1], uv[1, 0], uv[1, 1] = (parse_float(f[i], special=False) for i in idx[1:])
        except ValueError:
            raise CliError(f"stdin: line {n}: {','.join(f[i] for i in idx[1:])!r}: expected four numbers (px) in ASCII "
                           "digits") from None
        why = spot_problem(rig, cam, uv)
        if why:
            raise CliError(f"stdin: line {n}: {why}")
        e = sol.solve(uv)
        a = e.angles_arcsec
        out.write(f"{f[si] if si is not None else n - 2},{cam},{float(e.delta_f_mm) * 1e3!r},{float(a[0])!r},"
                  f"{float(a[1])!r},{float(a[2])!r}\n")
        out.flush()
    return 0


def cmd_run_boresight(args) -> int:
    from tqdm import tqdm

    import rigsim
    from rigsim.files import write_json
    from rigsim.procedures.boresight.report import result_record, write_report
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
          f"reading '{args.reading}', loop model '{args.loop_model}'"
          + (" (the rendered orbit scenario stays physical)" if args.loop_model != "physical" and not args.no_orbit else ""))
    t0 = time.perf_counter()
    with tqdm(total=total, desc="boresight", unit="step", disable=True if args.quiet else None, file=sys.stderr,
              dynamic_ncols=True) as bar:
        def progress(n, stage):
            bar.set_postfix_str(stage)
            bar.update(n)

        orbit_kw = {"spp": args.spp, "measurements": args.measurements, "jitter_px": args.jitter_px}
        if args.export_frames:
            from rigsim.files import write_image

            names = [c.name for c in rig.cameras]

            def export(stage, c, j, k, fr):
                pre = "ref" if stage == "reference" else "meas"
                write_image(Path(args.export_frames) / f"{pre}_{names[c]}_m{j + 1}_{k:03d}.png", fr.dn)

            orbit_kw["on_frame"] = export
        res = run_study(rig, seed=args.seed, runs=args.runs, reading=args.reading, orbit=not args.no_orbit,
                        progress=progress, orbit_kw=orbit_kw, loop_model=args.loop_model,
                        eq20_cos2beta=args.eq20_cos2beta)
    cmd = "rigsim run boresight" + "".join(f" {a}" for a in sys.argv[3:]) if sys.argv[1:3] == ["run", "boresight"] else ""
    rel = rig_path.relative_to(Path.cwd()) if rig_path.is_relative_to(Path.cwd()) else rig_path
    report = write_report(res, args.out, rig_path=str(rel), command=cmd)
    f5 = res["fig5"]
    print(f"\nFig 5: {f5['runs']} runs at σ = {f5['sigma_px']} px, {args.loop_model} loop (3σ; eqs 19–22 in brackets)")
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
        write_json(args.json_out, result_record(res))
        print(f"wrote {args.json_out}")
    return 0
