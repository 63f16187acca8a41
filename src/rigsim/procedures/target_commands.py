"""``rigsim render target``: a user's calibration target (chessboard, circle grid or image) through a
rig's true camera, one 16-bit frame per pose with its sidecar, and ``points.csv`` with the exact pixel
of every target point in every frame (:mod:`rigsim.render.target`, :mod:`rigsim.optics.targets`)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from rigsim.errors import CliError
from rigsim.files import write_json, write_table
from rigsim.files.atomic import output_folder
from rigsim.files.options import SEED, SPP, integer, number
from rigsim.files.outputs import Output, declare
from rigsim.optics.targets import TARGET_SPECS, PlanarTarget, TargetPoses, parse_target, read_poses, spread_poses, write_poses
from rigsim.rig.load import DEFAULT_RIG

__all__ = ["POINT_COLUMNS", "add_cli", "render_target_frames", "spread_for_camera"]

POINT_COLUMNS = ("frame", "point", "x_mm", "y_mm", "u_px", "v_px", "visible")


def render_target_frames(rig, target: PlanarTarget, poses: TargetPoses, out, *, camera: str | None = None,
                         spp: int = 16, seed: int = 0, noiseless: bool = False, white_fraction: float = 0.6,
                         progress=None) -> dict:
    """Render ``target`` at every pose through ``rig``'s true ``camera`` into folder ``out``:
    ``<frame>.png`` + ``<frame>.json`` per pose, ``points.csv`` (:data:`POINT_COLUMNS`) and
    ``target.json``. Frame k's seed is ``seed + k``. Returns a summary (paths, seconds per frame)."""
    from rigsim.render.target import TargetScene, true_camera

    if not 0 <= seed < 2**62:
        raise CliError(f"--seed = {seed}: allowed 0 to 2^62 - 1")
    name, cam, det = true_camera(rig, camera)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out = {out}: a file, not a folder")
    if "target" in poses.frames:
        raise CliError("frame name 'target': its sidecar would overwrite target.json; rename the frame")
    output_folder(out)
    t0 = time.perf_counter()
    scene = TargetScene(cam, target, det, spp=spp, white_fraction=white_fraction)
    cols: dict[str, list] = {k: [] for k in POINT_COLUMNS}
    frames, per_frame, visible = [], [], []
    for k, fname in enumerate(poses.frames):
        t1 = time.perf_counter()
        fr = scene.render(poses.rvec_deg[k], poses.tvec_mm[k], seed=seed + k, noiseless=noiseless, frame=fname)
        png, _ = fr.write(out / fname)
        frames.append(png)
        pts = fr.truth["points"]
        n = len(pts["x_mm"])
        cols["frame"] += [png.name] * n
        cols["point"] += list(range(n))
        for key in ("x_mm", "y_mm", "u_px", "v_px"):
            cols[key] += [np.nan if v is None else float(v) for v in pts[key]]
        cols["visible"] += [int(bool(v)) for v in pts["visible"]]
        visible.append(int(np.sum(pts["visible"])))
        per_frame.append(time.perf_counter() - t1)
        if progress is not None:
            progress(1)
    points = write_table(out / "points.csv", cols)
    info = write_json(out / "target.json", {
        "format": "rigsim.target/1", "target": target.spec, "kind": target.kind,
        "pattern_size": list(target.pattern_size) if target.pattern_size else None,
        "size_mm": list(target.size_mm), "points_mm": target.points_mm, "rig": rig.name, "camera": name,
        "camera_true": cam.as_dict(), "frames": [p.name for p in frames], "seed": seed, "spp": spp,
        "conventions": {"pose": "p_cam = R(rvec) p_target + tvec (OpenCV), rvec in degrees, tvec in mm",
                        "target_frame": "z = 0 plane, x along a row of points, y down, origin at point 0, "
                                        "printed side towards -z",
                        "pixels": "pixel (0,0) centre at (u, v) = (0, 0), img[v, u]"}})
    return {"frames": frames, "points": points, "target_json": info, "camera": name,
            "seconds": time.perf_counter() - t0, "seconds_per_frame": per_frame,
            "visible_points": int(np.sum(cols["visible"])), "visible_per_frame": visible, "points_total": len(cols["visible"])}


def spread_for_camera(rig, target: PlanarTarget, n: int, *, camera: str | None = None, seed: int = 0) -> TargetPoses:
    """``n`` calibration poses for ``rig``'s ``camera``: centres out to 70 % of the half field (the
    narrower axis), boards at distances where they span 35 to 60 % of the detector width."""
    from rigsim.render.target import true_camera

    if not 1 <= n <= 10000:
        raise CliError(f"--spread = {n}: allowed 1 to 10000 poses")
    _, cam, _ = true_camera(rig, camera)
    half = min(np.arctan2(cam.width / 2, cam.fx), np.arctan2(cam.height / 2, cam.fy))
    w = max(target.size_mm)
    far, near = cam.fx * w / (0.35 * cam.width), cam.fx * w / (0.60 * cam.width)
    return spread_poses(target, n, distance_mm=(near, far), field_deg=float(np.degrees(0.7 * half)), seed=seed)


