"""cedar-solve's solutions of star frames, as JSON: the independent reference the lost-in-space
tests compare with (docs/examples/real-star-frames/cedar-solve-solutions.json).

cedar-solve (PyPI ``cedar-solve``, a maintained fork of ESA's tetra3 plate solver) pins an older
numpy than rigsim, so this script runs in its OWN virtualenv, never in rigsim's:

    python3 -m venv /tmp/cedar-venv
    /tmp/cedar-venv/bin/pip install cedar-solve==0.5.1 tifffile
    /tmp/cedar-venv/bin/python scripts/cedar_solutions.py docs/examples/real-star-frames/*.tiff \\
        --out docs/examples/real-star-frames/cedar-solve-solutions.json

It imports nothing of rigsim. Each frame is read as it is (16-bit TIFF), centroided with cedar's own
``get_centroids_from_image`` and solved with ``solve_from_centroids`` on cedar's bundled default
database with no field-of-view hint. Per frame the JSON holds what cedar returns: RA, Dec, Roll,
FOV (horizontal, degrees), distortion (cedar's radial term at half the width), RMSE (arcsec),
Matches, Prob, the epochs of its catalogue, matched_centroids as (y, x) pixels with (0.5, 0.5) the
centre of the top-left pixel (cedar's convention; rigsim's is (0, 0)), matched_catID (HIP numbers)
and matched_stars (RA, Dec, magnitude). ``_about`` records the versions and the call.
"""

from __future__ import annotations

import argparse
import importlib.metadata as metadata
import json
import sys
import time
from pathlib import Path

import numpy as np


def _plain(v):
    if isinstance(v, (str, int, float, bool, type(None))):
        return v
    a = np.asarray(v)
    return a.item() if a.ndim == 0 else a.tolist()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("frames", nargs="+", type=Path, help="16-bit TIFF frames")
    ap.add_argument("--out", type=Path, required=True, help="the JSON file to write")
    a = ap.parse_args(argv)
    import tetra3
    import tifffile

    t3 = tetra3.Tetra3()
    out = {"_about": {"solver": f"cedar-solve {metadata.version('cedar-solve')}",
                      "numpy": np.__version__, "tifffile": metadata.version("tifffile"),
                      "call": "tetra3.get_centroids_from_image(image.astype(float32)); "
                              "Tetra3().solve_from_centroids(centroids, (height, width), return_matches=True)",
                      "centroid_convention": "(y, x) px, (0.5, 0.5) = centre of the top-left pixel"}}
    for f in sorted(a.frames):
        img = tifffile.imread(f)
        t0 = time.perf_counter()
        cents = tetra3.get_centroids_from_image(img.astype(np.float32))
        t1 = time.perf_counter()
        sol = t3.solve_from_centroids(cents, img.shape[:2], return_matches=True)
        t2 = time.perf_counter()
        sol = {k: _plain(v) for k, v in sol.items() if k not in ("T_solve", "cache_hit_fraction")}
        sol["centroids_found"] = int(len(cents))
        out[f.name] = sol
        print(f"{f.name}: {len(cents)} centroids in {1e3 * (t1 - t0):.0f} ms, solved in {1e3 * (t2 - t1):.0f} ms: "
              f"FOV {sol.get('FOV')}, {sol.get('Matches')} matches", file=sys.stderr)
    a.out.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
