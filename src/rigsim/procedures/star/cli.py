"""``rigsim run star-calibration``: seed 004 end to end (docs/star_calibration.md)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from rigsim.errors import CliError
from rigsim.files.options import SEED, SPP, integer, number
from rigsim.files.outputs import Output, declare

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
    p.add_argument("--seed", type=SEED, default=0, help="seed of the rendered run (same seed, same numbers)")
    p.add_argument("--trials", type=integer(1, 100_000), default=None, help="Monte-Carlo trials of the study (default: the rig's)")
    p.add_argument("--no-study", action="store_true", help="skip the Monte-Carlo studies (both)")
    p.add_argument("--equations", default="framework",
                   help="equation sets of the EKFs, batch fit and study: framework (2N-3 pairs, 2N-4 triplets) | all "
                        "(every pair, every triplet) | chain (consecutive stars in brightness order)")
    p.add_argument("--weighting", default=None,
                   help="measurement noise R: propagated (G Σ Gᵀ) | diagonal | unweighted (σ²I) (default: the rig's)")
    p.add_argument("--readings-trials", type=integer(2, 100_000), default=30,
                   help="trials per cell of the AD-vs-ADS study under every estimator (equation set × weighting × "
                        "focal-length case)")
    p.add_argument("--renderer", default="analytic", help="frame renderer: analytic | mitsuba")
    p.add_argument("--mitsuba-spp", type=SPP, default=256, help="samples per pixel of the Mitsuba windows (power of 4)")
    p.add_argument("--out", default=None, help="report folder (default renders/star_calibration)")
    p.add_argument("--export-frames", default=None, metavar="DIR", help="also write the frames as bare image files "
                   "(no truth) with attitudes.csv (frame, time_s, qw..qz commanded), for `rigsim star calibrate`; FITS "
                   "frames carry a TAN-SIP WCS from the commanded attitude and the nominal camera (what the spacecraft "
                   "knows), EXPTIME, GAIN, DATE-OBS, BUNIT")
    p.add_argument("--frame-format", default="fits", choices=["fits", "png", "tiff"], help="file type of --export-frames")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    st = groups["top"].add_parser("star", help="seed 004 stages on your own star frames")
    sts = st.add_subparsers(dest="star_command", metavar="ACTION")
    c = sts.add_parser(
        "calibrate", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        help="extract, identify and calibrate (f, u0, v0, k1, k2) from star frames, with or without an attitude log",
        description="The seed-004 pipeline on your frames (PNG/TIFF 16-bit or FITS) with the nominal rig: star "
                    "extraction, identification (from the commanded attitude of an attitude log, or lost in space "
                    "from the frames alone), the intrinsics and every attitude fitted together with a held-out check, "
                    "and the document's AD/ADS EKFs and batch least squares of (f, u0, v0, k1, k2) with covariance. "
                    "The attitude log has one row per frame: frame, time_s, qw, qx, qy, qz (the commanded "
                    "R(cam<-ICRS), scalar first). Frames that cannot be identified are named and left out.")
    c.add_argument("frames", nargs="+", metavar="FRAME", help="star frames of the rig's detector size")
    c.add_argument("--rig", default="star_sensor", help="star-sensor rig file (nominal values only)")
    c.add_argument("--attitudes", default=None, metavar="FILE",
                   help="attitude log (.csv/.parquet); without it the frames are identified lost in space, in the "
                        "order given")
    c.add_argument("--out", required=True, metavar="DIR", help="output folder: stars.csv and calibration.json")
    c.add_argument("--ekf", default="both", choices=["ad", "ads", "both"], help="EKF measurement model(s) to report")
    c.add_argument("--opencv", default=None, metavar="FILE",
                   help="also write the batch calibration as OpenCV's FileStorage camera (.yml/.json/.xml)")
    c.add_argument("--identify", default=None, choices=["commanded", "lost-in-space"],
                   help="identification: from the log's commanded attitude, or with no prior (the log then needs only "
                        "frame and time_s). Default: commanded with --attitudes, else lost-in-space")
    c.add_argument("--site", default=None, metavar="LAT,LON[,HEIGHT_M]",
                   help="ground frames: the site (geodetic degrees, metres); with --utc the stars are refracted by the "
                        "air before the joint fit (off when not given)")
    c.add_argument("--utc", default=None, metavar="ISO8601", help="the first frame's time (UTC), with --site")
    c.add_argument("--pressure-hpa", type=number(100, 1100), default=None,
                   help="air pressure at the site (default the standard atmosphere at its height)")
    c.add_argument("--temperature-c", type=number(-60, 60), default=10.0, help="air temperature at the site")
    from rigsim.procedures.fit_verdict import add_accept_option

    add_accept_option(c)
    c.set_defaults(func=cmd_star_calibrate)
    declare(c, "out", folder=True, derived=lambda a: [Output(Path(a.out) / n, f"--out's {n}")
                                                      for n in ("stars.csv", "calibration.json")])
    declare(c, "opencv", suffixes=(".yml", ".yaml", ".json", ".xml"))
    from rigsim.procedures.star import twin_commands

    twin_commands.add_cli(sts)
    p.set_defaults(func=cmd_run_star_calibration)
    declare(p, "out", folder=True)
    declare(p, "export_frames", folder=True)
    from rigsim.procedures.star import render_commands

    render_commands.add_cli(groups)


def _check(args) -> None:
    from rigsim.estimation.star_calibration import EQUATIONS, WEIGHTINGS

    if args.renderer not in RENDERERS:
        raise CliError(f"--renderer = {args.renderer!r}: allowed one of {', '.join(RENDERERS)}")
    if args.trials is not None and not 2 <= args.trials <= 100000:
        raise CliError(f"--trials = {args.trials}: allowed range is 2 to 100000")
    if args.equations not in EQUATIONS:
        raise CliError(f"--equations = {args.equations!r}: allowed one of {', '.join(EQUATIONS)}")
    if args.weighting is not None and args.weighting not in WEIGHTINGS:
        raise CliError(f"--weighting = {args.weighting!r}: allowed one of {', '.join(WEIGHTINGS)}")
    if not 2 <= args.readings_trials <= 100000:
        raise CliError(f"--readings-trials = {args.readings_trials}: allowed range is 2 to 100000")
    if args.seed < 0:
        raise CliError(f"--seed = {args.seed}: allowed range is ≥ 0")
    spp = args.mitsuba_spp
    if spp < 1 or spp > 65536 or (spp & (spp - 1)) or (spp.bit_length() - 1) % 2:
        raise CliError(f"--mitsuba-spp = {spp}: must be a power of 4 between 1 and 65536 (e.g. 64, 256, 1024)")


def _fit_text(fit: dict) -> str:
    """A short phrase of a ``fit`` block: χ²/dof, the verdict, the covariance's scale."""
    c = fit.get("chi2_dof")
    head = f"χ²/dof {c:.3g}" if c is not None else "χ²/dof —"
    tail = {"good": "fits", "scaled": f"σ scaled ×{fit['covariance_scale']:.3g}^½ (covariance ×{fit['covariance_scale']:.3g})",
            "poor": "POOR FIT: not a measurement", "not judged": "not judged"}[fit["verdict"]]
    return f"{head}, {tail}"


