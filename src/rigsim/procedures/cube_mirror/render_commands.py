"""The cube-mirror rigs' other frames from the command line, as the campaign renders them:
``rigsim render aiming-camera`` (the hole frame and the spot frame of a pose, divergent beam) and
``rigsim render autocollimator`` (one autocollimator frame). Each frame is a 16-bit PNG with its
sidecar (truth and render settings); the command prints the truth beside what the file stages
measure on the frames."""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

import numpy as np

from rigsim.errors import CliError
from rigsim.files.names import file_stem
from rigsim.files.options import SEED, SPP
from rigsim.files.outputs import declare
from rigsim.rig.load import DEFAULT_RIG

__all__ = ["add_cli"]


def _common(p, default_rig: str, name: str) -> None:
    p.add_argument("--rig", default=default_rig, help="rig file path or default rig name")
    p.add_argument("--face", default=None, help="the face the beam returns from (default the procedure's first)")
    p.add_argument("--pose", default=None, help="true turntable angles in degrees, e.g. X=181.4,Y=0.55 "
                                                "(default: the face's search start)")
    p.add_argument("--seed", type=SEED, default=0, help="frame seed (same seed, same frames)")
    p.add_argument("--noiseless", action="store_true", help="detector without random noise")
    p.add_argument("--ideal", action="store_true", help="rig without its true errors")
    p.add_argument("--out", default="renders/frames", help="output folder")
    p.add_argument("--name", type=file_stem, default=name, help="file stem of the frame(s)")
    declare(p, "out", folder=True)


def add_cli(groups: dict) -> None:
    rds = groups["render"]
    a = rds.add_parser("aiming-camera", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
                       help="the aiming camera's hole and spot frames of the diaphragm screen (seed 000)",
                       description="Render the aiming camera's two frames at a true turntable pose exactly as the "
                                   "campaign does: the lit hole with the return blocked, and the returned divergent "
                                   "spot beside it. Writes NAME_hole.png and NAME_spot.png with their sidecars.")
    _common(a, DEFAULT_RIG, "aiming_camera")
    a.add_argument("--spp", type=SPP, default=4, help="pencil samples per pixel of the screen renderer")
    a.add_argument("--beam", choices=("divergent", "collimated"), default="divergent",
                   help="the sun simulator's beam: divergent (its full collimation angle, as the campaign renders "
                        "it) or one collimated pencil (near the null its return falls back into the hole)")
    a.set_defaults(func=cmd_render_aiming_camera)
    c = rds.add_parser("autocollimator", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
                       help="the autocollimator's frame of a cube face (seed 001)",
                       description="Render the autocollimator's frame of a cube face at a true turntable pose as the "
                                   "campaign does (its axis along the nominal beam). Writes NAME.png and its sidecar.")
    _common(c, "sun_sensor_3axis_autocollimator", "autocollimator")
    c.add_argument("--spp", type=SPP, default=1024, help="samples per pixel of the window")
    c.set_defaults(func=cmd_render_autocollimator)


def _setup(args, method: str):
    from rigsim.procedures.cube_mirror.null_files import parse_reading
    from rigsim.rig import load_rig
    from rigsim.truth.cube_mirror.realization import realization_from_rig

    rig = load_rig(args.rig)
    if rig.procedure.method != method:
        raise CliError(f"--rig {args.rig}: its procedure uses the {rig.procedure.method}; this frame needs the "
                       f"{method} (seed {'000' if method == 'diaphragm' else '001'})")
    faces = list(rig.procedure.faces)
    face = args.face or faces[0]
    if face not in faces:
        raise CliError(f"--face = {face!r}: the procedure's faces are {', '.join(faces)}")
    if args.seed < 0 or args.seed >= 2**63:
        raise CliError(f"--seed = {args.seed}: allowed 0 to 2^63 - 1")
    if not 1 <= args.spp <= 65536:
        raise CliError(f"--spp = {args.spp}: allowed 1 to 65536")
    pose_rad = parse_reading(args.pose, rig, faces.index(face), "--pose", every_axis=False)
    return rig, realization_from_rig(rig, ideal=args.ideal), faces.index(face), face, pose_rad


