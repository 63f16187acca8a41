"""Dataset throughput: frames/s with a Dask LocalCluster of 1 and 2 workers (issue 8 target: ≥ 1.7×).

    .venv/bin/python benchmarks/dataset.py [--frames 48] [--spp 1024] [--rig sun_sensor_2axis_diaphragm]

Each worker is a process with one thread and its own Mitsuba state (built on its first task, not
timed: a warm-up task runs first). Prints frames/s per worker count and the speed-up, plus the
local process-pool path for comparison. The load average is printed: on a shared machine other
work takes cores away and the speed-up drops.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path


def run(n_workers: int, frames: int, spp: int, rig: str, mode: str) -> float:
    from distributed import Client, LocalCluster

    from rigsim.dataset.runner import generate

    tmp = Path(tempfile.mkdtemp(prefix=f"rigsim-ds-{mode}{n_workers}-"))
    try:
        if mode == "dask":
            with LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None) as cl, \
                    Client(cl) as client:
                # warm-up: every worker builds its Mitsuba scene (and compiles) once, untimed
                generate(rig, tmp / "warm", frames=2 * n_workers, seed=99, spp=spp, scheduler=client, progress=False, chunk=1)
                t0 = time.perf_counter()
                generate(rig, tmp / "run", frames=frames, seed=1, spp=spp, scheduler=client, progress=False, chunk=2)
                return frames / (time.perf_counter() - t0)
        t0 = time.perf_counter()
        generate(rig, tmp / "run", frames=frames, seed=1, spp=spp, workers=n_workers, progress=False, chunk=2)
        return frames / (time.perf_counter() - t0)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--rig", default="sun_sensor_2axis_diaphragm")
    a = ap.parse_args()
    print(f"{a.frames} sun-sensor frames (1024², {a.spp} spp), load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs")
    res = {}
    for w in (1, 2):
        res[w] = run(w, a.frames, a.spp, a.rig, "dask")
        print(f"Dask LocalCluster, {w} worker(s): {res[w]:.2f} frames/s")
    print(f"speed-up 2 vs 1 workers: {res[2] / res[1]:.2f}× (target ≥ 1.7×)")
    for w in (1, 2):
        print(f"local process pool, {w} worker(s) (includes worker start-up): {run(w, a.frames, a.spp, a.rig, 'pool'):.2f} frames/s")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
