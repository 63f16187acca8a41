"""The main job, `rigsim run cube-mirror` on the default rig, old vs new side by side in one run.

    .venv/bin/python benchmarks/main_job.py [--rounds 1] [--ideal] [--base COMMIT]

Runs the whole command in a fresh process for the old package (the commit before the speed work)
and the new one, alternately, and prints wall time, peak resident memory of the main process, the
peak of the summed PSS of the whole process tree (the aiming-camera workers, the budget's workers and
the rig-picture process included; sampled every 50 ms), the campaign's R(cube←sun) error per axis
and the budget's σ per axis. Targets: ≤ 30 s and ≤ 600 MB on 2 cores,
the same accuracy: with ``--ideal`` (no rig errors, no noise) the error must be unchanged; the
default run's numbers must agree within their Monte-Carlo noise (the budget's σ per axis).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _compare import BASE, compare

SETUP = """
import json, tempfile, warnings
from pathlib import Path
from rigsim.cli import main
"""

STMT = """
out = Path(tempfile.mkdtemp(prefix="rigsim-bench-main-"))
rc = main(["run", "cube-mirror", "--out", str(out), "--quiet"{extra}])
assert rc in (0, None), rc
d = json.loads((out / "campaign.json").read_text())
e = d["error_arcsec"]
result = {{"err_x_arcsec": e[0], "err_y_arcsec": e[1], "err_z_arcsec": e[2],
          "sun_centroid_rms_px": d["measured_noise"]["sun_centroid_rms_px"]}}
for row in d.get("budget") or []:
    if row["source"].startswith("all"):
        result.update({{"budget_all_x_arcsec": row["sigma_arcsec"][0], "budget_all_y_arcsec": row["sigma_arcsec"][1],
                       "budget_all_z_arcsec": row["sigma_arcsec"][2]}})
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=1, help="old/new pairs (default 1)")
    ap.add_argument("--ideal", action="store_true", help="the noise-free ideal campaign instead of the default run")
    ap.add_argument("--base", default=BASE, help=f"the old side's commit (default {BASE}, before the speed work)")
    a = ap.parse_args()
    extra = ', "--ideal"' if a.ideal else ""
    name = "run cube-mirror" + (" --ideal" if a.ideal else "")
    compare(name, SETUP, STMT.format(extra=extra), repeat=1, rounds=a.rounds, target="≤ 30 s, ≤ 600 MB", base=a.base,
            tree=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
