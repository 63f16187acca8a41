"""``rigsim render boresight-roi``: one CMOS ROI of the laser spot of a line-array camera at a camera
state (α, β, γ, Δf), with its truth and the ROI's centroid beside the exact spot."""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

from rigsim.errors import CliError
from rigsim.files.names import file_stem, slug
from rigsim.files.options import SEED, SPP, number

__all__ = ["add_cli"]

_LIMITS = {"alpha": 3600.0, "beta": 3600.0, "gamma": 3600.0, "df_um": 1000.0}


def add_cli(groups: dict) -> None:
    p = groups["render"].add_parser(
        "boresight-roi", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        help="a CMOS ROI of a line-array camera's laser spot at a camera state (seed 003)",
        description="Render the ROI of one CMOS (M1 or M2) of one camera of the dual line-array rig: the laser spot "
                    "returned through the central prism, for the camera rotated by (alpha, beta, gamma) and its focal "
                    "length changed by df. Writes NAME.png (16-bit ROI) + NAME.json (truth: the exact spot centre "
                    "in detector pixels, the ROI origin). The ROI follows the spot, as the orbit scenario's does.")
    p.add_argument("--rig", default="dual_line_array_prism", help="seed-003 rig file (path or default name)")
    p.add_argument("--camera", default=None, help="camera name (default the rig's first)")
    p.add_argument("--detector", default="M1", choices=("M1", "M2"), help="which CMOS")
    p.add_argument("--alpha", type=number(-3600, 3600), default=0.0, help="rotation about x (arcsec)")
    p.add_argument("--beta", type=number(-3600, 3600), default=0.0, help="rotation about y (arcsec)")
    p.add_argument("--gamma", type=number(-3600, 3600), default=0.0, help="rotation about z (arcsec)")
    p.add_argument("--df-um", type=number(-10_000, 10_000), default=0.0, help="focal-length change (µm)")
    p.add_argument("--spp", type=SPP, default=None, help="light paths per ROI pixel (default: the rig's orbit.spp)")
    p.add_argument("--seed", type=SEED, default=0, help="frame seed (same seed, same frame)")
    p.add_argument("--noiseless", action="store_true", help="detector without random noise")
    p.add_argument("--out", default="renders/frames", help="output folder")
    p.add_argument("--name", type=file_stem, default=None, help="file stem (default boresight_<camera>_<detector>)")
    p.set_defaults(func=cmd_render_boresight_roi)
    from rigsim.files.outputs import declare

    declare(p, "out", folder=True)


def cmd_render_boresight_roi(args) -> int:
    from rigsim.imaging import NoiseModel
    from rigsim.imaging.rois import centroid_rois
    from rigsim.optics.line_camera import rotation_xyz
    from rigsim.render.boresight import LoopRenderer
    from rigsim.rig.load import load_boresight_rig

    for k, v in (("alpha", args.alpha), ("beta", args.beta), ("gamma", args.gamma), ("df_um", args.df_um)):
        lim = _LIMITS[k]
        if not (math.isfinite(v) and -lim <= v <= lim):
            unit = "µm" if k == "df_um" else "arcsec"
            raise CliError(f"--{k.replace('_', '-')} = {v}: allowed -{lim:g} to {lim:g} {unit}")
    if not 0 <= args.seed < 2**63:
        raise CliError(f"--seed = {args.seed}: allowed 0 to 2^63 - 1")
    if args.spp is not None and not 1 <= args.spp <= 65536:
        raise CliError(f"--spp = {args.spp}: allowed 1 to 65536")
    rig = load_boresight_rig(args.rig)
    names = [c.name for c in rig.cameras]
    cam = args.camera or names[0]
    if cam not in names:
        raise CliError(f"--camera = {cam!r}: this rig ({rig.name}) has cameras {', '.join(names)}")
    j = 0 if args.detector == "M1" else 1
    t0 = time.perf_counter()
    r = LoopRenderer(rig, cam, j, spp=args.spp, follow=True)
    E = rotation_xyz(*(math.radians(a / 3600.0) for a in (args.alpha, args.beta, args.gamma)))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fr = r.render(E, args.df_um * 1e-3, seed=int(args.seed), noiseless=args.noiseless)
    seconds = time.perf_counter() - t0
    name = args.name or slug(f"boresight_{cam}_{args.detector.lower()}")  # camera names come from the rig file
    png, js = fr.write(Path(args.out) / name)
    uv = fr.truth.get("spot_uv")
    o = fr.origin_uv
    print(f"wrote {png} and {js} in {seconds:.2f} s (camera {cam} {args.detector}, α {args.alpha:g}″ β {args.beta:g}″ "
          f"γ {args.gamma:g}″, Δf {args.df_um:g} µm; ROI {fr.dn.shape[1]}×{fr.dn.shape[0]} px at detector ({o[0]}, {o[1]}))")
    for w in caught:
        print(f"warning: {w.message}")
    if uv is None or fr.flags.get("spot_off_detector"):
        print("the spot is off the detector: nothing to measure")
        return 0
    print(f"exact spot centre: u {uv[0]:.4f} px, v {uv[1]:.4f} px (detector pixels)")
    m = centroid_rois(fr.dn, [o], method="tcom", noise=NoiseModel.from_detector(rig.detector))
    if not m.valid.all():
        print("measured: no usable spot in the ROI")
    else:
        du, dv = m.uv[0][0] - uv[0], m.uv[0][1] - uv[1]
        print(f"measured (rigsim boresight centroid, tcom): u {m.uv[0][0]:.4f} px, v {m.uv[0][1]:.4f} px "
              f"(error {du:+.4f}, {dv:+.4f} px)")
    return 0
