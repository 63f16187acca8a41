"""Seed 003 real-time numbers: latency of one frame pair → (Δf, α, β, γ), DVAD throughput, render time.

    cd /work/main && .venv/bin/python benchmarks/boresight.py [--quick]

Targets (issue 6): ≤ 1 ms from two CMOS ROIs to (Δf, α, β, γ) on one core; ≥ 1e6 vectorised DVAD
solutions per second. Everything runs single-threaded (thread pools limited to one before numpy
is imported). The machine is shared: timings are the best/median of repeated runs.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402


def _timeit(fn, reps):
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return np.array(ts)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer repetitions, no rendering")
    args = ap.parse_args()

    from rigsim.estimation.dvad import dvad, simplified
    from rigsim.frames import ARCSEC_PER_RAD as AS
    from rigsim.imaging import NoiseModel
    from rigsim.optics.line_camera import CameraGeometry, rotation_xyz, spots_uv
    from rigsim.procedures.boresight.pipeline import CameraProcessor
    from rigsim.rig.load import load_boresight_rig

    rig = load_boresight_rig()
    g = CameraGeometry.from_rig(rig.cameras[0])
    print(f"# rigsim seed-003 benchmark; python {platform.python_version()}, numpy {np.__version__}, "
          f"{platform.machine()}, single thread")

    # ---- frames for the latency test: rendered ROIs of both CMOS (or synthetic disks with --quick)
    E = rotation_xyz(*(np.array([3.0, -2.0, 5.0]) / AS))
    W = rig.orbit.window_px
    if args.quick:
        from rigsim.imaging.synth import disk_image

        rois, origins = [], []
        for uv in spots_uv(g, E, 0.004):
            o = (int(round(uv[0])) - W // 2, int(round(uv[1])) - W // 2)
            img = disk_image((W, W), uv[0] - o[0], uv[1] - o[1], 2.5) * 2500.0 + 70.0
            rois.append(np.round(img).astype(np.uint16))
            origins.append(o)
        render_note = "synthetic disk ROIs"
    else:
        from rigsim.render.boresight import LoopRenderer

        rends = [LoopRenderer(rig, 0, j) for j in (0, 1)]
        for r in rends:
            r.warm_up()
        frames = [r.render(E, 0.004, seed=5) for r in rends]
        rois = [f.dn for f in frames]
        origins = [f.origin_uv for f in frames]
        ts = []
        for k in range(6):
            t0 = time.perf_counter()
            for r in rends:
                r.render(E, 0.004, seed=10 + k, with_truth=False)
            ts.append(time.perf_counter() - t0)
        render_note = f"rendered ROIs ({W}² px)"
        print(f"\n## Rendering (Mitsuba ptracer, {rends[0].spp} light paths per pixel, {W}² ROI + detector model)")
        print(f"frame pair (M1 + M2): median {np.median(ts):.3f} s, best {min(ts):.3f} s "
              f"({W * W * rends[0].spp / 1e3:.0f}k light paths per ROI); warm-up (kernel compilation) not included")

    # ---- latency: two ROIs -> centroids -> DVAD
    proc = CameraProcessor(g, noise=NoiseModel.from_detector(rig.detector))
    proc.process(rois[0], rois[1], origins[0], origins[1])   # warm caches
    reps = 300 if args.quick else 2000
    t = _timeit(lambda: proc.process(rois[0], rois[1], origins[0], origins[1]), reps)
    from rigsim.imaging.rois import tcom_fast

    stack = np.stack(rois)
    t_cen = _timeit(lambda: tcom_fast(stack, origins, noise=proc.noise), reps)
    t_img = _timeit(lambda: proc.spots(rois[0], rois[1], origins[0], origins[1]), max(reps // 4, 50))
    uv = tcom_fast(stack, origins, noise=proc.noise)[0].reshape(2, 2)
    t_dvad = _timeit(lambda: proc.process_uv(uv), reps)
    est = proc.process(rois[0], rois[1], origins[0], origins[1])
    print(f"\n## Latency: two CMOS ROIs ({render_note}, {rois[0].shape[0]}×{rois[0].shape[1]}) → (Δf, α, β, γ), one core, {reps} repetitions")
    print(f"total:      median {np.median(t) * 1e3:.3f} ms, 99th percentile {np.percentile(t, 99) * 1e3:.3f} ms "
          f"(target ≤ 1 ms: {'met' if np.median(t) <= 1e-3 else 'NOT met'})")
    print(f"  centroids (pipeline.tcom_fast, both ROIs): median {np.median(t_cen) * 1e3:.3f} ms "
          f"(rigsim.imaging.centroid_tcom with flags: {np.median(t_img) * 1e3:.3f} ms)")
    print(f"  DVAD (consistent reading, cached reference, one pair): median {np.median(t_dvad) * 1e3:.3f} ms")
    print(f"  result: Δf = {est.delta_f_mm * 1e3:.3f} µm (true 4.000), α, β, γ = "
          f"{', '.join(f'{a:.3f}' for a in np.ravel(est.angles_arcsec))}″ (true 3, -2, 5)")

    # ---- throughput: vectorised DVAD on N spot pairs
    n = 200_000 if args.quick else 1_000_000
    rng = np.random.default_rng(1)
    ang = rng.normal(0, 20.0, (n, 3)) / AS
    df = rng.normal(0, 0.01, n)
    meas = spots_uv(g, rotation_xyz(*ang.T), df) + rng.normal(0, 0.1, (n, 2, 2))
    ref_one = g.reference_uv
    ref_many = ref_one + rng.normal(0, 0.01, (n, 2, 2))
    print(f"\n## Throughput: vectorised estimators on N = {n:,} spot pairs (best of 3)")
    for name, fn in (("DVAD consistent, one fixed reference", lambda: dvad(g, ref_one, meas)),
                     ("DVAD consistent, a reference per pair", lambda: dvad(g, ref_many, meas)),
                     ("DVAD as printed, one fixed reference", lambda: dvad(g, ref_one, meas, "as_printed")),
                     ("simplified (eqs 1–4)", lambda: simplified(g, ref_one, meas))):
        best = _timeit(fn, 3).min()
        flag = "" if not name.startswith("DVAD consistent") else f" (target ≥ 1e6/s: {'met' if n / best >= 1e6 else 'NOT met'})"
        print(f"{name:40s} {best:7.3f} s  → {n / best / 1e6:6.2f} M solutions/s{flag}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
