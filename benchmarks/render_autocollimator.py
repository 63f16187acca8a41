"""Speed and rendering error of the seed-001 autocollimator frames (Mitsuba ptracer).

    .venv/bin/python benchmarks/render_autocollimator.py            # full run (~3-5 min)
    .venv/bin/python benchmarks/render_autocollimator.py --quick    # fewer poses, no 4096 spp

Prints:

1. the instrument (objective, focus, spot size, measuring range) and the backend;
2. per spp, for the cube face "+Z" at poses across the measuring range: seconds per window
   render, seconds per full frame (exact truth + render + detector model on 1280x1024), and the
   spot centroid error against the exact trace (noise-free renderer output, pixel-binned truth
   over the same window), rms and max over the poses;
3. the plane mirror (step A) at 1024 spp;
4. that pose changes after the warm-up go through mi.traverse without recompiling: drjit's
   kernel history over the poses (launched / compiled fresh) and the parameter-update time;
5. two studies behind the design: the world origin at the mirror instead of the objective
   (Mitsuba's ray offsets then rescale the spot offset), and Fresnel ghosts switched on.

Rendering error is measured on the photon image before the detector model: the detector's
photon noise is physics, not rendering error.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from rigsim.errors import GeometryWarning  # noqa: E402
from rigsim.render import backend  # noqa: E402
from rigsim.render.cube_mirror.autocollimator import AutocollimatorRenderer
from rigsim.rig import load_rig  # noqa: E402
from rigsim.truth.cube_mirror.realization import realization_from_rig  # noqa: E402

ARCMIN = math.radians(1 / 60)
# (outer Y', middle X') offsets in arcmin from the face's null: the spot moves along u, v.
# The measuring range is ±10.6' (u) x ±8.5' (v).
POSES = [(0.0, 0.0), (0.3, 0.2), (5.0, 0.0), (0.0, -6.0), (-9.0, 0.0), (7.0, 7.0), (-8.0, -6.5), (2.5, -3.5)]
QUICK_POSES = POSES[:4]


def pose_of(ref, dy, dx):
    p = dict(ref)
    p["Y"] += dy * ARCMIN
    p["X"] += dx * ARCMIN
    return p


def run_poses(r: AutocollimatorRenderer, poses, seed0: int, frames: bool = False):
    errs, t_win, t_frame, t_mi = [], [], [], []
    for k, (dy, dx) in enumerate(poses):
        p = pose_of(r.layout.reference_pose_rad, dy, dx)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", GeometryWarning)
            w = r.render_window(p, seed=seed0 + k)
        errs.append(w.centroid_geometric() - w.truth.pixel_centroid_uv)
        t_win.append(w.seconds)
        t_mi.append(w.seconds_mitsuba)
        if frames:
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", GeometryWarning)
                r.render_frame(p, seed=seed0 + k)
            t_frame.append(time.perf_counter() - t0)
    return np.array(errs), t_win, t_frame, t_mi


def stats(e: np.ndarray) -> tuple[float, float]:
    return float(np.sqrt(np.mean(np.sum(e ** 2, axis=1)))), float(np.max(np.abs(e)))


def truth_seconds(r, poses) -> float:
    ts = []
    for dy, dx in poses:
        t0 = time.perf_counter()
        r.truth(pose_of(r.layout.reference_pose_rad, dy, dx))
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer poses, skip 4096 spp and the studies")
    args = ap.parse_args()
    poses = QUICK_POSES if args.quick else POSES
    spps = (256, 1024) if args.quick else (256, 1024, 4096)

    rig = load_rig("sun_sensor_3axis_autocollimator")
    real = realization_from_rig(rig)
    variant = backend.ensure_variant()
    print(f"variant {variant}, libLLVM {backend.loaded_libllvm()}")

    r = AutocollimatorRenderer(rig, real, "face", spp=spps[0])
    o = r.optics
    ob = o.objective
    hx, hy = o.measuring_range_rad()
    tr0 = r.truth(r.layout.reference_pose_rad)
    print(f"objective: plano-convex {ob.glass} n={ob.n:.5f} @ {ob.wavelength_nm} nm, f={ob.focal_length_mm} mm, "
          f"R={ob.radius_mm:.3f} mm, t={ob.center_thickness_mm} mm, stop Ø{ob.clear_aperture_mm} mm (f/{ob.focal_length_mm / ob.clear_aperture_mm:.0f})")
    print(f"reticle at best collimation: {o.focus_shift_mm:.4f} mm inside the paraxial focus; detector "
          f"{o.source_offset_mm * 1e3:.0f} µm behind the reticle; detector {o.width}x{o.height} px of {o.pitch_mm * 1e3} µm")
    print(f"measuring range ±{hx / ARCMIN:.1f}' (u) x ±{hy / ARCMIN:.1f}' (v); 1 px = "
          f"{0.5 * o.pitch_mm / o.efl_mm * 206264.806:.3f}\" of mirror tilt")
    print(f"nulled spot on the 25 mm cube face: rms radius {tr0.rms_radius_px:.2f} px, extent "
          f"{np.ptp(tr0.extent_uv, axis=0).round(1).tolist()} px, window {r.window_px} px, "
          f"{r.source_photons:.3g} reticle photons (peak at 50 % full well)")
    print(f"exact truth ({r.truth_rays} rays): {truth_seconds(r, poses[:3]):.2f} s per pose (median)\n")

    print("cube face +Z, poses (Y', X') arcmin:", poses)
    print(f"{'spp':>6} {'light paths':>12} {'warm-up s':>10} {'mitsuba s':>10} {'s/window':>9} {'s/frame':>8} "
          f"{'rms err px':>11} {'max err px':>11}")
    for spp in spps:
        r = AutocollimatorRenderer(rig, real, "face", spp=spp)
        tw = r.warm_up()
        e, t_win, t_frame, t_mi = run_poses(r, poses, 100 * spp, frames=(spp == 1024))
        rms, mx = stats(e)
        tf = f"{statistics.median(t_frame):8.2f}" if t_frame else f"{'-':>8}"
        print(f"{spp:>6} {spp * r.window_px ** 2:>12,d} {tw:>10.2f} {statistics.median(t_mi):>10.2f} "
              f"{statistics.median(t_win):>9.2f} {tf} {rms:>11.4f} {mx:>11.4f}", flush=True)
        if spp == 1024:
            r1024 = r
    print("  (mitsuba s = traverse update + mi.render; s/window adds the exact truth (numpy) and the diffraction\n"
          "   convolution; s/frame adds the 1280x1024 detector model; errors: Mitsuba's window vs the exact trace)\n")

    # plane mirror, step A
    rp = AutocollimatorRenderer(rig, real, "plane_mirror", spp=1024)
    rp.warm_up()
    pm_poses = [(0.0, 0.0), (0.5, -0.4), (2.0, 1.5)]
    e, t_win, _, _ = run_poses(rp, pm_poses, 7000)
    rms, mx = stats(e)
    print(f"plane mirror (Ø50 mm, step A), 1024 spp, poses {pm_poses}: rms {rms:.4f} px, max {mx:.4f} px, "
          f"{statistics.median(t_win):.2f} s/window")
    print(f"  (reading at the zero pose: {(rp.optics.reading(rp.truth(rp.layout.reference_pose_rad).mean_uv) * 206264.806).round(4).tolist()}\")\n")

    # no recompile
    import drjit as dr

    rr = r1024
    ref = rr.layout.reference_pose_rad
    dr.kernel_history_clear()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    t_upd = []
    try:
        for k, (dy, dx) in enumerate(poses):
            p = pose_of(ref, dy, dx)
            w0 = rr.optics.window_for(rr.truth(p).mean_uv, rr.window_px)[:2]
            t0 = time.perf_counter()
            rr._scene.update({"pose": p, "window_origin": w0})
            t_upd.append(time.perf_counter() - t0)
            rr.render_window(p, seed=9000 + k)
        hist = [h for h in dr.kernel_history() if h["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    fresh = sum(1 for h in hist if not h.get("cache_hit"))
    print(f"recompile check after warm-up, {len(poses)} new poses: {len(hist)} kernel launches, {fresh} compiled "
          f"fresh; mirror + camera update through mi.traverse: {1e3 * statistics.median(t_upd):.1f} ms")

    if args.quick:
        return
    # study 1: world origin at the mirror
    print("\nstudy: world origin at the mirror instead of the objective (4096 spp)")
    rm = AutocollimatorRenderer(rig, real, "face", spp=4096, world_origin="mirror")
    rm.warm_up()
    for k, (dy, dx) in enumerate([(0.0, 0.0), (9.0, 0.0), (-9.0, 0.0), (0.0, -8.0)]):
        p = pose_of(rm.layout.reference_pose_rad, dy, dx)
        w = rm.render_window(p, seed=500 + k)
        off = w.truth.mean_uv - [rm.optics.cx, rm.optics.cy]
        err = w.centroid_geometric() - w.truth.pixel_centroid_uv
        print(f"  ({dy:+.1f}', {dx:+.1f}') spot offset {off.round(1).tolist()} px: error {err.round(4).tolist()} px"
              f"  (error/offset {np.dot(err, off) / max(np.dot(off, off), 1e-9):+.2e})")
    # study 2: Fresnel ghosts on
    print("\nstudy: Fresnel reflections (ghosts) kept, 4096 spp (the truth has none)")
    rg = AutocollimatorRenderer(rig, real, "face", spp=4096, lens_ghosts=True)
    rg.warm_up()
    e, _, _, _ = run_poses(rg, [(0.0, 0.0), (0.3, 0.2), (5.0, 0.0), (-9.0, 0.0)], 600)
    rms, mx = stats(e)
    print(f"  rms {rms:.4f} px, max {mx:.4f} px")


if __name__ == "__main__":
    main()
