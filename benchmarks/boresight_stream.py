"""Rows per second through `rigsim boresight solve --stream` (a real-time loop: one CSV row of spot
centroids in, one row of (Δf, α, β, γ) out, flushed per row), against the in-process batch solve
of the same rows. Usage: python benchmarks/boresight_stream.py [ROWS]"""

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rigsim.estimation.dvad import estimate
from rigsim.files import write_table
from rigsim.optics.line_camera import CameraGeometry
from rigsim.rig.load import load_boresight_rig


def main(n: int = 20000) -> None:
    rig = load_boresight_rig()
    cam = rig.cameras[0]
    geom = CameraGeometry.from_rig(cam)
    ref = geom.reference_uv
    rng = np.random.default_rng(0)
    uv = ref + rng.normal(0.0, 0.3, (n, 2, 2))
    with tempfile.TemporaryDirectory() as d:
        rp = Path(d) / "ref.csv"
        write_table(rp, {"camera": [cam.name], "u_m1_px": [ref[0, 0]], "v_m1_px": [ref[0, 1]], "u_m2_px": [ref[1, 0]],
                         "v_m2_px": [ref[1, 1]]})
        rows = "camera,u_m1_px,v_m1_px,u_m2_px,v_m2_px\n" + "".join(
            f"{cam.name},{a!r},{b!r},{c!r},{e!r}\n" for (a, b), (c, e) in uv.tolist())
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "rigsim.cli", "boresight", "solve", "--reference", str(rp), "--stream"],
                           input=rows, capture_output=True, text=True)
        if p.returncode:
            sys.exit(p.stderr)
        wall = time.perf_counter() - t0
        # start-up alone (no rows), to separate it from the per-row rate
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "rigsim.cli", "boresight", "solve", "--reference", str(rp), "--stream"],
                       input="camera,u_m1_px,v_m1_px,u_m2_px,v_m2_px\n", capture_output=True, text=True, check=True)
        start = time.perf_counter() - t0
    out = np.array([[float(x) for x in ln.split(",")[2:]] for ln in p.stdout.strip().splitlines()[1:]])
    t0 = time.perf_counter()
    b = estimate(geom, ref, uv, "dvad")
    batch = time.perf_counter() - t0
    bb = np.column_stack([b.delta_f_mm * 1e3, b.angles_arcsec])
    print(f"{n} rows through `rigsim boresight solve --stream`: {wall:.2f} s wall, of which start-up {start:.2f} s")
    print(f"streaming rate: {n / (wall - start):,.0f} rows/s (target ≥ 1,000); per row {1e6 * (wall - start) / n:.0f} µs")
    print(f"in-process batch solve of the same rows: {n / batch:,.0f} rows/s; max |stream − batch| "
          f"{np.abs(out - bb).max():.2e} (µm, ″)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20000)
