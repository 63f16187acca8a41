"""``rigsim run star-calibration`` end to end, old vs new: the whole command in-process (the CLI's own
entry point, report written to a temporary folder), default options (seed 0, analytic renderer, both
studies: 200 trials, 30 readings trials per cell).

Prints the best wall time, speed-up and peak RSS of each side, and from the written
star_calibration.json: the batch least-squares errors against truth (f, u0, v0 in px), the study's RMS
u0/v0 errors (f known, AD and ADS, px) and the readings study's RMS u0 of AD/ADS (all/propagated,
f+1, px), which should agree between old and new; and the run's own per-stage seconds.

Usage: PYTHONPATH=src .venv/bin/python benchmarks/run_star.py [--repeat 1] [--rounds 1]
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _compare import main_for

SETUP = """
import json, os, tempfile, io, contextlib
os.environ.setdefault("TQDM_DISABLE", "1")
from rigsim.cli import main
RIG = {rig!r}
"""

STMT = """
out = tempfile.mkdtemp(prefix="bench-star-")
with contextlib.redirect_stdout(io.StringIO()):
    rc = main(["run", "star-calibration", "--rig", RIG, "--out", out, "--quiet"])
assert rc == 0
d = json.load(open(os.path.join(out, "star_calibration.json")))
err = d["batch"]["error"]
st = d["study"]["rms_px"]
row = [r for r in d["readings_study"]["rows"] if (r["case"], r["equations"], r["weighting"]) == ("f+1", "all", "propagated")][0]
result = {"batch_f_err_px": err[0], "batch_u0_err_px": err[1], "batch_v0_err_px": err[2],
          "study_ad_u0_rms_px": st["f_known/ad"][0], "study_ads_u0_rms_px": st["f_known/ads"][0],
          "readings_ad_u0_rms_px": row["rms_ad_px"][0], "readings_ads_u0_rms_px": row["rms_ads_px"][0]}
for k, v in d.get("times_s", {}).items():   # per-stage seconds of the run (its own timer)
    result["stage_" + "".join(c if c.isalnum() else "_" for c in k.split(" (")[0]) + "_s"] = v
"""


def main() -> None:
    # the default rig by name: each side reads its own scenes/star_sensor.toml (the old package does not
    # know the new file's [effects] and defect settings)
    main_for(__doc__, "run star-calibration (default)", SETUP, STMT, target="<= 40 s", rig="star_sensor")


if __name__ == "__main__":
    main()
