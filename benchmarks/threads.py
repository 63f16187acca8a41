"""Threads per pool for each kind of work rigsim does: the measurements behind rigsim.render.threads.

    .venv/bin/python benchmarks/threads.py [--repeat 5]

For every kind of work, the best of ``--repeat`` runs with each pool at 1 thread and at every core,
side by side in one run (the machine is shared: compare within a row, not between runs):

- small-matrix numpy/scipy (a 9-parameter least-squares fit of 574 points, the sweep's shape);
- large dense linear algebra (scipy lstsq 20000×200, matmul 1500²);
- OpenCV image work on an aiming-camera-sized frame (GaussianBlur, dft, 1600×1200 float32);
- a Mitsuba render (Dr.Jit threads), alone and with BLAS work running beside it.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))


def best(fn, repeat: int) -> float:
    fn()
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return min(ts)


def small_lsq():
    from scipy.optimize import least_squares

    rng = np.random.default_rng(0)
    t = np.linspace(-1, 1, 574)
    y = np.polyval(rng.normal(size=9), t) + rng.normal(0, 1e-3, t.size)
    for _ in range(20):
        least_squares(lambda p: np.polyval(p, t) - y, np.zeros(9), method="lm")


def large_lsq():
    import scipy.linalg as sl

    rng = np.random.default_rng(1)
    A = rng.normal(size=(20000, 200))
    sl.lstsq(A, A @ np.ones(200))
    B = rng.normal(size=(1500, 1500))
    B @ B


def opencv_image():
    import cv2

    img = np.random.default_rng(2).random((1200, 1600), dtype=np.float32)
    for _ in range(5):
        cv2.GaussianBlur(img, (0, 0), 3.0)
    cv2.dft(img)


def mitsuba_render():
    import mitsuba as mi

    scene = getattr(mitsuba_render, "scene", None)
    if scene is None:
        scene = mi.load_dict({
            "type": "scene", "integrator": {"type": "path", "max_depth": 3},
            "sensor": {"type": "perspective", "fov": 40, "film": {"type": "hdrfilm", "width": 512, "height": 512},
                       "sampler": {"type": "independent", "sample_count": 64},
                       "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0])},
            "sphere": {"type": "sphere", "bsdf": {"type": "diffuse"}},
            "light": {"type": "constant"},
        })
        mitsuba_render.scene = scene
    np.array(mi.render(scene, seed=0))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    import cv2
    import drjit as dr
    from threadpoolctl import threadpool_limits

    from rigsim.render.backend import ensure_variant
    from rigsim.render.threads import cores

    ensure_variant()
    n = cores()
    print(f"{n} cores, load average {os.getloadavg()[0]:.2f}; best of {a.repeat} runs, seconds")
    print(f"{'work':<46} {'1 thread':>9} {f'{n} threads':>10} {'ratio':>7}")

    def row(name, fn, setter):
        r = {}
        for k in (1, n):
            setter(k)
            r[k] = best(fn, a.repeat)
        setter(n)
        print(f"{name:<46} {r[1]:>9.3f} {r[n]:>10.3f} {r[1] / r[n]:>6.2f}x")

    def blas(k):
        blas.lim = threadpool_limits(limits=k, user_api="blas")

    row("small lsq ×20 (574×9), BLAS threads", small_lsq, blas)
    row("large lsq 20000×200 + matmul 1500², BLAS", large_lsq, blas)
    row("OpenCV blur ×5 + dft 1600×1200, cv2 threads", opencv_image, cv2.setNumThreads)
    row("Mitsuba path 512² 64 spp, Dr.Jit threads", mitsuba_render, dr.set_thread_count)

    # a render with BLAS work beside it (what a pipeline thread does while a frame renders)
    def mixed(k):
        dr.set_thread_count(n)
        threadpool_limits(limits=k, user_api="blas")

    def render_with_blas():
        t = threading.Thread(target=large_lsq)
        t.start()
        mitsuba_render()
        t.join()

    row("render + large lsq beside it, BLAS threads", render_with_blas, mixed)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