def _site(args):
    """--site and --utc (both or neither) as a refraction Site; None without them."""
    if (args.site is None) != (args.utc is None):
        raise CliError("--site and --utc go together: refraction needs where and when (leave both out when unknown)")
    if args.site is None:
        return None
    from astropy.time import Time

    from rigsim.optics.refraction import Site

    from rigsim.files.numbers import parse_float

    parts = args.site.split(",")
    try:
        vals = [parse_float(x) for x in parts]  # ASCII digits only
    except ValueError:
        vals = []
    if len(vals) not in (2, 3) or not all(np.isfinite(vals)):
        raise CliError(f"--site = {args.site!r}: expected LAT,LON[,HEIGHT_M] in degrees and metres")
    lat, lon, hgt = (*vals, 0.0)[:3]
    if not (-90 <= lat <= 90 and -180 <= lon <= 360 and -500 <= hgt <= 9000):
        raise CliError(f"--site = {args.site!r}: latitude −90 to 90°, longitude −180 to 360°, height −500 to 9000 m")
    try:
        Time(args.utc, scale="utc")
    except ValueError:
        raise CliError(f"--utc = {args.utc!r}: expected an ISO 8601 time, e.g. 2019-07-29T20:47:26") from None
    return Site(lat, lon, hgt, pressure_hpa=args.pressure_hpa, temperature_c=args.temperature_c)


