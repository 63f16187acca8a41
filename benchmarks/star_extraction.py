"""Star extraction on real frames: rigsim's star-field extractor against sep's extractor (and,
when a Python with cedar-solve is given, cedar-solve's own), side by side in one run.

Per frame and per extractor: the time of one extraction (best of --repeat, the extractors
interleaved so that a shared machine's load hits them alike), the stars found, and the share of
the stars the independent solver matched (cedar-solve's matched centroids, from the JSON beside the
frames) that the extractor found within 1 px. rigsim's time covers the whole of
:func:`rigsim.imaging.star_field.extract_star_field` (sky map, detection, every star's Gaussian fit);
sep's covers ``sep.Background`` and ``sep.extract`` (threshold 5σ of the background rms, minimum area
3 px); the old rigsim path is ``rigsim centroid --method gauss`` before the star-field extractor (one
background level and one noise value per frame).

Run:  .venv/bin/python benchmarks/star_extraction.py [FRAMES...] [--repeat 7] [--cedar-python PATH]
(default frames: docs/examples/real-star-frames/*.tiff)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
FRAMES = REPO / "docs" / "examples" / "real-star-frames"

_CEDAR = r"""
import json, sys, time, numpy as np, tifffile, tetra3
out = {}
for f in sys.argv[2:]:
    img = tifffile.imread(f).astype(np.float32)
    ts = []
    for _ in range(int(sys.argv[1])):
        t0 = time.perf_counter(); c = tetra3.get_centroids_from_image(img); ts.append(time.perf_counter() - t0)
    out[f] = {"best_s": min(ts), "n": len(c), "uv": (np.asarray(c)[:, ::-1] - 0.5).tolist()}
print(json.dumps(out))
"""


def _matched(ref: dict, name: str) -> np.ndarray:
    c = np.asarray(ref[name]["matched_centroids"], float)  # (y, x), pixel (0, 0)'s centre at (0.5, 0.5)
    return c[:, ::-1] - 0.5


def _found(uv: np.ndarray, want: np.ndarray) -> float:
    if len(uv) == 0 or len(want) == 0:
        return 0.0
    d = np.hypot(want[:, None, 0] - uv[None, :, 0], want[:, None, 1] - uv[None, :, 1])
    return float(np.mean(np.nanmin(d, axis=1) < 1.0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("frames", nargs="*", help="16-bit TIFF/PNG frames (default: the repository's real frames)")
    ap.add_argument("--repeat", type=int, default=7, help="timed runs per extractor and frame (best kept)")
    ap.add_argument("--reference", default=None, help="cedar-solve solutions JSON (default: beside the frames)")
    ap.add_argument("--cedar-python", default=None, help="a Python with cedar-solve and tifffile: also time its extractor")
    a = ap.parse_args()
    import cv2
    import sep

    from rigsim.imaging.detect import find_spots
    from rigsim.imaging.star_field import extract_star_field

    paths = [Path(p) for p in a.frames] or sorted(FRAMES.glob("*.tiff"))
    ref_path = Path(a.reference) if a.reference else (paths[0].parent / "cedar-solve-solutions.json")
    ref = json.loads(ref_path.read_text()) if ref_path.exists() else {}
    cedar = {}
    if a.cedar_python:
        p = subprocess.run([a.cedar_python, "-c", _CEDAR, str(a.repeat), *map(str, paths)], capture_output=True,
                           text=True, check=True)
        cedar = json.loads(p.stdout.strip().splitlines()[-1])

    def rigsim_new(img):
        sf = extract_star_field(img, psf_sigma_px=0.8, gain_dn_per_e=6.0)
        return sf.uv

    def rigsim_old(img):
        res, _ = find_spots(img.astype(float), method="gauss", threshold_sigma=5.0, saturation=65535.0)
        return np.stack([res.u, res.v], 1) if len(res) else np.zeros((0, 2))

    def sep_extract(img):
        f = img.astype(np.float32)
        bk = sep.Background(f)
        obj = sep.extract(f - bk.back(), 5.0, err=bk.rms(), minarea=3)
        return np.stack([obj["x"], obj["y"]], 1)

    ways = {"rigsim (star field)": rigsim_new, "sep": sep_extract, "rigsim before (one background)": rigsim_old}
    print(f"{'frame':<34} {'extractor':<32} {'ms':>7} {'stars':>6} {'matched found':>14}")
    tot = {k: 0.0 for k in ways}
    found = {k: [] for k in ways}
    for p in paths:
        img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        best = {k: np.inf for k in ways}
        out = {}
        for _ in range(a.repeat):
            for k, fn in ways.items():
                t0 = time.perf_counter()
                out[k] = fn(img)
                best[k] = min(best[k], time.perf_counter() - t0)
        want = _matched(ref, p.name) if p.name in ref else np.zeros((0, 2))
        rows = [(k, best[k], out[k]) for k in ways]
        if str(p) in cedar:
            c = cedar[str(p)]
            rows.append(("cedar-solve", c["best_s"], np.asarray(c["uv"])))
            tot.setdefault("cedar-solve", 0.0)
            found.setdefault("cedar-solve", [])
        for k, t, uv in rows:
            f = _found(uv, want) if len(want) else float("nan")
            tot[k] += t
            found[k].append(f)
            print(f"{p.name:<34} {k:<32} {1e3 * t:>7.1f} {len(uv):>6d} {100 * f:>13.0f}%")
    print()
    base = tot["sep"]
    for k, t in tot.items():
        print(f"total {k:<32} {1e3 * t:>8.1f} ms   ratio to sep {t / base:5.2f}"
              + (f"   ratio to cedar-solve {t / tot['cedar-solve']:5.2f}" if "cedar-solve" in tot else "")
              + f"   matched stars found {100 * np.nanmean(found[k]):.0f}%")


if __name__ == "__main__":
    sys.exit(main())
