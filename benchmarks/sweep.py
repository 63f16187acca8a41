"""The cube-mirror sun-sensor calibration sweep: old per-frame path vs one batched Mitsuba launch.

    .venv/bin/python benchmarks/sweep.py [--rig sun_sensor_2axis_diaphragm] [--seed 2009] [--spp 256]
                                         [--repeat 2] [--rounds 2] [--base 03aff45]
                                         [--cases sweep,exact,throughput]

Prints, through benchmarks/_compare.py (old = the package at ``--base``, new = the working tree,
alternating subprocesses):

1. ``sweep render + centroid``: ``render_sweep`` on the default sweep (574 frames in the field),
   exactly what ``rigsim run cube-mirror`` calls; result: R(sun←rot) error of the fit against the
   rig's truth (″ per axis, and its 1σ), the centroid rms against the exact sun-centre projection
   (px), the frames rendered and the Mitsuba samples drawn.
2. ``rendered vs exact``: the same sweep with a frame callback: rms of the first moment of each
   frame's expected-photon window minus the exact pixel-binned centroid of the disk (px), the
   rendering's own error (one run per side; its time includes the per-frame truth).
3. ``throughput`` (new only): in one process, alternately, the whole sweep and its Mitsuba launches
   alone (the same films, tiles and spp, parameters already set, nothing else): Mitsuba's raw
   sample throughput on this machine for this scene, and the sweep's samples/s as a fraction of it
   (best of each, and the median of the paired runs: the machine's load moves both).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _compare import BASE, compare

SETUP = """
import warnings
import numpy as np
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.realization import noise_from_rig, realization_from_rig
from rigsim.procedures.cube_mirror.sweep import calibrate_from_sweep, render_sweep
from rigsim.frames import ARCSEC_PER_RAD, small_angle_error
warnings.simplefilter("ignore")
rig = load_rig({rig!r} if {rig!r}.endswith(".toml") else "scenes/{rig}.toml")  # the old tree's scenes/ link is not archived
real = realization_from_rig(rig)
noise = noise_from_rig(rig)
"""

SWEEP = """
obs, tr = render_sweep(rig, real, noise, {seed}, spp={spp})
cal = calibrate_from_sweep(rig, obs)
e = small_angle_error(cal.R_sun_from_rot, real.R_sun_from_mount) * ARCSEC_PER_RAD
sig = np.sqrt(np.diag(cal.covariance))[-3:] * ARCSEC_PER_RAD
result = {{"R_err_x_arcsec": e[0], "R_err_y_arcsec": e[1], "R_err_z_arcsec": e[2], "R_sigma_max_arcsec": sig.max(),
          "centroid_vs_centre_rms_px": np.sqrt(np.mean((obs.uv - tr.uv_centre) ** 2)),
          "frames": obs.n_rendered, "rejected": obs.n_rejected}}
"""

EXACT = """
errs = []
def on_frame(fr, spots, k, reading, i):
    if k is not None and not fr.sidecar["flags"]["spot_cut_by_edge"]:  # a spot the detector's edge cuts: no exact twin
        errs.append(fr.photon_centroid() - np.asarray(fr.sidecar["truth"]["spot"]["pixel_centroid_uv"]))
obs, tr = render_sweep(rig, real, noise, {seed}, spp={spp}, on_frame=on_frame)
errs = np.array(errs)
result = {{"rendered_vs_exact_rms_px": np.sqrt(np.mean(errs ** 2)), "rendered_vs_exact_max_px": np.abs(errs).max(),
          "frames": len(errs)}}
"""

BARE_SETUP = SETUP + """
import time
from rigsim.estimation.sun_calibration import sweep_poses
from rigsim.render.cube_mirror.sun_batch import SunSpotBatch, spot_tile_px, tile_groups
from rigsim.render.cube_mirror.sun_sensor import SunSensorScene
from rigsim.render.scene import mitsuba_seed
sc = SunSensorScene(rig, real, spp={spp})
p = rig.procedure
poses = sweep_poses(p.sweep_axes, p.sweep_range_deg, p.sweep_step_deg,
                    {{a.label: 0.0 for a in rig.turntable.axes if a.label not in p.sweep_axes}})