def cmd_star_calibrate(args) -> int:
    from rigsim.files import write_json, write_table
    from rigsim.procedures.star.files import calibrate_star_files, star_result_json, stars_table
    from rigsim.rig.load import load_star_rig

    rig = load_star_rig(args.rig)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out = {out}: exists and is not a folder")
    if args.opencv and Path(args.opencv).suffix.lower() not in (".yml", ".yaml", ".json", ".xml"):
        raise CliError(f"--opencv {args.opencv}: an OpenCV FileStorage name ends in .yml, .yaml, .json or .xml")
    site = _site(args)
    identify = args.identify or ("commanded" if args.attitudes else "lost-in-space")
    if identify == "commanded" and not args.attitudes:
        raise CliError("--identify commanded needs --attitudes (the commanded attitude of every frame)")
    t0 = time.perf_counter()
    res, names = calibrate_star_files(args.frames, args.attitudes, rig.nominal_rig(), identification=identify,
                                      site=site, utc=args.utc)
    for name, ident in zip(names, res.ident):
        if not ident.ok:
            print(f"{name}: not identified ({ident.reason}); left out", file=sys.stderr)
    models = ("ad", "ads") if args.ekf == "both" else (args.ekf,)
    verdict = None
    if res.joint is not None:  # the calibration this command writes is the joint fit: judged before anything is written
        from rigsim.procedures.fit_verdict import judge
        from rigsim.procedures.star.files import joint_fit_quality

        verdict = judge(joint_fit_quality(res.joint.bundle), accept=args.accept_poor_fit, what="star-camera calibration")
    data = star_result_json(res, names, models)
    if verdict is not None:
        data["joint"]["fit"]["accepted_poor_fit"] = bool(verdict.accepted)
    write_table(out / "stars.csv", stars_table(res, names))
    write_json(out / "calibration.json", data)
    j = data.get("joint")
    if args.opencv:
        from rigsim.files.opencv import write_opencv_camera

        th = dict(zip(data["theta_names"], j["theta"] if j else res.batch.theta))  # f, u0, v0 (px), k1, k2
        W, H = rig.sensor.resolution_px
        write_opencv_camera(args.opencv, th["f"], th["f"], th["u0"], th["v0"], [th["k1"], th["k2"], 0.0, 0.0, 0.0], W, H)
        print(f"→ {args.opencv} (OpenCV camera: the {'joint fit' if j else 'batch least squares'})")
    st = res.ident_stats
    print(f"{st['frames']} frames, {st['frames_identified']} identified ({identify}); {st['usable']} usable stars, "
          f"{st['identified']} identified")
    if j:
        sig = dict(zip(j["estimated"], j["covariance"]["sigma"]))
        th = dict(zip(data["theta_names"], j["theta"]))
        print("joint fit (intrinsics and attitudes): " + ", ".join(
            f"{n} {th[n]:.5g} ± {sig[n]:.2g}" for n in j["estimated"]) + f"; {j['n_stars']} stars, {j['n_rejected']} left "
            f"out beyond 5σ")
        print(f"  χ²/dof {j['chi2_reduced_noise_model']:.2f} under the centroid σ → {j['chi2_reduced']:.2f} with a floor "
              f"of {j['sigma_floor_px']:.3f} px; {j['verdict']}")
        fov = j["field_of_view_deg"]
        print(f"  field of view {fov['horizontal']:.4f}° × {fov['vertical']:.4f}° (edge to edge through the principal point)")
        if j["held_out"]:
            h = j["held_out"]
            print(f"  held out: {h['n_stars']} stars of frames left out of the fit predicted to {h['rms_px']:.3f} px rms, "
                  f"error/σ rms {h['z_rms']:.2f}")
    if verdict is not None and verdict.accepted:  # (the χ² line above says how the σ were widened)
        print("  " + verdict.lines()[-1])
    bj = data["batch"]
    print("batch least squares (angular distances): " + ", ".join(f"{n} {v:.4f} ± {s:.4f}" for n, v, s in
                                                               zip(bj["estimated"], res.batch.x, bj["covariance"]["sigma"]))
          + f"; {_fit_text(bj['fit'])}")
    for key, e in data["ekf"].items():
        print(f"EKF {key}: " + ", ".join(f"{n} {v:.4f} ± {s:.4f}" for n, v, s in
                                           zip(e["estimated"], e["state"], e["covariance"]["sigma"]))
              + f"; {_fit_text(e['fit'])}")
    print(f"→ {out / 'stars.csv'}, {out / 'calibration.json'} [{time.perf_counter() - t0:.2f} s]")
    return 0


