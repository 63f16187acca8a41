"""The cube-mirror stages as commands on files: ``rigsim calibrate sun-sensor``, ``rigsim triad``
(2- and 3-axis tables, from the null log or from θ1..θ4) and ``rigsim compose``."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from rigsim.errors import CliError, PoorFitError
from rigsim.files.options import number, real
from rigsim.files.outputs import declare
from rigsim.procedures.fit_verdict import add_accept_option
from rigsim.rig.load import DEFAULT_RIG

__all__ = ["add_cli"]

FACES = ["+X", "-X", "+Y", "-Y", "+Z", "-Z"]


def add_cli(groups: dict) -> None:
    from rigsim.procedures.cube_mirror import null_files

    null_files.add_cli(groups)
    sub = groups["top"]
    cal = sub.add_parser("calibrate", help="calibrate a sensor from a user's logs and centroid tables")
    cs = cal.add_subparsers(dest="sensor", metavar="SENSOR")
    c = cs.add_parser(
        "sun-sensor", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        help="intrinsics, distortion and R(sun←rot) from a turntable sweep (seed 000 step 1 / 001 step B)",
        description="Least-squares calibration of the sun sensor from the turntable's angle log (frame, x_deg, y_deg"
                    "[, z_deg]) and a centroid table (frame, u_px, v_px[, spot, flags]; e.g. from `rigsim centroid`), "
                    "with the rig's nominal turntable and design focal length as the start.")
    c.add_argument("--rig", default=DEFAULT_RIG, help="rig file or default rig name (nominal values only)")
    c.add_argument("--angles", required=True, metavar="FILE", help="angle log: frame, x_deg, y_deg[, z_deg] (.csv/.parquet)")
    c.add_argument("--centroids", required=True, metavar="FILE", help="centroid table: frame, u_px, v_px[, spot, flags]")
    c.add_argument("--out", required=True, metavar="FILE", help="the calibration (.json); a residual plot is written beside it")
    c.add_argument("--axis-order", default=None, help="axis nesting, outermost first (default the rig's)")
    c.add_argument("--opencv", default=None, metavar="FILE", help="also write OpenCV's FileStorage camera (.yml/.json)")
    add_accept_option(c)
    c.set_defaults(func=cmd_calibrate_sun_sensor)
    declare(c, "out", suffixes=(".json",), derived=_residual_plot)
    declare(c, "opencv", suffixes=(".yml", ".yaml", ".json", ".xml"))

    t = sub.add_parser(
        "triad", formatter_class=argparse.RawDescriptionHelpFormatter,
        help="R(cube←rot) by TRIAD from the readings at two face nulls (2- or 3-axis table)",
        description="Dual-vector attitude of the mirror cube in the turntable frame from the readings at the two "
                    "face nulls: either θ1 θ2 θ3 θ4 in degrees (2-axis table, seed 000 Table 1), or --nulls FILE "
                    "(two rows: face, x_deg, y_deg[, z_deg]) with --rig for any table.",
        epilog="examples:\n  rigsim triad 181.398 0.528 91.386 -0.048\n"
               "  rigsim triad --nulls nulls.csv --rig sun_sensor_3axis_autocollimator --out cube.json")
    t.add_argument("angles_deg", nargs="*", type=real, metavar="θ", help="θ1 θ2 θ3 θ4 in degrees (θ1, θ3 about X'; θ2, θ4 about Y')")
    t.add_argument("--nulls", default=None, metavar="FILE", help="null log: face, x_deg, y_deg[, z_deg] (two rows)")
    t.add_argument("--rig", default=None, help="rig file or name: axes, faces, reading σ (default: 2-axis, +Z +Y)")
    t.add_argument("--axis-order", default=None, help="nesting reading, outermost first (2-axis: XY or YX; 3-axis: YXZ or XYZ)")
    t.add_argument("--faces", nargs=2, default=None, choices=FACES, help="faces nulled first and second (default the rig's, +Z +Y)")
    t.add_argument("--sigma-arcsec", type=number(1e-6, 3600), default=None, help="1σ of each reading (default: the rig's encoder ⊕ null accuracy)")
    t.add_argument("--eq8", default="beam", choices=["beam", "printed"],
                   help="reading of seed 000 eqs 7–8: 'beam' rotates the beam direction for both nulls (rigsim's); "
                        "'printed' rotates each face's own normal (degenerate; the conditioning is printed)")
    t.add_argument("--out", default=None, metavar="FILE", help="write R(cube←rot) and its covariance as JSON")
    t.add_argument("--json", action="store_true", help="also print the JSON result (last line)")
    add_accept_option(t)
    t.set_defaults(func=cmd_triad)
    declare(t, "out")

    m = sub.add_parser("compose", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
                       help="R(cube←sun) = R(cube←rot)·R(sun←rot)ᵀ with the propagated covariance",
                       description="Compose the results of `rigsim triad --out` and `rigsim calibrate sun-sensor`.")
    m.add_argument("--cube-from-rot", required=True, metavar="A.json", help="JSON with R_cube_from_rot (rigsim triad --out)")
    m.add_argument("--sun-from-rot", required=True, metavar="B.json", help="JSON with R_sun_from_rot (rigsim calibrate sun-sensor)")
    m.add_argument("--out", default=None, metavar="FILE", help="write R(cube←sun) and its covariance as JSON")
    add_accept_option(m)
    m.set_defaults(func=cmd_compose)
    declare(m, "out")


def _residual_plot(args) -> list:
    from rigsim.files.outputs import Output

    return [Output(Path(args.out).with_suffix(".residuals.png"), "--out's residual plot")] if args.out else []


def _print_rotation(name: str, blk: dict) -> None:
    np.set_printoptions(precision=9, suppress=True)
    print(f"{name} =\n{np.array(blk['matrix'])}")
    s = blk["covariance"]["sigma"]
    print(f"1σ of its small rotation about the target axes: ({s[0]:.3f}, {s[1]:.3f}, {s[2]:.3f})″")


def cmd_calibrate_sun_sensor(args) -> int:
    from rigsim.files import write_json
    from rigsim.procedures.cube_mirror import files as F
    from rigsim.procedures.cube_mirror.input_causes import SweepCauses
    from rigsim.procedures.fit_verdict import judge
    from rigsim.rig.load import load_rig

    rig = load_rig(args.rig)
    order = _axis_order(rig, args.axis_order)
    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise CliError(f"--out = {args.out}: expected a .json file name")
    t0 = time.perf_counter()
    tables = F.read_sweep_tables(rig, args.angles, args.centroids)
    cal, inputs, q = F.fit_sweep_tables(rig, tables, order)
    causes = SweepCauses(rig, tables, order)
    q = causes.outliers_explained(cal, q)
    verdict = judge(q, causes.alternatives(), accept=args.accept_poor_fit, what="sun-sensor calibration")
    if cal is None:
        raise PoorFitError(f"sun-sensor calibration: {q.describe()}; there is no calibration to write")
    res = F.sun_calibration_json(cal, rig, order, inputs, fit=verdict.block())
    res["inputs"] = {"angles": str(args.angles), "centroids": str(args.centroids)}
    write_json(out, res)
    plot = F.plot_residuals(cal, out.with_suffix(".residuals.png"))
    if args.opencv:
        F.write_opencv_camera(args.opencv, cal.camera, poor_fit=verdict.quality.poor)
    i = res["intrinsics"]
    print(f"sun-sensor calibration: {cal.n_points} frames ({len(inputs.rejected)} without a usable spot, "
          f"{len(cal.outliers)} outliers and {len(cal.outside_field)} beyond the field left out), "
          f"residual rms {cal.rms_px:.4f} px")
    for line in verdict.lines():
        print(line)
    print(f"fx {i['fx_px']:.3f} px, fy {i['fy_px']:.3f} px, principal point ({i['cx_px']:.3f}, {i['cy_px']:.3f}) px, "
          f"k1 {cal.camera.k1:+.3e}, k2 {cal.camera.k2:+.3e}")
    _print_rotation("R(sun←rot)", res["R_sun_from_rot"])
    print(f"→ {out}, {plot}" + (f", {args.opencv}" if args.opencv else ""))
    print(f"[{time.perf_counter() - t0:.2f} s]")
    return 0


def _axis_order(rig, order: str | None) -> str:
    from rigsim.procedures.cube_mirror.files import axis_orders
    from rigsim.procedures.cube_mirror.pipeline import default_axis_order

    allowed = axis_orders(rig)
    o = order or default_axis_order(rig)
    if o not in allowed:
        raise CliError(f"--axis-order = {o!r}: allowed for this {len(rig.turntable.axes)}-axis table: {', '.join(allowed)}")
    return o


def cmd_triad(args) -> int:
    from rigsim.estimation.cube_attitude import AXIS_ORDERS_2AXIS
    from rigsim.files import write_json
    from rigsim.frames import ARCSEC_PER_RAD, angle_between, rotation_angle
    from rigsim.procedures.cube_mirror import files as F
    from rigsim.rig.load import load_rig
    from rigsim.rig.turntable import TurntableReading

    rig = load_rig(args.rig or DEFAULT_RIG)
    if args.nulls is not None:
        if args.angles_deg:
            raise CliError("give either θ1 θ2 θ3 θ4 or --nulls FILE, not both")
        faces, readings = F.read_nulls(args.nulls, rig)
        if args.faces and list(args.faces) != faces:
            raise CliError(f"--faces {' '.join(args.faces)}: the null log {args.nulls} names {' '.join(faces)}")
    else:
        if len(args.angles_deg) != 4:
            raise CliError(f"{len(args.angles_deg)} angles given; expected θ1 θ2 θ3 θ4 (degrees) or --nulls FILE")
        if len(rig.turntable.axes) != 2:
            raise CliError("θ1..θ4 are for a 2-axis table; give a 3-axis table's readings with --nulls FILE")
        for name, v in zip(("θ1", "θ2", "θ3", "θ4"), args.angles_deg):
            if not -360.0 <= v <= 360.0:
                raise CliError(f"{name} = {v}: allowed range is -360 to 360 degrees")
        t1, t2, t3, t4 = np.radians(args.angles_deg)
        readings = [TurntableReading({"X": t1, "Y": t2}), TurntableReading({"X": t3, "Y": t4})]
        faces = list(args.faces or ["+Z", "+Y"])
    faces = list(args.faces or faces)
    if faces[0] == faces[1] or faces[0][1] == faces[1][1]:
        raise CliError(f"--faces {' '.join(faces)}: expected two non-parallel faces")
    order = _axis_order(rig, args.axis_order if args.axis_order or args.nulls else "XY" if len(rig.turntable.axes) == 2 else None)
    if args.sigma_arcsec is not None:
        if not (np.isfinite(args.sigma_arcsec) and 0.0 <= args.sigma_arcsec <= 3600.0):
            raise CliError(f"--sigma-arcsec = {args.sigma_arcsec}: allowed 0 to 3600")
        sigma = {a.label: args.sigma_arcsec / ARCSEC_PER_RAD for a in rig.turntable.axes}
    else:
        sigma = F.reading_sigma_rad(rig)
    _refuse_parallel_normals(readings, faces, order, args)
    verdict = _judge_triad(rig, readings, faces, order, sigma, args.accept_poor_fit,
                           None if args.nulls is not None else {"X": "θ1, θ3", "Y": "θ2, θ4"})
    try:
        R, C = F.triad_with_covariance(readings, faces, order, sigma, eq8=args.eq8)
    except ValueError as exc:  # parallel normals: no attitude at all
        raise PoorFitError(f"TRIAD: {exc}; there is no rotation to write") from None
    res = F.triad_json(R, C * verdict.covariance_scale, faces, order, readings, sigma, rig.name, eq8=args.eq8)
    res["fit"] = verdict.block()
    from rigsim.estimation.cube_attitude import EQ8_READINGS, cube_from_rot_triad
    from rigsim.estimation.triad import triad_conditioning
    from rigsim.optics.cube import FACE_NORMALS

    _, r1, r2 = cube_from_rot_triad(readings, faces, order, eq8=args.eq8)
    ang = np.degrees(angle_between(r1, r2))
    res["normal_angle_deg"] = float(ang)
    cond = triad_conditioning(FACE_NORMALS[faces[0]], FACE_NORMALS[faces[1]], r1, r2)
    res["triad_conditioning"] = cond
    if args.out:
        write_json(args.out, res)
    print(f"R(cube←rot) by TRIAD, faces n1={faces[0]} n2={faces[1]} (cube frame), axis order {order}"
          + (f" — {AXIS_ORDERS_2AXIS[order]}" if order in AXIS_ORDERS_2AXIS else ""))
    if args.eq8 == "beam":
        print("normals r = R_rot_from_mount(θ)ᵀ·d with d = (0,0,1), the beam direction (towards the source)")
    else:
        print(f"eq 8 reading 'printed': {EQ8_READINGS['printed']}")
    for f, r in zip(faces, readings):
        print(f"  {f}: " + ", ".join(f"{k}={np.degrees(v):.6f}°" for k, v in r.items()))
    _print_rotation("R(cube←rot)", res["R_cube_from_rot"])
    for line in verdict.lines():
        print(line)
    print(f"angle between the two measured normals: {ang:.5f}° (a perfect cube: 90°; deviation {(ang - 90) * 3600:+.1f}″)")
    if cond["degenerate"]:
        print(f"DEGENERATE: r1 and r2 are {cond['angle_r_deg']:.3f}° apart while the faces are {cond['angle_n_deg']:.1f}° "
              f"apart (inconsistency {cond['inconsistency_deg']:+.2f}°); the rotation about r1 rests on a vector "
              f"{cond['angle_r_deg']:.3f}° from it: reading errors are amplified ×{cond['amplification']:.0f}. "
              "This result is not a measurement of the cube.")
    if args.eq8 != "beam":
        Rb, _, _ = cube_from_rot_triad(readings, faces, order)
        print(f"rigsim's reading (beam) differs by {np.degrees(rotation_angle(R, Rb)):.4f}°")
    others = [o for o in F.axis_orders(rig) if o != order]
    for o in others:
        R2, _, _ = cube_from_rot_triad(readings, faces, o, eq8=args.eq8)
        print(f"the other reading ({o}) differs by {np.degrees(rotation_angle(R, R2)):.4f}°")
    if args.out:
        print(f"→ {args.out}")
    if args.json:
        print(json.dumps(res))
    return 0


def _judge_triad(rig, readings, faces, order, sigma, accept, cols=None):
    """The verdict of TRIAD on the null readings (:func:`~rigsim.procedures.cube_mirror.files.triad_fit_quality`),
    with the null log's readings read other ways as the causes."""
    from rigsim.procedures.cube_mirror import files as F
    from rigsim.procedures.cube_mirror.input_causes import null_alternatives
    from rigsim.procedures.fit_verdict import judge
    from rigsim.rig.turntable import TurntableReading

    def quality(rr, o=None):
        return F.triad_fit_quality([TurntableReading(r) for r in rr], faces, o or order, sigma)

    alts = null_alternatives([a.label for a in rig.turntable.axes], [dict(r) for r in readings], quality,
                             [o for o in F.axis_orders(rig) if o != order], cols)
    return judge(quality([dict(r) for r in readings]), alts, accept=accept, what="TRIAD")