n = len(next(iter(poses.values())))
S = np.array([sc.sun_dir_cam({{k: float(v[i]) for k, v in poses.items()}}) for i in range(n)])
c, ok = sc.camera.project_valid(S)
ok &= sc.camera.on_detector(c, margin_px=3.0)
S, c = S[ok], c[ok]
sizes = np.minimum(sc.renderer.window_px, spot_tile_px(sc.camera, S, sc.full_angle_rad))
# the sweep's launches exactly: the same tiles, film sizes and spp, state set, kernels compiled
launches = []
for tile, idx in tile_groups(sizes):
    b = SunSpotBatch(sc.renderer, tile, len(idx))
    b.render(S[idx], np.floor(c[idx] + 0.5).astype(np.int64) - tile // 2, seed=1)
    launches.append(b)
samples = sum(b.samples_per_launch for b in launches)
render_sweep(rig, real, noise, {seed}, spp={spp})  # warm
t_sweep, t_bare = [], []
"""

BARE = """
t0 = time.perf_counter()
render_sweep(rig, real, noise, {seed}, spp={spp})
t_sweep.append(time.perf_counter() - t0)
t0 = time.perf_counter()
for g, b in enumerate(launches):  # Mitsuba alone: the film of each launch, nothing else
    b._scene.render(None, seed=mitsuba_seed(2, g), spp={spp})
t_bare.append(time.perf_counter() - t0)
result = {{"samples": samples, "bare_launches_s": min(t_bare), "sweep_s": min(t_sweep),
          "raw_Msamples_per_s": samples / min(t_bare) / 1e6, "sweep_Msamples_per_s": samples / min(t_sweep) / 1e6,
          "fraction_of_raw": min(t_bare) / min(t_sweep),
          "fraction_median_of_pairs": float(np.median(np.array(t_bare) / np.array(t_sweep)))}}
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rig", default="sun_sensor_2axis_diaphragm")
    ap.add_argument("--seed", type=int, default=2009)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--base", default=BASE)
    ap.add_argument("--cases", default="sweep,exact,throughput", help="comma-separated subset to run")
    a = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} at start ({os.cpu_count()} cores)")
    setup = SETUP.format(rig=a.rig)
    cases = set(a.cases.split(","))
    if "sweep" in cases:
        compare("sweep render + centroid", setup, SWEEP.format(seed=a.seed, spp=a.spp), repeat=a.repeat,
                rounds=a.rounds, base=a.base, target="<= 3 s")
    if "exact" in cases:
        compare("rendered vs exact (1 run, + truth)", setup, EXACT.format(seed=a.seed, spp=a.spp), repeat=1, rounds=1,
                base=a.base, target="<= 0.0025 px rms")
    if "throughput" not in cases:
        return
    bare = compare("throughput: sweep vs its bare launches", BARE_SETUP.format(rig=a.rig, spp=a.spp, seed=a.seed),
                   BARE.format(spp=a.spp, seed=a.seed), repeat=max(3, a.repeat), rounds=a.rounds, old=False,
                   target=">= 50 % of raw")
    r = bare["new"].result
    print(f"\nMitsuba raw throughput {r['raw_Msamples_per_s']:.1f} M samples/s (the sweep's launches alone, same "
          f"scene, tiles and spp); sweep {r['sweep_Msamples_per_s']:.1f} M samples/s = {100 * r['fraction_of_raw']:.0f} % "
          f"of raw (best of each; median of the paired runs {100 * r['fraction_median_of_pairs']:.0f} %) "
          f"(goal >= 50 %); load average {os.getloadavg()[0]:.2f} at end")


if __name__ == "__main__":
    main()
