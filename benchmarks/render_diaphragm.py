"""Seed-000 diaphragm screen: seconds per frame and reflected-spot error against the exact trace.

    .venv/bin/python benchmarks/render_diaphragm.py                 # full run (~2-4 min)
    .venv/bin/python benchmarks/render_diaphragm.py --quick         # fewer poses and spp values
    .venv/bin/python benchmarks/render_diaphragm.py --preview renders/aiming_camera_screen.png

Default rig (scenes/sun_sensor_2axis_diaphragm.toml) with its true errors, face "+Z", aiming
camera 768 x 576 px, 15 µm object pixel. Prints:

1. speed: seconds per pose (both frames: the hole with the spot blocked, then the spot), split into
   spot render, hole render, detector; for the physical screen (real hole) and with one render
   thread (bit-reproducible, the default) or all threads;
2. fidelity: with a noise-free detector, the rendered spot offset from the hole, mapped back to the
   screen in µm through the camera/screen homography, minus the exact placement trace; split into
   the estimator's own bias (the same centroid on the analytically rasterised disks) and the
   rendering error. Uses the hole-less 'diffuse' mode so that the whole spot is visible at every
   tilt, including the null;
3. no-recompile check: kernels compiled after the warm-up frame (drjit kernel history) and the
   time of a pose update;
4. float32 geometry: the face tilt Mitsuba actually sees (its float32 vertex positions) and the
   spot shift that alone causes.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from rigsim.detector import apply_detector  # noqa: E402
from rigsim.frames import from_arcsec  # noqa: E402
from rigsim.imaging.screen import screen_centroid, screen_circle_fit
from rigsim.render.cube_mirror import diaphragm as D  # noqa: E402
from rigsim.rig import load_rig  # noqa: E402
from rigsim.truth.cube_mirror.diaphragm import rasterise_screen_disk
from rigsim.truth.cube_mirror.realization import realization_from_rig  # noqa: E402

RIG = load_rig("sun_sensor_2axis_diaphragm")
REAL = realization_from_rig(RIG)
DET = RIG.aiming_camera.detector
TILTS = [dict(), dict(X=2.0), dict(Y=20.0), dict(X=100.0), dict(Y=-100.0), dict(X=-150.0, Y=60.0)]


def pose_of(geom, tilt):
    p = dict(geom.layout.null_pose_rad)
    for ax, a in tilt.items():
        p[ax] += from_arcsec(a)
    return p


def label(tilt):
    return ", ".join(f"{k}'{v:+g}″" for k, v in tilt.items()) or "null"


def signal(frame):
    return np.maximum((frame.dn.astype(float) - DET.offset_dn) / DET.gain_dn_per_e - DET.dark_mean_e, 0.0)


def speed(spps, n_poses, deterministic):
    print(f"\n## Speed: physical screen (real hole), seconds per pose = hole frame + spot frame "
          f"({'one render thread, bit-reproducible' if deterministic else 'all threads'})")
    print("| spp | light paths / frame | build + warm-up s | spot render s | hole render s | detector s (2 frames) | **s per pose** | s per spot frame |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    rows = {}
    for spp in spps:
        t0 = time.perf_counter()
        r = D.DiaphragmRenderer(RIG, REAL, 0, spp=spp, deterministic=deterministic)
        build = time.perf_counter() - t0
        g = r.geometry
        secs = []
        rng = np.random.default_rng(spp)
        for k in range(n_poses):
            tilt = dict(zip(("X", "Y"), rng.uniform(-400.0, 400.0, 2)))
            fr = r.render(pose_of(g, tilt), seed=k + 1)
            secs.append(fr.seconds)
        med = {k: statistics.median(s[k] for s in secs) for k in secs[0]}
        per_spot = med["render_spot"] + med["detector"] / 2
        rows[spp] = med
        print(f"| {spp} | {spp * g.camera.width * g.camera.height / 1e6:.1f} M | {build:.2f} | {med['render_spot']:.2f} | "
              f"{med['render_hole']:.2f} | {med['detector']:.2f} | **{med['total']:.2f}** | {per_spot:.2f} |")
    return rows


def fidelity(spps, tilts, seeds):
    print("\n## Fidelity: rendered spot offset − exact trace (µm on the screen), noise-free detector, "
          "hole-less 'diffuse' mode, sampler multijitter")
    print("| spp | tilt | |offset| µm | total error (s, t) µm | estimator bias µm | rendering error µm | circle-fit error µm |")
    print("|---:|---|---:|---|---|---|---|")
    summary = {}
    for spp in spps:
        r = D.DiaphragmRenderer(RIG, REAL, 0, spp=spp, return_into_hole="diffuse", deterministic=False)
        g = r.geometry
        ras_hole = screen_centroid(rasterise_screen_disk(g, [0.0, 0.0], g.hole_radius_mm), g)
        errs, rend = [], []
        for seed in range(seeds):
            fr = r.render(pose_of(g, {}), seed=1000 + seed, noiseless=True)
            hole = screen_centroid(signal(fr.hole), g)
            for tilt in tilts:
                pose = pose_of(g, tilt)
                tr = g.trace(pose)
                ph, _, _ = r.render_photons(pose, seed=seed * 100 + 7, hole=False)
                frame = apply_detector(ph, DET, noiseless=True)
                spot = screen_centroid(signal(frame), g)
                err = 1e3 * (spot - hole - tr.offset_mm)
                ras = screen_centroid(rasterise_screen_disk(g, tr.offset_mm, g.hole_radius_mm), g)
                bias = 1e3 * (ras - ras_hole - tr.offset_mm)
                cf = screen_circle_fit(signal(frame), g)
                cerr = 1e3 * (np.array([cf.u, cf.v]) - tr.offset_mm)
                errs.append(np.linalg.norm(err))
                rend.append(np.linalg.norm(err - bias))
                if seed == 0:
                    print(f"| {spp} | {label(tilt)} | {1e3 * np.linalg.norm(tr.offset_mm):.2f} | "
                          f"({err[0]:+.3f}, {err[1]:+.3f}) | ({bias[0]:+.4f}, {bias[1]:+.4f}) | "
                          f"({err[0] - bias[0]:+.3f}, {err[1] - bias[1]:+.3f}) | ({cerr[0]:+.3f}, {cerr[1]:+.3f}) |")
        e = np.array(errs)
        summary[spp] = (float(np.sqrt(np.mean(e**2))), float(e.max()), len(e))
    print("\n| spp | poses × seeds | |error| rms µm | |error| max µm |")
    print("|---:|---:|---:|---:|")
    for spp, (rms, mx, n) in summary.items():
        print(f"| {spp} | {n} | {rms:.3f} | {mx:.3f} |")
    return summary


def recompile_check():
    import drjit as dr

    r = D.DiaphragmRenderer(RIG, REAL, 0, spp=16)
    g = r.geometry
    dr.kernel_history_clear()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    ups = []
    try:
        for k, tilt in enumerate(TILTS):
            _, _, sec = r.render_photons(pose_of(g, tilt), seed=k)
            ups.append(sec["update"])
        hist = [h for h in dr.kernel_history() if h["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    fresh = sum(1 for h in hist if not h.get("cache_hit"))
    disk = sum(1 for h in hist if h.get("cache_disk"))
    print(f"\n## No recompile: {len(TILTS)} poses after the warm-up frame: {len(hist)} kernel launches, "
          f"{fresh} compiled fresh, {disk} loaded from the disk cache; pose update (cube vertices "
          f"through mi.traverse) median {1e3 * statistics.median(ups):.1f} ms, max {1e3 * max(ups):.1f} ms; "
          f"build {r.build_seconds:.2f} s, warm-up frame {r.warmup_seconds:.2f} s")
    return fresh


def float32_geometry():
    """Face normal Mitsuba sees (float32 vertices) vs float64: the spot shift it alone causes."""
    r = D.DiaphragmRenderer(RIG, REAL, 0, spp=1, warmup=False)
    g = r.geometry
    print("\n## float32 geometry: spot shift caused by Mitsuba's float32 cube vertices alone")
    print("| tilt | face-normal error of the lit face (rad) | spot shift µm | worst other face (rad) |")
    print("|---|---:|---:|---:|")
    for tilt in TILTS:
        pose = pose_of(g, tilt)
        r.set_pose(pose)
        v32 = np.array(r._spot_scene.params["cube.vertex_positions"], dtype=np.float64).reshape(-1, 3)
        M = D.cube_to_scene_matrix(g, pose)
        v64 = r._cube_local @ M[:3, :3].T + M[:3, 3]
        tri = np.arange(len(v64)).reshape(-1, 3)
        n64 = np.cross(v64[tri[:, 1]] - v64[tri[:, 0]], v64[tri[:, 2]] - v64[tri[:, 0]])
        n32 = np.cross(v32[tri[:, 1]] - v32[tri[:, 0]], v32[tri[:, 2]] - v32[tri[:, 0]])
        n64 /= np.linalg.norm(n64, axis=1, keepdims=True)
        n32 /= np.linalg.norm(n32, axis=1, keepdims=True)
        k = int(np.argmax(n64 @ np.array([0.0, 0.0, 1.0])))  # a triangle of the face the beam hits
        err = np.linalg.norm(n32 - n64, axis=1)
        dn = err[k]
        shift = 2.0 * dn * RIG.diaphragm_screen.distance_to_cube_mm
        print(f"| {label(tilt)} | {dn:.1e} | {1e3 * shift:.1e} | {err.max():.1e} |")


def preview(path, seed=11):
    r = D.DiaphragmRenderer(RIG, REAL, 0, spp=16)
    g = r.geometry
    tilt = dict(X=-260.0, Y=330.0)  # offset ≈ 2.6 mm: the spot beside the hole, both whole
    fr = r.render(pose_of(g, tilt), seed=seed)
    png = D.preview_png(fr.spot.dn, path)
    print(f"\npreview: {png} (spot frame, tilt {label(tilt)}, offset {1e3 * fr.truth.offset_mm} µm, "
          f"hole at {fr.truth.hole_uv}, spot at {np.round(fr.truth.spot_uv, 2)} px)")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--preview", type=Path, default=None, help="also write an 8-bit preview PNG of a spot frame")
    args = ap.parse_args()
    load = os.getloadavg()
    print(f"# benchmarks/render_diaphragm.py  (load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} on "
          f"{os.cpu_count()} cores; timings on a shared machine vary by up to 2x)")
    t0 = time.perf_counter()
    r0 = D.DiaphragmRenderer(RIG, REAL, 0, spp=1, warmup=False)
    print(f"variant {r0.variant}; geometry: hole Ø{RIG.diaphragm_screen.hole_diameter_mm} mm, "
          f"{RIG.diaphragm_screen.distance_to_cube_mm} mm to the face; camera "
          f"{r0.geometry.camera.width}x{r0.geometry.camera.height} px, f = {r0.geometry.camera.f_px:.1f} px, "
          f"view {RIG.aiming_camera.view_angle_deg}°; object pixel {1e3 * abs(r0.geometry.screen_mm_per_px()[1, 1]):.2f} µm (v), "
          f"{1e3 * abs(r0.geometry.screen_mm_per_px()[0, 0]):.2f} µm (u)")
    spps = [4, 16] if args.quick else [4, 16, 64]
    speed(spps, 3 if args.quick else 5, deterministic=True)
    speed([16], 3 if args.quick else 5, deterministic=False)
    fidelity(spps, TILTS[:4] if args.quick else TILTS, 1 if args.quick else 3)
    recompile_check()
    float32_geometry()
    if args.preview is not None:
        preview(args.preview)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