def _refuse_parallel_normals(readings, faces, order, args) -> None:
    """The two nulls must give two distinct measured normals: equal readings (the same null twice) leave TRIAD
    without a second direction."""
    from rigsim.estimation.cube_attitude import cube_from_rot_triad
    from rigsim.frames import angle_between

    try:
        _, r1, r2 = cube_from_rot_triad(readings, faces, order, eq8=args.eq8)
        ang = float(np.degrees(angle_between(r1, r2)))
    except ValueError:
        ang = 0.0
    if not ang > 0.5:
        where = args.nulls if args.nulls is not None else "θ1 θ2 θ3 θ4"
        raise CliError(f"{where}: the two nulls give measured normals {ang:.3g}° apart; expected two faces' nulls "
                       "(about 90° apart): is the same null listed twice?")


def cmd_compose(args) -> int:
    from rigsim.files import write_json
    from rigsim.procedures.cube_mirror.files import compose_with_verdict

    res, verdict = compose_with_verdict(args.cube_from_rot, args.sun_from_rot, accept_poor_fit=args.accept_poor_fit)
    _print_rotation("R(cube←sun) = R(cube←rot)·R(sun←rot)ᵀ", res["R_cube_from_sun"])
    for line in verdict.lines():
        print(line)
    if args.out:
        write_json(args.out, res)
        print(f"→ {args.out}")
    return 0
