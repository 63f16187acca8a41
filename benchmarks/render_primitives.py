"""Speed and rendering-induced centroid error of the rig-independent render primitives.

    .venv/bin/python benchmarks/render_primitives.py            # full run (~1-2 min)
    .venv/bin/python benchmarks/render_primitives.py --quick    # fewer frames

Prints, for a wide-field sun sensor (1024 x 1024, fx = 500 px, strong barrel distortion, sun
0.53 deg):

1. the backend choice (variant, libLLVM) and how long the cached choice takes;
2. crop-window frames: seconds per frame and the centroid error caused by rendering (noise-free
   detector, against the exact pixel-binned truth of the distorted disk), per spp;
3. full 1024^2 frames with the detector noise model: (a) the window composited into the full
   frame + detector, (b) Mitsuba rendering the whole detector at a given spp + detector;
4. that pose changes after a warm-up frame go through mi.traverse without recompiling: per-frame
   time and drjit's kernel history (kernels launched / compiled fresh / loaded from disk cache).

Rendering-induced error is measured with the noise-free renderer output (photons per pixel),
because the detector's photon noise is physics, not rendering error.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from rigsim.detector import DetectorConfig, apply_detector  # noqa: E402
from rigsim.optics.camera import PinholeBrown  # noqa: E402
from rigsim.optics.sun_disk import SUN_FULL_ANGLE_RAD, spot_truth, window_centroid
from rigsim.render import backend  # noqa: E402
from rigsim.render.cube_mirror.sun_sensor import SunSpotRenderer

CAM = PinholeBrown(fx=500.0, fy=502.0, cx=515.3, cy=508.7, width=1024, height=1024,
                    k1=-0.15, k2=0.012, k3=-0.0003, p1=3e-4, p2=-2e-4)
DET = DetectorConfig(quantum_efficiency=0.6, exposure_s=0.005, full_well_e=40000.0,
                     read_noise_e=7.0, dark_current_e_per_s=100.0, dsnu_e=2.0, prnu_frac=0.005,
                     gain_dn_per_e=0.1, adc_bits=12, offset_dn=64.0, sensor_seed=1)
SPOT_PHOTONS = 3.0e6


def directions(n: int, seed: int = 7) -> list[np.ndarray]:
    """Seeded directions whose spot lies fully on the detector (up to ~62 deg off axis)."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        c = rng.uniform(math.cos(math.radians(62.0)), 1.0)
        az = rng.uniform(0.0, 2 * math.pi)
        s_ = math.sqrt(1 - c * c)
        d = np.array([s_ * math.cos(az), s_ * math.sin(az), c])
        uv, ok = CAM.project_valid(d[None])
        if ok[0] and CAM.on_detector(uv, margin_px=20)[0]:
            out.append(d)
    return out


def _stats(errs: np.ndarray) -> str:
    e = np.asarray(errs)
    rms = math.sqrt(np.mean(np.sum(e ** 2, axis=1)))
    return f"rms {rms:.4f} px  max|.| {np.max(np.abs(e)):.4f} px"


