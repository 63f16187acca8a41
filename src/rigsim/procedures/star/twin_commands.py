"""``rigsim star twin``: render the twin of a real star camera from its frames and its calibration,
and compare twin with real (rigsim.procedures.star.twin; docs/real-frames.md)."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
import sys
import time
from pathlib import Path

import numpy as np

from rigsim.errors import CliError, InputError
from rigsim.files.options import SEED

__all__ = ["add_cli", "cmd_star_twin"]


def add_cli(star_actions) -> None:
    c = star_actions.add_parser(
        "twin", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        help="render a real camera's twin from its frames and their calibration, and compare the two",
        description="Measure the real frames (gain, vignetting, each frame's sky and glow, photometric zero point, PSF), "
                    "render each frame's twin with rigsim's star renderer at its solved attitude through the calibrated "
                    "camera, run the same pipeline on both and compare: identified stars per magnitude bin, PSF FWHM "
                    "across the field, the sky's level and radial profile, the sky noise, the identification rate and "
                    "the centroid scatter. Writes the twin frames, twin.json, twin.md and the figures into --out.")
    c.add_argument("frames", nargs="+", metavar="FRAME", help="the real frames (those `rigsim star calibrate` read)")
    c.add_argument("--rig", required=True, help="the star rig the frames were calibrated with (the camera's design)")
    c.add_argument("--calibration", required=True, metavar="JSON", help="calibration.json of `rigsim star calibrate`")
    c.add_argument("--out", required=True, metavar="DIR", help="output folder")
    c.add_argument("--seed", type=SEED, default=0, help="seed of the twin's detector noise (frame k takes seed + k)")
    c.set_defaults(func=cmd_star_twin)
    from rigsim.files.outputs import declare

    declare(c, "out", folder=True)


def _calibration(path, names):
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not a readable calibration JSON ({exc})") from None
    j = data.get("joint") if isinstance(data, dict) else None
    if not j or not isinstance(j.get("theta"), list) or len(j["theta"]) != 5:
        raise InputError(f"{path}: no joint fit (field joint.theta); write it with `rigsim star calibrate`")
    att = {a.get("frame"): a for a in data.get("attitudes", []) if isinstance(a, dict)}
    R = []
    for n in names:
        a = att.get(n)
        if a is None or "R_cam_from_icrs_joint" not in a:
            raise InputError(f"{path}: frame {n!r} has no solved attitude (attitudes[].R_cam_from_icrs_joint); only "
                             "frames the calibration identified can have a twin")
        R.append(np.array(a["R_cam_from_icrs_joint"]["matrix"], float))
    ident = data.get("identification", {})
    rate = ident.get("frames_identified", 0) / max(ident.get("frames", 1), 1)
    return j, R, rate, float(j.get("residual_rms_px", float("nan")))


def cmd_star_twin(args) -> int:
    from rigsim.files import read_image, write_image, write_json
    from rigsim.files.atomic import atomic_write_bytes
    from rigsim.optics.sky import SkyCatalogue
    from rigsim.procedures.star.pipeline import StarObservation, StarPipeline
    from rigsim.procedures.star.twin import (compare, describe_camera, fit_faint_density, frame_stats, render_twin,
                                             twin_rig)
    from rigsim.procedures.star.twin_report import frames_figure, profiles_figure, table_markdown
    from rigsim.rig.load import load_star_rig

    t0 = time.perf_counter()
    rig = load_star_rig(args.rig)
    nominal = rig.nominal_rig()
    names = [Path(p).name for p in args.frames]
    if len(set(names)) != len(names):
        raise CliError("two frames share a file name: the calibration names frames by file name")
    j, Rs, rate_real, scatter_real = _calibration(args.calibration, names)
    W, H = rig.sensor.resolution_px
    images = [read_image(p, shape=(H, W), what="star frame") for p in args.frames]
    f, u0, v0, k1, k2 = j["theta"]
    camera = nominal.sensor.camera(f_px=f, principal_point_px=(u0, v0), k1=k1, k2=k2)
    sat = float(rig.sensor.detector.saturation_dn) if hasattr(rig.sensor.detector, "saturation_dn") else 65535.0
    sky = SkyCatalogue.load(max(10.0, rig.sky.magnitude_limit), rig.sky.epoch_year)
    print(f"measuring {len(images)} real frames …", file=sys.stderr)
    desc = describe_camera(images, camera, Rs, sky, psf_sigma_px=nominal.sensor.psf_sigma_px, saturation=sat)
    out = Path(args.out)
    stats_kw = {"psf_sigma_px": desc.psf_sigma_px, "gain": desc.gain_dn_per_e, "saturation": sat}
    real_s = [frame_stats(im, camera, R, sky, **stats_kw) for im, R in zip(images, Rs)]

    def render_all(density):
        d = replace(desc, faint_density_per_deg2_per_mag=float(density))
        return [render_twin(twin_rig(rig, d, camera, k), R, seed=int(args.seed) + k) for k, R in enumerate(Rs)]

    def unidentified(density):
        st = [frame_stats(im, camera, R, sky, **stats_kw) for im, R in zip(render_all(density), Rs)]
        return sum(s.n_detected - s.n_identified for s in st)

    # the stars beyond the catalogue: as many detections without a catalogue star as the real frames have
    desc = replace(desc, faint_density_per_deg2_per_mag=fit_faint_density(
        unidentified, sum(s.n_detected - s.n_identified for s in real_s)))
    twins = render_all(desc.faint_density_per_deg2_per_mag)
    for name, dn in zip(names, twins):
        write_image(out / "frames" / f"twin_{Path(name).stem}.tiff", dn)
    print(f"rendered {len(twins)} twin frames → {out / 'frames'}", file=sys.stderr)
    twin_s = [frame_stats(im, camera, R, sky, **stats_kw) for im, R in zip(twins, Rs)]
    # the pipeline on the twin frames, as on the real ones (frames alone, the same rig)
    pipe = StarPipeline(nominal, SkyCatalogue.load(nominal.sky.magnitude_limit, nominal.sky.epoch_year),
                        identification="lost-in-space")
    for k, dn in enumerate(twins):
        pipe.add(StarObservation(k, float(k), dn, None))
    ok = [i.ok for i in pipe.ident]
    rate_twin = float(np.mean(ok))
    scatter_twin = float("nan")
    if any(ok):
        tw = pipe.calibrate()
        scatter_twin = float(tw.joint.bundle.residual_rms_px) if tw.joint is not None else float("nan")
    rows = compare(real_s, twin_s, ident_real=rate_real, ident_twin=rate_twin, scatter_real=scatter_real,
                   scatter_twin=scatter_twin)
    figs = {"frames": frames_figure(out / "frames.png", names, images, twins, bin_px=2),
            "frames_crop": frames_figure(out / "frames_crop.png", names, images, twins,
                                         crop=(H // 2 - 96, H // 2 + 96, W // 2 - 128, W // 2 + 128)),
            "profiles": profiles_figure(out / "profiles.png", real_s, twin_s)}
    within = sum(r["within"] for r in rows)
    write_json(out / "twin.json", {"format": "rigsim.star-twin/1", "frames": names, "calibration": str(args.calibration),
                                   "description": desc.as_dict(), "comparison": rows,
                                   "real": [s.__dict__ for s in real_s], "twin": [s.__dict__ for s in twin_s]})
    md = ["# The rendered twin of a real star camera", "",
          f"{len(names)} frames; {within} of {len(rows)} comparisons within their tolerance.", "",
          table_markdown(rows), "", "What the real frames say (twin.json has every number):", "",
          f"- gain {desc.gain_dn_per_e:.3f} ± {desc.gain_sigma:.3f} DN per electron, dark variance "
          f"{desc.dark_variance_dn2:.0f} DN² (photon transfer of each frame's sky)",
          f"- vignetting V = 1 − {desc.rho2:.3f} ρ² − {desc.rho4:.3f} ρ⁴ (corner {1 - desc.rho2 - desc.rho4:.2f})",
          f"- PSF σ {desc.psf_sigma_px:.3f} px (FWHM {2.3548 * desc.psf_sigma_px:.2f} px) from {desc.n_psf_stars} bright stars",
          f"- zero point log10(DN of an Hp = 0 star) {desc.zero_point_log10_dn:.3f}, scatter {desc.zero_point_scatter_dex:.3f} dex",
          f"- stars beyond the catalogue's completeness: {desc.faint_density_per_deg2_per_mag:.2f} per deg² per magnitude "
          "at 9 mag (fitted to the detections with no catalogue star)",
          *[f"- {n}" for n in desc.notes], "",
          "![frames (2 × 2 means)](frames.png)", "", "![frames, centre at full resolution](frames_crop.png)", "",
          "![profiles](profiles.png)", ""]
    atomic_write_bytes(out / "twin.md", "\n".join(md).encode())
    print(table_markdown(rows))
    print(f"{within} of {len(rows)} within tolerance → {out / 'twin.md'}, {out / 'twin.json'}, "
          + ", ".join(p.name for p in figs.values()) + f" [{time.perf_counter() - t0:.1f} s]")
    return 0
