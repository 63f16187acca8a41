"""Seconds per frame and rendered-vs-exact error of every frame kind, each through its `rigsim render`
command on the default rigs, the measurement by the file stage the command prints beside the truth.

Usage: python benchmarks/frame_kinds.py [REPEATS]   (each kind rendered REPEATS times, different seeds)
Each invocation builds its scene, as a user's command does; the first of a kind also compiles the
kernels (later ones reuse Dr.Jit's cache). The table gives the first and the median of the rest."""

import contextlib
import io
import re
import sys
import tempfile
import time

import numpy as np

from rigsim.cli import main as rigsim

# kind, command (after `rigsim render`), regex(es) of the printed error, unit
KINDS = [
    ("sun-sensor", ["sun-sensor", "--pose", "X=20,Y=-10", "--spp", "1024"],
     r"px, ([0-9.]+) px from the true centre", "px"),
    ("aiming-camera (pair)", ["aiming-camera", "--pose", "X=181.398,Y=0.528", "--spp", "4"],
     r"true offset spot − hole: x ([-+0-9.]+) px, y ([-+0-9.]+) px.*?measured \(rigsim concentricity\): x ([-+0-9.]+) px, "
     r"y ([-+0-9.]+) px", "px"),
    ("autocollimator", ["autocollimator", "--spp", "256"],
     r"exact reading: θx ([-+0-9.]+)″, θy ([-+0-9.]+)″.*?measured \(rigsim autocollimator read\): θx ([-+0-9.]+)″ ± "
     r"[0-9.]+″, θy ([-+0-9.]+)″", "arcsec"),
    ("boresight-roi", ["boresight-roi", "--alpha", "30", "--df-um", "5"], r"error ([-+0-9.]+), ([-+0-9.]+) px", "px"),
    ("star-field (Mitsuba)", ["star-field", "--spp", "256", "--noiseless"], r"error vs exact rms ([0-9.]+) px", "px"),
    ("star-field (analytic)", ["star-field", "--renderer", "analytic", "--noiseless"], r"error vs exact rms ([0-9.]+) px", "px"),
    ("target (chessboard, 16 spp)", ["target", "--target", "chessboard:10x7:20", "--spread", "1", "--quiet"], None, "px"),
]


def _error(pattern: str | None, out: str) -> float:
    if pattern is None:
        return float("nan")
    m = re.search(pattern, out, re.S)
    if m is None:
        raise RuntimeError(f"no error line in:\n{out}")
    v = [float(x) for x in m.groups()]
    if len(v) == 1:
        return v[0]
    if len(v) == 2:
        return float(np.hypot(*v))
    return float(np.hypot(v[2] - v[0], v[3] - v[1]))


def main(repeats: int = 3) -> None:
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for kind, cmd, pat, unit in KINDS:
            secs, errs = [], []
            for k in range(repeats):
                buf = io.StringIO()
                t0 = time.perf_counter()
                with contextlib.redirect_stdout(buf):
                    rc = rigsim(["render", *cmd, "--out", f"{d}/{k}", "--seed", str(k)])
                secs.append(time.perf_counter() - t0)
                if rc != 0:
                    raise RuntimeError(f"rigsim render {' '.join(cmd)}: exit {rc}")
                errs.append(_error(pat, buf.getvalue()))
            rest = secs[1:] or secs
            rows.append((kind, secs[0], float(np.median(rest)), float(np.max(errs)), unit))
            print(f"{kind:30s} first {secs[0]:6.2f} s   then {np.median(rest):6.2f} s   max error {np.max(errs):.4f} {unit}",
                  flush=True)
    print("\n| kind | first frame (s) | next frames (s) | rendered vs exact (max) |\n|---|---|---|---|")
    for kind, s0, s1, e, unit in rows:
        print(f"| {kind} | {s0:.2f} | {s1:.2f} | {'–' if np.isnan(e) else f'{e:.4f} {unit}'} |")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