def cmd_run_star_calibration(args) -> int:
    import os

    from tqdm import tqdm

    import rigsim
    from rigsim.files import write_image, write_table
    from rigsim.procedures.star.estimators import readings_study
    from rigsim.procedures.star.files import attitude_log_columns
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
        exported: list = []

        nominal_camera = rig.nominal_rig().sensor.camera()

        def export(obs):
            name = f"star_{obs.index:03d}.{ {'fits': 'fits', 'png': 'png', 'tiff': 'tif'}[args.frame_format]}"
            header = None
            if args.frame_format == "fits":  # what the spacecraft knows: commanded attitude, nominal camera
                from rigsim.render.star import frame_seed, star_fits_cards

                header = star_fits_cards(rig, obs.R_commanded, seed=frame_seed(args.seed, obs.index), time_s=obs.time_s,
                                         camera=nominal_camera, wcs_name="commanded attitude, nominal camera")
            write_image(Path(args.export_frames) / name, obs.dn, header)
            exported.append((name, obs.time_s, obs.R_commanded))

        res = run_pipeline(rig, seed=args.seed, renderer=args.renderer, mitsuba=mitsuba, progress=bar,
                           on_frame=export if args.export_frames else None, equations=args.equations,
                           weighting=args.weighting)
    if args.export_frames:
        write_table(Path(args.export_frames) / "attitudes.csv",
                    attitude_log_columns(*zip(*exported)) if exported else {})
        print(f"exported {len(exported)} frames to {args.export_frames}/ with attitudes.csv")
    study = readings = None
    if not args.no_study:
        from rigsim.truth.star import StarSky

        sky = StarSky(rig)
        noise = CentroidNoise.from_rig(rig, scale=res.noise_scale, background_photons_per_px=sky.background_photons_per_px)
        t1 = time.perf_counter()
        with tqdm(total=trials, desc="AD vs ADS study", unit="trial", disable=True if args.quiet else None,
                  file=sys.stderr, dynamic_ncols=True) as bar:
            study = run_study(rig, sky, trials=trials, noise=noise, progress=bar, equations=args.equations,
                              weightings=None if args.weighting is None else (args.weighting,))
        res.times["study"] = time.perf_counter() - t1
        t1 = time.perf_counter()
        with tqdm(total=args.readings_trials, desc="AD vs ADS under every estimator", unit="trial",
                  disable=True if args.quiet else None, file=sys.stderr, dynamic_ncols=True) as bar:
            readings = readings_study(rig, sky, trials=args.readings_trials, noise=noise, progress=bar)
        res.times["readings study"] = time.perf_counter() - t1
    res.times["wall"] = time.perf_counter() - t0
    print()
    for line in summary_lines(res, study, readings):
        print(line)
    try:
        rig_path = os.path.relpath(resolve_star_rig_path(args.rig))
    except Exception:
        rig_path = args.rig
    cmd = "rigsim " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("rigsim") else None
    files = write_report(out, res, study, command=cmd, rig_path=rig_path, readings=readings)
    print(f"\nwall time {res.times['wall']:.1f} s; report: {files['report']} (plots: "
          + ", ".join(p.name for k, p in files.items() if k not in ("report", "json")) + ")")
    return 0