def add_cli(groups: dict) -> None:
    rds = groups["render"]
    p = rds.add_parser(
        "target", formatter_class=argparse.RawDescriptionHelpFormatter,
        help="a calibration target (chessboard, circle grid, image) through a rig's true camera",
        description="Render a planar target at each pose of a table through the rig's true camera (intrinsics,\n"
                    "distortion, detector). Writes FRAME.png (16-bit) + FRAME.json (truth) per pose, points.csv\n"
                    "(frame, point, x_mm, y_mm, u_px, v_px, visible: the exact pixel of every target point) and\n"
                    "target.json (the target, its points and the true camera).",
        epilog="targets:\n"
               "  chessboard:COLSxROWS:SQUARE_MM     COLS x ROWS squares; points = inner corners row by row,\n"
               "                                     OpenCV patternSize = (COLS-1, ROWS-1); top-left square black\n"
               "  circles:COLSxROWS:PITCH_MM:DIAM_MM symmetric grid of black disks; points = centres,\n"
               "                                     patternSize = (COLS, ROWS)\n"
               "  image:PATH:WIDTH_MM                an 8/16-bit grey image printed WIDTH_MM wide; points = its corners\n"
               "poses table (.csv/.parquet), one row per frame:\n"
               "  frame, rx_deg, ry_deg, rz_deg, tx_mm, ty_mm, tz_mm\n"
               "  the target's pose in the camera frame as OpenCV's rvec (degrees) and tvec (mm):\n"
               "  p_cam = R(rvec) p_target + tvec; target frame: z = 0 plane, x along a row of points,\n"
               "  y down, origin at point 0. Pixels: pixel (0,0) centre at (0,0).\n"
               "examples:\n"
               "  rigsim render target --target chessboard:10x7:20 --poses poses.csv --out renders/board\n"
               "  rigsim render target --target circles:7x5:25:12 --spread 12 --camera aiming-camera --out renders/grid")
    p.add_argument("--rig", default=DEFAULT_RIG, help=f"rig file path or default rig name (default {DEFAULT_RIG})")
    p.add_argument("--camera", default=None, help="sun-sensor or aiming-camera (cube-mirror rigs), star-sensor "
                                                  "(star rigs); default the rig's main camera")
    p.add_argument("--target", required=True, metavar="SPEC", help=TARGET_SPECS)
    pg = p.add_mutually_exclusive_group(required=True)
    pg.add_argument("--poses", metavar="TABLE", help="poses table (.csv or .parquet)")
    pg.add_argument("--spread", type=integer(1, 10_000), metavar="N",
                    help="N calibration poses spread over the camera's field instead (written to DIR/poses.csv): "
                         "board centres on a spiral out to 70%% of the half field, tilted up to 25°, at distances "
                         "where the board spans 35-60%% of the detector width (--seed draws them)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--spp", type=SPP, default=16, help="samples per pixel, a power of 4 (default 16)")
    p.add_argument("--seed", type=SEED, default=0, help="seed of frame 0; frame k uses seed + k (default 0)")
    p.add_argument("--noiseless", action="store_true", help="detector without random noise")
    p.add_argument("--white-fraction", type=number(1e-3, 1), default=0.6,
                   help="white's signal on axis as a fraction of the usable full well (default 0.6)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_render_target)
    declare(p, "out", folder=True, derived=lambda a: [Output(Path(a.out) / n, f"--out's {n}") for n in
                                                      ("points.csv", "target.json", *(("poses.csv",) if a.spread else ()))])


def cmd_render_target(args) -> int:
    from tqdm import tqdm

    from rigsim.rig.load import load_any_rig

    rig = load_any_rig(args.rig)
    target = parse_target(args.target)
    if args.poses is not None:
        poses = read_poses(args.poses, target)
    else:
        poses = spread_for_camera(rig, target, args.spread, camera=args.camera, seed=args.seed)
        output_folder(Path(args.out), "--out")
        print(f"wrote {write_poses(Path(args.out) / 'poses.csv', poses)}: {len(poses)} poses spread over the field")
    with tqdm(total=len(poses), desc="target", unit="frame", disable=True if args.quiet else None) as pb:
        s = render_target_frames(rig, target, poses, args.out, camera=args.camera, spp=args.spp, seed=args.seed,
                                 noiseless=args.noiseless, white_fraction=args.white_fraction, progress=pb.update)
    sp = np.asarray(s["seconds_per_frame"])
    cut = [p.name for p, n in zip(s["frames"], s["visible_per_frame"]) if n < len(target.points_mm)]
    print(f"{target.describe()}")
    print(f"wrote {len(s['frames'])} frames ({rig.name}, {s['camera']}, {args.spp} spp) to {args.out} in "
          f"{s['seconds']:.1f} s ({sp.mean():.2f} s per frame)")
    print(f"{s['points']}: {s['points_total']} points, {s['visible_points']} visible on the detector")
    if cut:
        print(f"frames with points off the detector or out of view: {', '.join(cut)}")
    return 0
