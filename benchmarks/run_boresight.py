"""``rigsim run boresight`` end to end, old vs new: the whole command in-process (the CLI's own entry
point, report written to a temporary folder), default options (rig dual_line_array_prism, its seed,
1200 Monte-Carlo runs, the rendered orbit scenario: 140 Mitsuba ROIs).

Prints the best wall time, speed-up and peak RSS of each side, and from the written boresight.json:
the orbit's relative-angle RMS errors (DVAD, x/y/z in arcsec), Fig 5's DVAD 3σ α/β/γ (arcsec), the
render-vs-exact fidelity (px), which should agree between old and new; and the run's stage seconds
(analyses, orbit, orbit warm-up). The new side renders camera 1's frames in a worker subprocess
(procedures/boresight/frame_pool.py) and draws the report's rig picture in another; both are in their
own session, so on a shared machine (Linux autogroups) they also get their own share of the CPU. The
load average is printed before and after: compare the ratio, not the seconds, on a busy machine.

Usage: PYTHONPATH=src .venv/bin/python benchmarks/run_boresight.py [--repeat 1] [--rounds 1]
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _compare import main_for

SETUP = """
import json, os, tempfile, io, contextlib
from rigsim.cli import main
RIG = {rig!r}
"""

STMT = """
out = tempfile.mkdtemp(prefix="bench-boresight-")
with contextlib.redirect_stdout(io.StringIO()):
    rc = main(["run", "boresight", "--rig", RIG, "--out", out, "--quiet"])
assert rc == 0
d = json.load(open(os.path.join(out, "boresight.json")))
k = d["key_numbers"]
rel = k["orbit_relative_rms_arcsec"]
f5 = k["fig5_3sigma"]["dvad"]
result = {"orbit_rel_rms_x_arcsec": rel[0], "orbit_rel_rms_y_arcsec": rel[1], "orbit_rel_rms_z_arcsec": rel[2],
          "fig5_dvad_3s_alpha_arcsec": f5["alpha_arcsec"], "fig5_dvad_3s_beta_arcsec": f5["beta_arcsec"],
          "fig5_dvad_3s_gamma_arcsec": f5["gamma_arcsec"], "render_fidelity_max_px": k["render_fidelity_max_px"],
          "stage_analyses_s": d["analysis_seconds"], "stage_orbit_s": d["orbit"]["seconds"],
          "stage_orbit_warm_up_s": d["orbit"]["warm_up_seconds"], "stage_study_s": d["seconds"]}
"""


def main() -> None:
    rig = str(Path(__file__).resolve().parents[1] / "scenes" / "dual_line_array_prism.toml")
    print("load average before: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))
    main_for(__doc__, "run boresight (default)", SETUP, STMT, target="<= 20 s", rig=rig)
    print("load average after:  {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))


if __name__ == "__main__":
    main()
