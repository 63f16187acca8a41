"""Render benchmarks, one line per frame type: seconds per frame and rendering-induced error.

Runs the sun-sensor rig frame here, then the per-scene benchmark scripts beside this file
(render_primitives.py, render_diaphragm.py, render_autocollimator.py) as they exist.

    .venv/bin/python benchmarks/render.py [--quick]
"""

import argparse
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def sun_sensor_rig(spp: int, n: int):
    from rigsim.render.cube_mirror.sun_sensor import SunSensorScene
    from rigsim.rig import load_rig
    from rigsim.truth.cube_mirror.realization import realization_from_rig

    rig = load_rig("sun_sensor_2axis_diaphragm")
    sc = SunSensorScene(rig, realization_from_rig(rig), spp=spp)
    sc.render({"X": 0.0, "Y": 0.0}, seed=0, noiseless=True)  # warm-up (JIT)
    rng = np.random.default_rng(1)
    errs, secs = [], []
    for i in range(n):
        pose = {"X": math.radians(rng.uniform(-55, 55)), "Y": math.radians(rng.uniform(-40, 40))}
        t = time.perf_counter()
        fr = sc.render(pose, seed=i, noiseless=False, truth_points=1)
        secs.append(time.perf_counter() - t)
        if fr.sidecar["flags"]["spot_off_detector"]:
            continue
        s = sc.sun_dir_cam(pose)
        truth = sc.renderer.truth(s, n=400_000)["pixel_centroid_uv"]
        errs.append(np.linalg.norm(fr.extra["window"].centroid() - np.array(truth)))
    return np.median(secs), float(np.sqrt(np.mean(np.square(errs)))), len(errs)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer frames, skip the per-scene scripts")
    args = ap.parse_args()
    n = 8 if args.quick else 24
    print("frame type                          spp   s/frame   rendering error (RMS, vs exact)   frames")
    for spp in (256, 1024):
        t, e, k = sun_sensor_rig(spp, n)
        print(f"sun sensor 1024² (rig, +detector)  {spp:5d}   {t:7.3f}   {e:.4f} px (window first moment)        {k}")
    if args.quick:
        return
    here = Path(__file__).parent
    for script in ("render_primitives.py", "render_diaphragm.py", "render_autocollimator.py"):
        p = here / script
        if p.exists():
            print(f"\n=== {script} ===", flush=True)
            subprocess.run([sys.executable, str(p)], check=False)


if __name__ == "__main__":
    main()