def cmd_render_aiming_camera(args) -> int:
    from rigsim.procedures.cube_mirror.null_files import measure_concentricity
    from rigsim.render.cube_mirror.aiming import ConcentricityRenderer
    from rigsim.render.cube_mirror.diaphragm import DiaphragmRenderer

    rig, real, fi, face, pose = _setup(args, "diaphragm")
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if args.beam == "divergent":
            r = ConcentricityRenderer(rig, real, fi, spp=args.spp)
            fr = r.render(pose, seed=args.seed, hole_seed=args.seed, noiseless=args.noiseless, warn=False)
        else:
            r = DiaphragmRenderer(rig, real, fi, spp=args.spp, beam="collimated")
            fr = r.render(pose, seed=args.seed, noiseless=args.noiseless)
    seconds = time.perf_counter() - t0
    out = Path(args.out)
    paths = [fr.hole.write(out / f"{args.name}_hole")[0], fr.spot.write(out / f"{args.name}_spot")[0]]
    bad = [k for k in ("beam_misses_face", "spot_not_returned", "spot_off_detector", "spot_cut_by_edge",
                       "hole_off_detector", "saturated") if fr.flags.get(k)]
    ex = np.asarray(fr.truth.offset_mm, float) / rig.aiming_camera.object_pixel_mm
    print(f"wrote {paths[0]} and {paths[1]} (16-bit DN, with sidecars; {args.beam} beam) in {seconds:.2f} s (face {face}, "
          + ", ".join(f"{k}={math.degrees(v):.4f}°" for k, v in pose.items()) + ")")
    print(f"true offset spot − hole: x {ex[0]:+.3f} px, y {ex[1]:+.3f} px")
    if bad:
        print(f"flags: {', '.join(bad)}")
    else:
        m = measure_concentricity(rig, fr.hole.dn, fr.spot.dn)
        print(f"measured (rigsim concentricity): x {m['offset_px'][0]:+.3f} px, y {m['offset_px'][1]:+.3f} px")
        if fr.flags.get("spot_overlaps_hole") and np.hypot(*ex) > 1.0:
            print("note: the spot overlaps the hole; the light that falls back into it is lost, which pulls the "
                  "spot's centroid away from the hole (physics, zero at concentricity: the null search converges "
                  "there)")
    return 0


def cmd_render_autocollimator(args) -> int:
    from rigsim.procedures.cube_mirror.autocollimation import FaceReadingMeasurer
    from rigsim.procedures.cube_mirror.null_files import read_autocollimator
    from rigsim.rig.turntable import NOMINAL_D

    rig, real, _, face, pose = _setup(args, "autocollimator")
    t0 = time.perf_counter()
    f = FaceReadingMeasurer(rig, real, face, NOMINAL_D, spp=args.spp)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fr = f.renderer.render_frame(pose, seed=args.seed, noiseless=args.noiseless)
    seconds = time.perf_counter() - t0
    png, js = fr.write(Path(args.out) / args.name)
    ex = f.exact_rad(pose) * 180.0 / math.pi * 3600.0
    print(f"wrote {png} and {js} in {seconds:.2f} s (face {face}, "
          + ", ".join(f"{k}={math.degrees(v):.4f}°" for k, v in pose.items()) + ")")
    print(f"exact reading: θx {ex[0]:+.4f}″, θy {ex[1]:+.4f}″")
    m, sig, sm = read_autocollimator(rig, fr.dn, f.optics)
    print(f"measured (rigsim autocollimator read): θx {m[0]:+.4f}″ ± {sig[0]:.4f}″, θy {m[1]:+.4f}″ ± {sig[1]:.4f}″"
          if sm.ok else f"not measurable: {sm.problem}")
    return 0
