"""The cube-mirror family's commands (seeds 000/001): ``rigsim run cube-mirror``, ``rigsim triad``,
``rigsim render sun-sensor`` and ``rigsim scene export``. Heavy modules are imported inside the
commands, so that ``rigsim --help`` stays fast."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

import rigsim
from rigsim.errors import CliError
from rigsim.files.atomic import atomic_write_text, output_folder
from rigsim.files.numbers import parse_float
from rigsim.files.outputs import declare
from rigsim.files.names import file_stem, slug
from rigsim.files.options import SEED, SPP, integer, number
from rigsim.procedures.cube_mirror import file_commands, render_commands
from rigsim.reporting import text_table
from rigsim.rig.load import DEFAULT_RIG

__all__ = ["add_cli"]


def add_cli(groups: dict) -> None:
    """Add the family's commands to the parser groups {"top", "run", "render"} of ``rigsim``."""
    sub, rs, rds = groups["top"], groups["run"], groups["render"]
    file_commands.add_cli(groups)
    render_commands.add_cli(groups)

    cmr = rs.add_parser("cube-mirror", help="seeds 000/001: sun sensor ↔ mirror cube calibration campaign",
                        description="Run the cube-mirror campaign on a rig and compare with truth; then the Monte-Carlo error budget.",
                        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    cmr.add_argument("--rig", default=DEFAULT_RIG, help="rig file path or default rig name")
    cmr.add_argument("--analytic", action="store_true", help="analytic campaign (exact geometry + modelled noise, no rendering; seconds)")
    cmr.add_argument("--ideal", action="store_true", help="no rig errors, no encoder or detector noise: checks the simulator itself")
    cmr.add_argument("--seed", type=SEED, default=2009, help="random seed (the same seed gives the same numbers)")
    cmr.add_argument("--trials", type=integer(1, 100_000), default=None, help="Monte-Carlo campaigns per error-budget row (default 200 rendered, 300 analytic)")
    cmr.add_argument("--out", default=None, metavar="DIR", help="rendered: report directory (default renders/cube_mirror_<rig name>)")
    cmr.add_argument("--threshold", type=number(1e-6, 1000), default=None, help="rendered: null-search threshold, px (seed 000) or arcsec (001); default the rig's")
    cmr.add_argument("--sweep-spp", type=SPP, default=256, help="rendered: samples per pixel of the sun-sensor sweep frames")
    cmr.add_argument("--sweep-step", type=number(1e-3, 90), default=None, metavar="DEG", help="rendered: sweep step (default the rig's, 5°)")
    cmr.add_argument("--autocollimator-spp", type=SPP, default=None, metavar="N",
                     help="rendered, seed 001: samples per pixel of the autocollimator's frames (default 1024)")
    cmr.add_argument("--repeat-frames", type=integer(0, 100), default=4, help="rendered: extra frames at the first null to measure the null-measurement noise")
    cmr.add_argument("--axis-order", default=None, help="estimator's axis nesting reading, outermost first (default: the rig's)")
    cmr.add_argument("--no-budget", action="store_true", help="skip the Monte-Carlo error budget")
    cmr.add_argument("--centroid-sigma-px", type=number(0.0, 10.0), default=None, metavar="PX",
                     help="analytic: the sun-sensor centroid noise per axis (default the rig's "
                          "sun_sensor.centroid_sigma_px); a rendered run prints the σ its frames measure")
    cmr.add_argument("--json-out", default=None, metavar="FILE", help="also write the results as JSON")
    cmr.add_argument("--export-frames", default=None, metavar="DIR", help="rendered: also write the sweep and null-search "
                     "frames as bare image files (no truth) with angles.csv, nulls.csv and null_frames.csv, for your own pipeline")
    cmr.add_argument("--frame-format", default="png", choices=["png", "tiff", "fits"], help="rendered: file type of --export-frames")
    cmr.add_argument("--centroider", default=None, metavar="PKG.MODULE:FUNC", help="rendered: your centroider (frame → (u, v) "
                     "px) on the same sweep frames; the report shows its end-to-end error beside rigsim's")
    cmr.add_argument("--import-centroids", default=None, metavar="FILE", help="rendered: your centroids (frame, u_px, v_px) "
                     "of frames exported with --export-frames (same rig, seed, sweep options); compared as --centroider")
    cmr.add_argument("--quiet", action="store_true", help="no progress bar")
    cmr.set_defaults(func=cmd_run_cube_mirror)
    declare(cmr, "out", folder=True)
    declare(cmr, "json_out")
    declare(cmr, "export_frames", folder=True)

    rss = rds.add_parser("sun-sensor", help="the sun simulator seen by the sun sensor at a turntable pose",
                         formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    rss.add_argument("--rig", default=DEFAULT_RIG, help="rig file path or default rig name")
    rss.add_argument("--pose", default=None, help="true turntable angles in degrees, e.g. X=10,Y=-5")
    rss.add_argument("--seed", type=SEED, default=0, help="frame seed (same seed, same frame)")
    rss.add_argument("--spp", type=SPP, default=1024, help="samples per pixel (power of 4)")
    rss.add_argument("--noiseless", action="store_true", help="detector without random noise")
    rss.add_argument("--ideal", action="store_true", help="rig without its true errors")
    rss.add_argument("--out", default="renders/frames", help="output folder")
    rss.add_argument("--name", type=file_stem, default="sun_sensor", help="file stem of the frame")
    rss.add_argument("--preview", default=None, metavar="PNG", help="also write an 8-bit zoomed preview")
    rss.set_defaults(func=cmd_render_sun_sensor)
    declare(rss, "out", folder=True)
    declare(rss, "preview", suffixes=(".png", ".jpg", ".tif"))

    sc = sub.add_parser("scene", help="Mitsuba scenes of a rig")
    scs = sc.add_subparsers(dest="scene_command", metavar="ACTION")
    sce = scs.add_parser("export", help="write the rig's scenes as Mitsuba XML (rendered by the plain mitsuba command)")
    sce.add_argument("rig", help="rig file path or default rig name")
    sce.add_argument("--xml", required=True, metavar="DIR", help="output folder (XML + meshes/)")
    sce.add_argument("--pose", default=None, help="turntable angles in degrees, e.g. X=180,Y=0")
    sce.add_argument("--spp", type=SPP, default=64, help="samples per pixel written into the XML")
    sce.add_argument("--beam", choices=("divergent", "collimated"), default="divergent",
                     help="diaphragm screen: the sun simulator's divergent beam as the campaign renders it (default), "
                          "or one collimated pencil")
    sce.set_defaults(func=cmd_scene_export)
    declare(sce, "xml", folder=True)


def _progress(total, desc, enabled=True):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="campaign", disable=None if enabled else True, file=sys.stderr, dynamic_ncols=True)


def _print_truth_vs_recovered(res, labels) -> None:
    """The three recovered rotations of a cube-mirror campaign against the truth (arcsec)."""
    from rigsim.frames import ARCSEC_PER_RAD, small_angle_error

    rows = []
    for label, (est, tru) in zip(labels, ((res.R_sun_from_rot_est, res.R_sun_from_rot_true),
                                          (res.R_cube_from_rot_est, res.R_cube_from_rot_true),
                                          (res.R_cube_from_sun_est, res.R_cube_from_sun_true))):
        e = small_angle_error(est, tru) * ARCSEC_PER_RAD
        rows.append([label, *(f"{x:+.3f}" for x in e), f"{np.linalg.norm(e):.3f}"])
    print("\nTruth vs recovered (small-angle error of the recovered rotation, about the target frame's axes, arcsec):")
    print(text_table(["rotation", "x″", "y″", "z″", "|δ|″"], rows))


def cmd_run_cube_mirror(args) -> int:
    from rigsim.rig import load_rig
    from rigsim.rig.geometry import check_geometry
    from rigsim.rig.load import resolve_rig_path

    check_geometry(load_rig(args.rig), resolve_rig_path(args.rig))  # refuse what cannot work before rendering
    if args.trials is None:
        args.trials = 300 if args.analytic else 200
    if args.analytic:
        used = [o for o in ("export_frames", "centroider", "import_centroids", "autocollimator_spp") if getattr(args, o)]
        if used:
            raise CliError(f"--{used[0].replace('_', '-')}: works on rendered frames; drop --analytic")
        return _run_cube_mirror_analytic(args)
    if args.centroid_sigma_px is not None:
        raise CliError("--centroid-sigma-px: the analytic campaign's modelled centroid noise; a rendered run measures "
                       "it on its frames (add --analytic)")
    return _run_cube_mirror_rendered(args)


def _run_cube_mirror_rendered(args) -> int:
    import time
    import warnings

    from tqdm import tqdm

    from rigsim.procedures.cube_mirror import campaign as cm
    from rigsim.procedures.cube_mirror import rendered_campaign as rc
    from rigsim.procedures.cube_mirror.report import write_report
    from rigsim.rig import load_rig
    from rigsim.rig.load import resolve_rig_path
    from rigsim.truth.cube_mirror.realization import realization_from_rig

    rig = load_rig(args.rig)
    if not 2 <= args.trials <= 100000:
        raise CliError(f"--trials = {args.trials}: allowed range is 2 to 100000")
    if args.sweep_spp < 1 or args.sweep_spp > 65536:
        raise CliError(f"--sweep-spp = {args.sweep_spp}: allowed range is 1 to 65536")
    if args.threshold is not None and not (0 < args.threshold <= 1000):
        raise CliError(f"--threshold = {args.threshold}: allowed range is (0, 1000] (px for seed 000, arcsec for 001)")
    if args.repeat_frames < 0 or args.repeat_frames > 100:
        raise CliError(f"--repeat-frames = {args.repeat_frames}: allowed range is 0 to 100")
    axis_order = args.axis_order or cm.default_axis_order(rig)
    if sorted(axis_order) != sorted(a.label for a in rig.turntable.axes):
        raise CliError(f"--axis-order = {axis_order!r}: must be a permutation of {[a.label for a in rig.turntable.axes]}")
    if args.ideal:
        rig = rig.model_copy(update={"procedure": rig.procedure.model_copy(update={"command_resolution_deg": 0.0})})
    real = realization_from_rig(rig, ideal=args.ideal)
    noise = cm.Noise() if args.ideal else cm.noise_from_rig(rig)
    out_dir = Path(args.out) if args.out else Path("renders") / f"cube_mirror_{slug(rig.name)}"
    frames = _user_frames(args, rig)
    threshold = args.threshold if args.threshold is not None else (0.01 if args.ideal and rig.procedure.method == "diaphragm"
                                                                   else 0.005 if args.ideal else None)
    print(f"rigsim {rigsim.__version__} — cube-mirror campaign on rendered frames (seed {rig.seed_document}), rig '{rig.name}'")
    print(f"rig file: {args.rig}   seed: {args.seed}   axis order (outer→inner): {axis_order}   "
          f"errors: {'none (ideal rig, noise-free detector)' if args.ideal else 'the rig file’s true errors + detector and encoder noise'}")
    from rigsim.render.backend import cap_mmap_threshold

    cap_mmap_threshold()  # the frames' large arrays go back to the system when freed (here and in the workers)
    picture = _rig_picture_first(rig)  # while this process is small: see _rig_picture_first
    from rigsim.render.threads import cores

    t_all = time.perf_counter()
    total = rc.expected_frames(rig) + args.repeat_frames
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # geometry problems surface as SearchError / flags
        with tqdm(total=total, desc="campaign", unit="frame", disable=True if args.quiet else None, file=sys.stderr,
                  dynamic_ncols=True) as bar:
            camp = rc.run_rendered_campaign(rig, real, seed=args.seed, axis_order=axis_order, noise=noise,
                                            noiseless=args.ideal, threshold=threshold, sweep_spp=args.sweep_spp,
                                            sweep_step_deg=args.sweep_step, repeat_frames=args.repeat_frames,
                                            progress=_Releasing(bar), frames=frames, aiming_workers=min(2, cores()),
                                            autocollimator_spp=args.autocollimator_spp)
    wall = dict(camp.times)
    res = camp.result
    cal = camp.calibration
    print(f"\nStep 1/B  sun-sensor sweep ±{rig.procedure.sweep_range_deg:g}° every "
          f"{args.sweep_step or rig.procedure.sweep_step_deg:g}°: {camp.sweep.n_rendered} frames rendered, "
          f"{cal.n_points} used" + (f" ({len(cal.outliers)} outliers left out)" if len(cal.outliers) else "")
          + (f" ({len(cal.outside_field)} beyond the field)" if len(cal.outside_field) else "")
          + f", fit RMS {cal.rms_px:.4f} px; centroid − exact {camp.measured_noise['sun_centroid_rms_px']:.4f} px rms")
    from rigsim.procedures.cube_mirror.concentricity import table1_text

    if camp.step_a is not None:
        sa = camp.step_a
        print(f"\nStep A  autocollimator on the plane mirror: {len(sa.measured_arcsec)} frames, last reading "
              f"({sa.measured_arcsec[-1][0]:+.3f}″, {sa.measured_arcsec[-1][1]:+.3f}″)")
    print(f"\n{'Steps 2-3' if rig.procedure.method == 'diaphragm' else 'Step C'}  null search log "
          f"({'Table 1 form: θ in degrees, hole/spot offset in aiming-camera px' if camp.null_unit == 'px' else 'readings in arcsec'}):")
    print(table1_text(camp.searches))

    _print_truth_vs_recovered(res, ("R(sun←rot)  sweep fit", "R(cube←rot) search + TRIAD", "R(cube←sun) composed"))
    user = _user_frames_finish(args, rig, frames, camp, real, axis_order)
    from rigsim.render.backend import release_memory

    release_memory()  # the renderers are gone: the budget's workers start smaller
    budget = None
    if not args.no_budget:
        mn = camp.measured_noise
        t0 = time.perf_counter()
        with tqdm(total=rc.budget_trials_count(rig, args.trials), desc="error budget", unit="campaign",
                  disable=True if args.quiet else None, file=sys.stderr, dynamic_ncols=True) as bar:
            budget = rc.rendered_error_budget(rig, args.trials, args.seed + 1, null_sigma=mn["null_measurement_rms"],
                                              centroid_sigma_px=mn["sun_centroid_rms_px"], axis_order=axis_order,
                                              progress=bar)
        wall["error budget (Monte Carlo)"] = time.perf_counter() - t0
        print(f"\nError budget by Monte Carlo ({args.trials} campaigns per row, image noise as measured above): "
              "σ of the R(cube←sun) error per cube axis")
        tab = [[r.source, *(f"{s:.2f}" for s in r.sigma_arcsec), "-" if r.paper_arcsec is None else f"{r.paper_arcsec:.2f}"]
               for r in budget.rows]
        print(text_table(["source", "σx″", "σy″", "σz″", "document σ″"], tab))
        rss, tog = budget.rss_of_sources(), budget.together().sigma_arcsec
        print(f"RSS of the single-source rows: {rss[0]:.2f} / {rss[1]:.2f} / {rss[2]:.2f}″; together: "
              f"{tog[0]:.2f} / {tog[1]:.2f} / {tog[2]:.2f}″ (ratio {tog[0] / rss[0]:.2f} / {tog[1] / rss[1]:.2f} / {tog[2] / rss[2]:.2f})")
        if rig.procedure.method == "diaphragm":
            print("paper: RSS of σ1..σ4 = 3.69″ (eq 14), claim < 4″ (1σ); docs/campaign.md compares.")
    wall["total"] = time.perf_counter() - t_all
    try:
        import os

        rig_path = os.path.relpath(resolve_rig_path(args.rig))
    except Exception:
        rig_path = args.rig
    release_memory()  # the budget's arrays
    files = write_report(out_dir, camp, rig, budget=budget, rig_path=rig_path, wall_times=wall, user=user, picture=picture,
                         command="rigsim " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("rigsim") else None)
    print("\nWall time by stage (s): " + ", ".join(f"{k} {v:.1f}" for k, v in wall.items()))
    print(f"report: {files['report']}  (plots: " + ", ".join(p.name for k, p in files.items() if k not in ("report", "json")) + ")")
    if args.json_out:
        atomic_write_text(Path(args.json_out), files["json"].read_text())
        print(f"wrote {args.json_out}")
    return 0


class _Releasing:
    """The campaign's progress bar, giving freed render memory back to the system after every frame and
    between stages, so that the next frame's transient arrays start from a smaller process."""

    def __init__(self, bar):
        self.bar = bar

    def update(self, n: int = 1) -> None:
        from rigsim.render.backend import trim_memory

        self.bar.update(n)
        trim_memory()

    def set_description(self, s: str) -> None:
        from rigsim.render.backend import release_memory

        release_memory()
        self.bar.set_description(s)


def _rig_picture_first(rig) -> tuple[bytes | None, str]:
    """The report's 3D rig picture at the first face's exact null, rendered now in a child process.

    pyvista, VTK and Mesa's off-screen OpenGL take ~350 MB; rendered in this process after the
    campaign they would add to what the renderers leave behind, and in a child at the end to all
    of this process. Before Mitsuba is imported this process is small, and the picture needs only
    the rig and the pose (the exact null: the search's null differs by arcseconds). Returns (PNG
    bytes, "") or (None, one line saying why there is no picture)."""
    import tempfile

    from rigsim.view.picture_process import picture_in_child

    with tempfile.TemporaryDirectory(prefix="rigsim-picture-") as tmp:
        path, why = picture_in_child(rig, Path(tmp) / "rig.png", pose_deg="null", size=(1400, 800))
        return (path.read_bytes(), "") if path is not None else (None, why)


def _user_frames(args, rig):
    """The sweep-frame collector for --export-frames / --centroider / --import-centroids (or None)."""
    if not (args.export_frames or args.centroider or args.import_centroids):
        return None
    from rigsim.procedures.cube_mirror.user_frames import CampaignFrames, load_centroider

    if args.centroider and args.import_centroids:
        raise CliError("--centroider and --import-centroids: give one of them")
    out = None
    if args.export_frames:
        out = Path(args.export_frames)
        if out.exists() and not out.is_dir():
            raise CliError(f"--export-frames = {out}: exists and is not a folder")
        output_folder(out)
    fn = load_centroider(args.centroider) if args.centroider else None
    return CampaignFrames(rig, out, centroider=fn, centroider_name=args.centroider or "", seed=args.seed,
                          suffix={"png": ".png", "tiff": ".tif", "fits": ".fits"}[args.frame_format])


def _user_frames_finish(args, rig, frames, camp, real, axis_order):
    if frames is None:
        return None
    if frames.out_dir is not None:
        logs = frames.write_logs([s.final_reading_rad for s in camp.searches], rig.procedure.faces)
        print(f"\nexported {len(frames.names)} sweep frames and {len(frames.null_rows)} null-search frames to "
              f"{frames.out_dir}/ with " + ", ".join(p.name for p in logs.values()))
    if args.import_centroids:
        frames.import_centroids(args.import_centroids)
    if not (args.centroider or args.import_centroids):
        return None
    from rigsim.procedures.cube_mirror.user_frames import user_comparison

    cmp = user_comparison(rig, frames, camp, real, axis_order)
    rows = []
    for who, label in (("rigsim", "rigsim"), ("user", "yours")):
        c = cmp[who]
        rows.append([label, str(c["centroids"]["n"]), ", ".join(f"{x:.4f}" for x in c["centroids"]["rms_px"]),
                     ", ".join(f"{x:+.3f}" for x in c["R_sun_from_rot_error_arcsec"]),
                     ", ".join(f"{x:+.3f}" for x in c["R_cube_from_sun_error_arcsec"])])
    print(f"\nYour centroider ({cmp['centroider']}) beside rigsim's on the same sweep frames (errors against the truth):")
    print(text_table(["centroider", "frames", "centroid−exact rms u, v px", "R(sun←rot) err ″", "R(cube←sun) err ″"], rows))
    return cmp


def _run_cube_mirror_analytic(args) -> int:
    from rigsim.procedures.cube_mirror import campaign as cm
    from rigsim.rig import load_rig
    from rigsim.truth.cube_mirror.realization import realization_from_rig

    rig = load_rig(args.rig)
    if args.trials < 2:
        raise CliError(f"--trials = {args.trials}: allowed range is 2 to 100000")
    axis_order = args.axis_order or cm.default_axis_order(rig)
    if sorted(axis_order) != sorted(a.label for a in rig.turntable.axes):
        raise CliError(f"--axis-order = {axis_order!r}: must be a permutation of {[a.label for a in rig.turntable.axes]}")
    rng = np.random.default_rng(args.seed)
    real = realization_from_rig(rig, ideal=args.ideal)
    noise = cm.Noise() if args.ideal else cm.noise_from_rig(rig)
    if args.centroid_sigma_px is not None:
        from dataclasses import replace

        noise = replace(noise, centroid_sigma_px=float(args.centroid_sigma_px))
    res = cm.run_campaign(rig, real, noise, rng, axis_order)

    print(f"rigsim {rigsim.__version__} — cube-mirror campaign, analytic (seed {rig.seed_document}), rig '{rig.name}'")
    print(f"rig file: {args.rig}   seed: {args.seed}   axis order (outer→inner): {axis_order}   "
          f"errors: {'none (ideal rig)' if args.ideal else 'the rig file’s true errors + random noise'}")
    cal = res.calibration
    print(f"\nStep 1/B  sun-sensor sweep ±{rig.procedure.sweep_range_deg:g}° every {rig.procedure.sweep_step_deg:g}°: "
          f"{cal.n_points} poses on the detector, fit RMS {cal.rms_px:.4f} px")
    src = "--centroid-sigma-px" if args.centroid_sigma_px is not None else "the rig's sun_sensor.centroid_sigma_px"
    print(f"  centroids: the exact spot centre + Gaussian noise of {noise.centroid_sigma_px:g} px per axis ({src}; "
          "a rendered run, without --analytic, measures its frames' σ and prints it: pass it here to compare)")
    ss = rig.sun_sensor
    truth = {"fx": ss.fx_px, "fy": ss.fy_px, "cx": ss.principal_point_px[0], "cy": ss.principal_point_px[1], **ss.distortion.model_dump()}
    rows = []
    for name, val, sig in zip(cal.param_names, cal.params, np.sqrt(np.diag(cal.covariance))):
        if name in truth:
            rows.append([name, f"{truth[name]:.6g}", f"{val:.6g}", f"{val - truth[name]:+.3g}", f"{sig:.2g}", f"{(val - truth[name]) / sig:+.2f}" if sig > 0 else "-"])
    print(text_table(["param", "truth", "recovered", "error", "σ (pred.)", "error/σ"], rows))
    poses = ", ".join(f"θ{2 * i + 1}={p['X']:.4f}° θ{2 * i + 2}={p['Y']:.4f}°" for i, p in enumerate(res.null_poses_deg))
    print(f"\nSteps 2-3/C  nulls on faces {rig.procedure.faces[0]} and {rig.procedure.faces[1]} (readings): {poses}")

    _print_truth_vs_recovered(res, ("R(sun←rot)  step 1/B", "R(cube←rot) TRIAD", "R(cube←sun) composed"))
    np.set_printoptions(precision=7, suppress=True)
    print(f"\nrecovered R(cube←sun):\n{res.R_cube_from_sun_est}")

    from rigsim.procedures.cube_mirror.result_json import campaign_json
    from rigsim.rig.load import resolve_rig_path

    out = campaign_json(res, rig, mode="analytic", seed=args.seed, rig_file=resolve_rig_path(args.rig), ideal=args.ideal)
    out["centroid_sigma_px"] = float(noise.centroid_sigma_px)
    if not args.no_budget:
        n_src = len(cm.budget_sources(rig)) + (2 if rig.procedure.method == "diaphragm" else 1)
        with _progress(n_src * args.trials, "error budget (Monte Carlo)", not args.quiet) as bar:
            rows_b = cm.error_budget(rig, args.trials, args.seed + 1, axis_order, progress=bar.update)
        print(f"\nError budget by Monte Carlo ({args.trials} campaigns per row): σ of the R(cube←sun) error per cube axis")
        tab = []
        for r in rows_b:
            tab.append([r.source, *(f"{s:.2f}" for s in r.sigma_arcsec), f"{r.rss_arcsec:.2f}", "-" if r.paper_arcsec is None else f"{r.paper_arcsec:.2f}"])
        print(text_table(["source", "σx″", "σy″", "σz″", "RSS″", "document σ″"], tab))
        if rig.procedure.method == "diaphragm":
            print("paper: RSS of σ1..σ4 = 3.69″ (eq 14), claim < 4″ (1σ). The paper's σ is one number per source; "
                  "rigsim reports the resulting σ about each cube axis (docs/error_budget.md).")
        out["budget"] = [{"source": r.source, "sigma_arcsec": r.sigma_arcsec.tolist(), "paper_arcsec": r.paper_arcsec} for r in rows_b]
    if args.json_out:
        atomic_write_text(Path(args.json_out), json.dumps(out, indent=2))
        print(f"\nwrote {args.json_out}")
    return 0


def _parse_pose(text: str | None, rig) -> dict[str, float]:
    """'X=10,Y=-5' → {'X': 10.0, 'Y': -5.0} (degrees), checked against the rig's axes and ranges."""
    if not text:
        return {}
    labels = {a.label: a for a in rig.turntable.axes}
    pose = {}
    for part in text.split(","):
        if "=" not in part:
            raise CliError(f"--pose = {text!r}: expected LABEL=DEGREES[,LABEL=DEGREES], e.g. X=10,Y=-5")
        k, v = (x.strip() for x in part.split("=", 1))
        if k not in labels:
            raise CliError(f"--pose axis {k!r}: this turntable has axes {sorted(labels)}")
        if k in pose:
            raise CliError(f"--pose = {text!r}: axis {k} given twice")
        try:
            val = parse_float(v)
        except ValueError:
            raise CliError(f"--pose {k} = {v!r}: not a number of degrees in ASCII digits") from None
        lo, hi = labels[k].range_deg
        if not lo <= val <= hi:
            raise CliError(f"--pose {k} = {val}: allowed range is {lo} to {hi} degrees")
        pose[k] = val
    return pose


def cmd_scene_export(args) -> int:
    from rigsim.render.cube_mirror.export import export_rig
    from rigsim.rig import load_rig

    rig = load_rig(args.rig)
    pose = _parse_pose(args.pose, rig)
    for p in export_rig(rig, Path(args.xml), pose, spp=args.spp, beam=args.beam):
        print(f"wrote {p}")
    print(f"render one with: mitsuba -o out.exr {Path(args.xml) / 'sun_sensor.xml'}")
    return 0


def cmd_render_sun_sensor(args) -> int:
    import cv2

    from rigsim.render.cube_mirror.sun_sensor import SunSensorScene
    from rigsim.rig import load_rig
    from rigsim.truth.cube_mirror.realization import realization_from_rig

    rig = load_rig(args.rig)
    pose = _parse_pose(args.pose, rig)
    if args.spp < 1 or args.spp & (args.spp - 1) or (args.spp.bit_length() - 1) % 2:
        raise CliError(f"--spp = {args.spp}: must be a power of 4 (the low-discrepancy sampler), e.g. 256, 1024, 4096")
    scene = SunSensorScene(rig, realization_from_rig(rig, ideal=args.ideal), spp=args.spp)
    fr = scene.render({k: np.radians(v) for k, v in pose.items()}, seed=args.seed, noiseless=args.noiseless)
    out = Path(args.out)
    png, js = fr.write(out / args.name)
    print(f"wrote {png} (16-bit DN) and {js} (truth and render settings) in {fr.seconds:.2f} s")
    flags = {k: v for k, v in fr.sidecar["flags"].items() if v and isinstance(v, (bool, int)) and k != "spot_extent_px"}
    t = fr.sidecar["truth"]["spot"]
    if t.get("valid"):
        print(f"true spot: centre {np.round(t['center_uv'], 4).tolist()} px, pixel-binned centroid "
              f"{np.round(t['pixel_centroid_uv'], 4).tolist()} px")
        from rigsim.imaging.frame_spots import measure_frame, single_spot
        from rigsim.procedures.detector_settings import detector_settings

        det = detector_settings(rig, "sun-sensor")
        sp = measure_frame(fr.dn, det.noise, saturation_dn=det.saturation_dn)
        k = single_spot(sp)
        if k is not None:
            e = np.hypot(sp.u[k] - t["center_uv"][0], sp.v[k] - t["center_uv"][1])
            print(f"measured (rigsim centroid, scurve): [{sp.u[k]:.4f}, {sp.v[k]:.4f}] px, {e:.4f} px from the true centre")
    if flags:
        print(f"flags: {flags}")
    if args.preview:
        win = fr.extra["window"]
        u0, v0 = win.origin_uv
        dn = fr.dn.astype(float)
        h = win.image.shape[0] // 2
        crop = dn[max(v0 + h - 12, 0):v0 + h + 12, max(u0 + h - 12, 0):u0 + h + 12]
        lo, hi = np.percentile(crop, 5), crop.max()
        img = (np.clip((crop - lo) / max(hi - lo, 1), 0, 1) ** 0.4 * 255).astype(np.uint8)  # gamma shows the noise floor
        img = cv2.resize(img, None, fx=16, fy=16, interpolation=cv2.INTER_NEAREST)
        from rigsim.files import atomic_write_bytes

        ext = Path(args.preview).suffix.lower()
        ok, buf = cv2.imencode(ext, img) if ext in (".png", ".jpg", ".jpeg", ".tif", ".tiff") else (False, None)
        if not ok:
            raise CliError(f"--preview {args.preview}: the name must end in .png, .jpg or .tif")
        atomic_write_bytes(args.preview, buf.tobytes())
        print(f"wrote {args.preview} (8-bit preview: 24×24 px around the spot, 16× zoom, gamma 0.4)")
    return 0
