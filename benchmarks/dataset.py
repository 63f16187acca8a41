"""Dataset generation throughput, old vs new side by side: frames/s per worker at 1 and 2 workers,
and the peak memory of one 5120×3840 frame.

    .venv/bin/python benchmarks/dataset.py [--frames 16] [--spp 1024] [--rig sun_sensor_2axis_diaphragm] [--quick]
                                           [--base COMMIT]

Each case runs in fresh subprocesses (benchmarks/_compare.py), once with the package at ``--base``
(default: the commit before the speed work) and once with the working tree. A pool case starts
``w`` spawned worker processes (one thread each, as ``rigsim dataset generate --workers w`` runs
them) and warms each worker's Mitsuba scene untimed; the timed statement renders ``--frames``
sun-sensor frames (1024², chunks of two) through the worker task ``render_chunk`` (render, truth,
detector, PNG, sidecar) into a fresh folder. ``result``: frames/s per worker and in all. On a
loaded machine wall-clock rates mislead: the in-process case reports the CPU time per frame (one
process, the worker thread policy; the I/O thread's PNG encoding included). The 5120×3840 case
renders one frame of the same rig with ``resolution_px = [5120, 3840]`` in the child itself: its
peak RSS is the "old MB"/"new MB" column. Targets: ≥ 14 frames/s per worker, 2 workers ≥ 1.8× one
(needs two idle cores: the load average is printed), 5120×3840 in ≤ 1 GB.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _compare import BASE, compare

ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}

POOL_SETUP = """
import multiprocessing as mp, shutil, tempfile, time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from rigsim.dataset.generators import generator_for_rig, make_generator
from rigsim.dataset.runner import _init_worker, render_chunk
from rigsim.rig.load import read_rig_text, resolve_rig_path

rig = resolve_rig_path({rig!r})
text = read_rig_text(rig)
kind = generator_for_rig(text)
opts = {{"spp": {spp}}}
gen = make_generator(kind, text, str(rig), **opts)
W, N = {workers}, {frames}
params = gen.plan(N + 2 * W, None, 1)
ex = ProcessPoolExecutor(max_workers=W, mp_context=mp.get_context("spawn"), initializer=_init_worker,
                         initargs=(1,))
runs = [0]
def _render(items):
    root = Path(tempfile.mkdtemp(prefix="rigsim-bench-ds-"))
    (root / "frames").mkdir()
    futs = [ex.submit(render_chunk, kind, text, str(rig), opts, str(root), gen.image_format, c) for c in items]
    for f in futs:
        f.result()
    shutil.rmtree(root, ignore_errors=True)
# warm-up, untimed: every worker builds its scene (one single-frame task per worker, submitted together)
_render([[(N + i, params[N + i])] for i in range(2 * W)])
"""

POOL_STMT = """
t0 = time.perf_counter()
_render([[(i, params[i]) for i in range(k, min(N, k + 2))] for k in range(0, N, 2)])
dt = time.perf_counter() - t0
result = {"frames_per_s_per_worker": N / dt / W, "frames_per_s": N / dt, "ms_per_frame_per_worker": dt * 1e3 * W / N}
"""

ONE_STMT = """
root = Path(tempfile.mkdtemp(prefix="rigsim-bench-one-"))
(root / "frames").mkdir()
t0, c0 = time.perf_counter(), time.process_time()
render_chunk(kind, text, str(rig), opts, str(root), gen.image_format, [(j, params[j]) for j in range(i[0], i[0] + 4)])
dt, dc = time.perf_counter() - t0, time.process_time() - c0
i[0] += 4
shutil.rmtree(root, ignore_errors=True)
result = {"ms_per_frame": dt * 1e3 / 4, "cpu_ms_per_frame": dc * 1e3 / 4, "frames_per_cpu_s": 4 / dc}
"""

BIG_SETUP = """
import shutil, tempfile, time
from pathlib import Path
from rigsim.dataset.generators import generator_for_rig, make_generator
from rigsim.dataset.runner import _set_threads, render_chunk
from rigsim.rig.load import read_rig_text, resolve_rig_path

_set_threads({threads})  # 1: the worker policy (every pool one thread); None: as `--workers 1` runs
rig = resolve_rig_path({rig!r})
text = read_rig_text(rig).replace("resolution_px = [1024, 1024]", "resolution_px = [{w}, {h}]")
kind = generator_for_rig(text)
opts = {{"spp": {spp}}}
gen = make_generator(kind, text, str(rig), **opts)
params = gen.plan(16, None, 1)
i = [0]
if {warm}:  # the scene built and every path compiled, untimed
    root = Path(tempfile.mkdtemp(prefix="rigsim-bench-warm-"))
    (root / "frames").mkdir()
    render_chunk(kind, text, str(rig), opts, str(root), gen.image_format, [(15, params[15])])
    shutil.rmtree(root, ignore_errors=True)
"""

BIG_STMT = """
root = Path(tempfile.mkdtemp(prefix="rigsim-bench-big-"))
(root / "frames").mkdir()
t0 = time.perf_counter()
render_chunk(kind, text, str(rig), opts, str(root), gen.image_format, [(i[0], params[i[0]])])
dt = time.perf_counter() - t0
i[0] += 1
shutil.rmtree(root, ignore_errors=True)
result = {"s_per_frame": dt}
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--rig", default="sun_sensor_2axis_diaphragm")
    ap.add_argument("--quick", action="store_true", help="one round per side")
    ap.add_argument("--base", default=BASE, help="the old side's commit (default %(default)s)")
    a = ap.parse_args()
    rounds = 1 if a.quick else 2
    # an absolute path: the old package's scenes/ link does not resolve inside its extracted copy
    rig = Path(a.rig) if a.rig.endswith(".toml") else Path(__file__).resolve().parents[1] / "scenes" / f"{a.rig}.toml"
    a.rig = str(rig.resolve())
    print(f"old = {a.base}; {a.frames} sun-sensor frames (1024², {a.spp} spp) per timed run; load average {os.getloadavg()[0]:.2f}, "
          f"{os.cpu_count()} CPUs")
    res = {}
    for w in (1, 2):
        setup = POOL_SETUP.format(rig=a.rig, spp=a.spp, workers=w, frames=a.frames)
        res[w] = compare(f"dataset 1024², {w} worker(s)", setup, POOL_STMT, repeat=2, rounds=rounds, env=ENV, base=a.base,
                         target="≥ 14 frames/s/worker" + (", ≥ 1.8× one worker" if w == 2 else ""))
    for side in ("old", "new"):
        f1 = res[1][side].result.get("frames_per_s", float("nan"))
        f2 = res[2][side].result.get("frames_per_s", float("nan"))
        print(f"{side}: 2 workers / 1 worker = {f2 / f1:.2f}× (load average now {os.getloadavg()[0]:.2f})")
    compare("dataset 1024², in-process, 4 frames", BIG_SETUP.format(rig=a.rig, spp=a.spp, w=1024, h=1024, warm=True, threads=1),
            ONE_STMT, repeat=2, rounds=rounds, env=ENV, base=a.base, target="CPU ms/frame: load-proof")
    compare("dataset frame 5120×3840 (peak MB)", BIG_SETUP.format(rig=a.rig, spp=a.spp, w=5120, h=3840, warm=False, threads=None),
            BIG_STMT, repeat=1, rounds=1, env=ENV, base=a.base, target="≤ 1 GB")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
