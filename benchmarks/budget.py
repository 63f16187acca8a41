"""The cube-mirror Monte-Carlo error budget, old vs new (issue: ≤ 8 s at 200 trials per row, same σ).

    .venv/bin/python benchmarks/budget.py [--rig sun_sensor_2axis_diaphragm] [--trials 200] [--seed 2010]
                                          [--repeat 1] [--rounds 2]

Runs :func:`rigsim.procedures.cube_mirror.rendered_campaign.rendered_error_budget` (what
``rigsim run cube-mirror`` runs after the rendered campaign) with the noise measured on the
default rig's published rendered run (renders/cube_mirror_sun-sensor-2axis-diaphragm/campaign.json)
under the old package (``benchmarks/_compare.py``'s base commit) and the working tree, and prints
the seconds and, in ``result``, the σ of every row and cube axis (arcsec) of both, so that their
identity for the same seed is visible. Single-threaded BLAS (the budget is small numpy).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _compare import REPO, compare


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rig", default="sun_sensor_2axis_diaphragm")
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--seed", type=int, default=2010)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--rounds", type=int, default=2)
    a = ap.parse_args()
    folder = {"sun_sensor_2axis_diaphragm": "cube_mirror_sun-sensor-2axis-diaphragm",
              "sun_sensor_3axis_autocollimator": "cube_mirror_sun-sensor-3axis-autocollimator"}.get(a.rig)
    mn = json.loads((REPO / "renders" / folder / "campaign.json").read_text())["measured_noise"] if folder else {}
    null_sigma = float(mn.get("null_measurement_rms", 0.05))
    centroid = float(mn.get("sun_centroid_rms_px", 0.008))
    setup = f"""
import os
for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[v] = "1"
import warnings
warnings.simplefilter("ignore")
from rigsim.rig import load_rig
from rigsim.procedures.cube_mirror.rendered_campaign import rendered_error_budget
rig = load_rig({str(REPO / "scenes" / (a.rig + ".toml"))!r})
"""
    # CPU seconds of this process and of its (finished) workers: on a loaded machine the wall time of
    # the new path depends on how much of a second core it gets; max(cpu main, cpu workers) is the
    # wall time it would take on two free cores, cpu main + workers the total work.
    stmt = f"""
import resource, time
c0, k0 = time.process_time(), resource.getrusage(resource.RUSAGE_CHILDREN)
b = rendered_error_budget(rig, {a.trials}, {a.seed}, null_sigma={null_sigma!r}, centroid_sigma_px={centroid!r})
k1 = resource.getrusage(resource.RUSAGE_CHILDREN)
result = {{"cpu main s": time.process_time() - c0,
          "cpu workers s": (k1.ru_utime + k1.ru_stime) - (k0.ru_utime + k0.ru_stime)}}
result.update({{f"row{{i}} {{ax}}": s for i, r in enumerate(b.rows) for ax, s in zip("xyz", r.sigma_arcsec)}})
"""
    print(f"rig {a.rig}, {a.trials} trials per row, seed {a.seed}, null σ {null_sigma:.4g}, centroid σ {centroid:.4g} px")
    sides = compare(f"error budget ({a.trials} per row)", setup, stmt, repeat=a.repeat, rounds=a.rounds,
                    target="≤ 8 s quiet (13.6 s today), same σ")
    o, n = sides["old"].result, sides["new"].result
    if o and n:
        print(f"max |σ_new − σ_old| over rows and axes: {max(abs(o[k] - n[k]) for k in o if k.startswith('row')):.3g}″")


if __name__ == "__main__":
    main()