def _timeit(fn, n):
    ts = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), min(ts), max(ts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer frames")
    args = ap.parse_args()
    n_dirs = 8 if args.quick else 24

    print("== backend")
    t0 = time.perf_counter()
    variant = backend.ensure_variant()
    t_choose = time.perf_counter() - t0
    rep = backend.doctor_report(test_all=False)
    print(f"variant {variant}   libLLVM {rep['llvm_chosen']}   loaded {backend.loaded_libllvm()}")
    print(f"ensure_variant (cached verdicts + mitsuba import): {t_choose:.2f} s")

    import drjit as dr

    dirs = directions(n_dirs)
    truths = [spot_truth(CAM, d, SUN_FULL_ANGLE_RAD, n=1_000_000) for d in dirs]
    print(f"\n{len(dirs)} seeded sun directions, field angles "
          f"{min(math.degrees(math.acos(d[2])) for d in dirs):.0f}-"
          f"{max(math.degrees(math.acos(d[2])) for d in dirs):.0f} deg; "
          f"spot ~{2 * CAM.fx * math.tan(SUN_FULL_ANGLE_RAD / 2):.1f} px across on axis")

    print("\n== crop window 32x32 (ldsampler), noise-free; error vs pixel-binned exact truth")
    windows = {}
    for spp in (256, 1024, 4096):
        r = SunSpotRenderer(CAM, window_px=32, spp=spp, spot_photons=SPOT_PHOTONS)
        t0 = time.perf_counter()
        r.render(dirs[0], seed=0)
        t_first = time.perf_counter() - t0
        errs, ts, bias = [], [], []
        for k, (d, t) in enumerate(zip(dirs, truths)):
            t0 = time.perf_counter()
            w = r.render(d, seed=k + 1)
            ts.append(time.perf_counter() - t0)
            c = w.centroid()
            errs.append(c - np.array(t["pixel_centroid_uv"]))
            bias.append(c - np.array(t["center_uv"]))
        windows[spp] = r
        print(f"spp {spp:5d}: {statistics.median(ts) * 1e3:6.1f} ms/frame (median; first frame "
              f"{t_first:.2f} s)   rendering error {_stats(np.array(errs))}")
    print(f"(rendered centroid - projection of the sun centre: {_stats(np.array(bias))} -- the "
          "disk-average and pixel-sampling biases, not rendering error)")

    print("\n== full frame 1024x1024 with the detector noise model")
    r = windows[1024]

    def composite(k):
        frame, _ = r.render_frame(dirs[k % len(dirs)], seed=100 + k)
        return apply_detector(frame, DET, seed=100 + k)

    composite(0)
    med, lo, hi = _timeit(lambda: composite(1), 5 if args.quick else 10)
    print(f"(a) window 32^2 @1024 spp composited + detector: {med:.3f} s/frame "
          f"(min {lo:.3f}, max {hi:.3f}); rendering error = the window's (above)")
    t0 = time.perf_counter()
    for k in range(5):
        apply_detector(np.zeros((1024, 1024)), DET, seed=k)
    print(f"    of which detector model alone: {(time.perf_counter() - t0) / 5:.3f} s/frame")
    for spp in ((16,) if args.quick else (16, 64)):
        r.render_full(dirs[0], seed=0, spp=spp)   # build + warm-up
        errs, ts = [], []
        for k, (d, t) in enumerate(list(zip(dirs, truths))[:6]):
            t0 = time.perf_counter()
            full = r.render_full(d, seed=k + 1, spp=spp)
            apply_detector(full, DET, seed=k)
            ts.append(time.perf_counter() - t0)
            errs.append(window_centroid(full) - np.array(t["pixel_centroid_uv"]))
        print(f"(b) Mitsuba whole detector @{spp:3d} spp + detector: {statistics.median(ts):.3f} "
              f"s/frame   rendering error {_stats(np.array(errs))}")

    print("\n== pose changes after warm-up: mi.traverse updates, no recompilation")
    r = windows[1024]
    r.render(dirs[0], seed=0)
    dr.kernel_history_clear()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    ts = []
    for k, d in enumerate(dirs):
        t0 = time.perf_counter()
        r.render(d, seed=1000 + k)
        ts.append(time.perf_counter() - t0)
    hist = [h for h in dr.kernel_history() if h["type"] == dr.KernelType.JIT]
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    fresh = sum(1 for h in hist if not h.get("cache_hit"))
    disk = sum(1 for h in hist if h.get("cache_disk"))
    print(f"{len(dirs)} frames, each with a new sun pose and window origin: "
          f"{statistics.median(ts) * 1e3:.1f} ms/frame median (max {max(ts) * 1e3:.1f} ms)")
    print(f"kernel launches {len(hist)}, compiled fresh {fresh}, loaded from disk cache {disk}")
    import mitsuba as mi

    params = r._scene.params
    t0 = time.perf_counter()
    for k in range(50):
        params["sensor.window_origin"] = mi.Point2f(float(k), 3.0)
        params.update()
    print(f"mi.traverse parameter update: {(time.perf_counter() - t0) / 50 * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
