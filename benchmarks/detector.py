"""Detector model (rigsim.detector.apply_detector), old vs new side by side.

    .venv/bin/python benchmarks/detector.py [--quick] [--base COMMIT]

Cases: a 1024² sun-sensor-like frame (dark sky, one bright spot) with every array of 128 kB or more
a fresh memory map (what B/px needs), the same with glibc's default malloc settings (the outputs'
pages reused rather than zeroed afresh by the kernel, as in a long-running process such as the
dataset generator) and with the main job's 1 MB threshold, a 1024² star-like frame (λ ≈ 9 e-
background everywhere), the sun frame with a new sensor seed every call (fixed patterns drawn each
time), a 256² window of a 5120×3840 detector with a new sensor seed every call (the old code drew
the whole detector's pattern), a whole 5120×3840 frame, and the sun frame at 256², 1024², 4096² for
linearity (ns/px). ``cpu_ms_per_frame`` (process CPU time) is the figure to trust on a loaded
machine. Each case prints the best time per frame, the speed-up, the child's peak RSS,
and in ``result``: ms per frame, ns per pixel, and B/px = (peak RSS during the call − RSS before
it) / pixels (the peak is reset through /proc/self/clear_refs; the outputs, 11 B/px, count;
glibc's mmap threshold is fixed so that freed arrays leave the RSS),
plus the mean DN and DN variance of the frame as a check that both sides model the same sensor.
One thread (numpy is single-threaded here; BLAS/OpenMP pinned to 1). Targets: ≤ 20 ms per 1024²
frame, ≤ 40 B/px, ns/px flat in the pixel count.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _compare import BASE, compare

# glibc: a fixed mmap threshold returns every freed array to the system at once, so that the RSS
# before a call is the live memory and the peak during it measures that call (both sides alike)
ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
       "MALLOC_MMAP_THRESHOLD_": "131072", "MALLOC_TRIM_THRESHOLD_": "131072"}

ENV_DEFAULT_MALLOC = {k: v for k, v in ENV.items() if not k.startswith("MALLOC_")}

# the main job's setting (rigsim.render.backend.cap_mmap_threshold): arrays of 1 MB and more are
# memory maps of their own, the blocks' temporaries come from the heap
ENV_MAIN_JOB = {**ENV_DEFAULT_MALLOC, "MALLOC_MMAP_THRESHOLD_": "1048576", "MALLOC_TRIM_THRESHOLD_": "1048576"}

SETUP = """
import numpy as np
from rigsim.detector import DetectorConfig, apply_detector
H, W = {h}, {w}
kind = {kind!r}
cfg = DetectorConfig()          # QE 0.6, dark 0.1 e-, DSNU 1 e-, PRNU 0.5 %, read 5 e-, 12 bit
if kind == "sun":               # dark sky and one bright, partly saturating spot
    ph = np.zeros((H, W))
    s = W / 40.0
    v = np.arange(H)[:, None] - H / 3.0
    u = np.arange(W)[None, :] - W / 2.0
    ph += np.exp(-v * v / (2 * s * s)) * 3e5
    ph *= np.exp(-u * u / (2 * s * s))
else:                           # star-like: λ ≈ 9 e- everywhere
    ph = np.full((H, W), (9.0 - cfg.dark_mean_e) / cfg.quantum_efficiency)
win = {win!r}
kw = {{}} if win is None else {{"origin_uv": win[0], "detector_shape": (win[1], win[2])}}
cold = {cold!r}
calls = [0]
def _rss(field):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field):
                return int(line.split()[1]) * 1024
apply_detector(ph, cfg, seed=0, **kw)   # warm: imports, and the fixed pattern unless cold
"""

STMT = """
import time
calls[0] += 1
c = cfg.model_copy(update={"sensor_seed": 1000 + calls[0]}) if cold else cfg
open("/proc/self/clear_refs", "w").write("5")
base = _rss("VmRSS:")
t0, c0 = time.perf_counter(), time.process_time()
f = apply_detector(ph, c, seed=calls[0], **kw)
dt, dc = time.perf_counter() - t0, time.process_time() - c0
peak = _rss("VmHWM:")
d = f.dn.astype(np.float64)
result = {"ms_per_frame": dt * 1e3, "cpu_ms_per_frame": dc * 1e3, "ns_per_px": dt * 1e9 / ph.size, "B_per_px": (peak - base) / ph.size,
          "mean_dn": d.mean(), "var_dn": d.var()}
del f, d
"""


_BASE = [BASE]


def case(name, h, w, kind="sun", win=None, cold=False, repeat=3, rounds=2, target="", env=None):
    setup = SETUP.format(h=h, w=w, kind=kind, win=win, cold=cold)
    return compare(name, setup, STMT, repeat=repeat, rounds=rounds, env=ENV if env is None else env, target=target,
                   base=_BASE[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="one round per side, skip the 4096² and 5120×3840 cases")
    ap.add_argument("--base", default=BASE, help=f"git commit of the old side (default {BASE})")
    a = ap.parse_args()
    _BASE[0] = a.base
    r = 1 if a.quick else 2
    print(f"load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs")
    case("sun-sensor 1024²", 1024, 1024, rounds=r, target="≤ 20 ms, ≤ 40 B/px")
    # the same frame with glibc's own malloc settings (its mmap threshold rises after the first large
    # free, so the outputs' pages are reused instead of being zeroed by the kernel afresh; B/px is
    # then not measured): what a long-running process such as the dataset generator sees
    case("sun-sensor 1024², default malloc", 1024, 1024, rounds=r, target="≤ 20 ms", env=ENV_DEFAULT_MALLOC)
    case("sun-sensor 1024², 1 MB maps (main job)", 1024, 1024, rounds=r, target="≤ 20 ms", env=ENV_MAIN_JOB)
    case("star-like 1024² (λ≈9 e-)", 1024, 1024, kind="star", rounds=r)
    case("sun 1024², new sensor seed per call", 1024, 1024, cold=True, rounds=r)
    case("256² window of 5120×3840, new seed", 256, 256, win=((2400, 1700), 3840, 5120), cold=True, rounds=r,
         target="∝ window pixels")
    for n in (256, 1024) + (() if a.quick else (4096,)):
        case(f"linearity: sun {n}²", n, n, rounds=r, repeat=3 if n < 4096 else 2, target="ns/px flat")
    if not a.quick:
        case("sun 5120×3840", 3840, 5120, rounds=1, repeat=2, target="≤ 40 B/px")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
