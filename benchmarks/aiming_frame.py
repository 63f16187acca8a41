"""One aiming-camera frame of the default rig (diaphragm screen, divergent beam), old vs new.

    PYTHONPATH=src .venv/bin/python benchmarks/aiming_frame.py            # 3 frames × 2 rounds per side
    PYTHONPATH=src .venv/bin/python benchmarks/aiming_frame.py --quick    # 2 frames × 1 round
    ... benchmarks/aiming_frame.py --base COMMIT                          # old side at COMMIT

Cases (each in fresh subprocesses, old package = git archive of the base commit, alternating):

1. ``scene build``: :class:`ConcentricityRenderer` for face +Z (Mitsuba scenes, screen grid, disk).
2. ``frame``: one hole + spot frame pair at the demo pose (after a warm-up frame: JIT), with the
   detector; the result is the measured hole/spot offset (the ``rigsim concentricity`` stage)
   minus the exact offset, in px, the screen-plane spot centre of the photon image against
   the analytic image, in µm, and this process's CPU seconds for the frame (a load-robust
   figure: with one worker the frame is single-threaded). Again with ``workers=2`` (new only).
3. ``concentricity search``: the rendered search of face +Z (Table 1), scene build included.

Then, new package only: the SHA-1 of one frame's two uint16 images rendered with Dr.Jit at 1 and
at 2 threads (must be equal: the render is single-threaded and seeded).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _compare import BASE, REPO, compare

COMMON = """
import math, warnings, hashlib
import numpy as np
warnings.simplefilter("ignore")
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.realization import realization_from_rig
from rigsim.render.cube_mirror.aiming import ConcentricityRenderer
rig = load_rig("scenes/sun_sensor_2axis_diaphragm.toml")  # the run folder is the repository
real = realization_from_rig(rig)
"""

FRAME_SETUP = COMMON + """
from rigsim.procedures.cube_mirror.null_files import measure_concentricity
from rigsim.imaging.screen import masked_screen_centroid
from rigsim.truth.cube_mirror.diaphragm import rasterise_screen_disk
r = ConcentricityRenderer(rig, real, 0)
g = r.geometry
pose = dict(g.layout.null_pose_rad)
pose["X"] += math.radians(-60.0 / 3600)
pose["Y"] += math.radians(40.0 / 3600)
r.render(pose, seed=100)  # warm-up: JIT of both scenes
tr = r.truth(pose)
exact_img = r.diverge(rasterise_screen_disk(g, tr.offset_mm, g.hole_radius_mm, value=1.0))
c_exact, _ = masked_screen_centroid(exact_img, g, 0.1)
"""

FRAME_STMT = """
import time as _t
_c0 = _t.process_time()
fr = r.render(pose, seed=7)
cpu_s = _t.process_time() - _c0
m = measure_concentricity(rig, fr.hole.dn, fr.spot.dn)
exact_px = np.asarray(fr.truth.offset_mm) / rig.aiming_camera.object_pixel_mm
err = np.asarray(m["offset_px"]) - exact_px
c_r, _ = masked_screen_centroid(fr.spot_photons, g, 0.1)
result = {"offset_err_x_px": err[0], "offset_err_y_px": err[1],
          "photon_centre_err_um": 1e3 * float(np.linalg.norm(c_r - c_exact)), "cpu_s_this_process": cpu_s}
"""

SEARCH_SETUP = COMMON + """
from rigsim.procedures.cube_mirror.concentricity import OffsetMeasurer, concentricity_search
"""

SEARCH_STMT = """
r = ConcentricityRenderer(rig, real, 0)
m = OffsetMeasurer(rig, real, 0, renderer=r, seed=11)
res = concentricity_search(rig, real, 0, m, {"X": 0.0, "Y": 0.0})
last = res.steps[-1]
err = np.asarray(last.measured) - (np.asarray(last.true) - m.bias_px)
result = {"frames": len(res.steps), "final_err_x_px": err[0], "final_err_y_px": err[1]}
"""

IDENTITY = COMMON + """
import drjit as dr
r = ConcentricityRenderer(rig, real, 0)
pose = dict(r.geometry.layout.null_pose_rad)
pose["X"] += math.radians(-60.0 / 3600)
out = {}
for n in (1, 2):
    dr.set_thread_count(n)
    fr = r.render(pose, seed=5)
    out[n] = hashlib.sha1(fr.hole.dn.tobytes() + fr.spot.dn.tobytes()).hexdigest()[:16]
print("frame SHA-1 with 1 Dr.Jit thread:", out[1], " with 2:", out[2], " identical:", out[1] == out[2])
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--base", default=BASE, help=f"git commit of the old side (default {BASE})")
    args = ap.parse_args()
    repeat, rounds = (2, 1) if args.quick else (3, 2)
    b = args.base
    compare("aiming-camera scene build, face +Z", COMMON, "r = ConcentricityRenderer(rig, real, 0)",
            repeat=repeat, rounds=rounds, base=b)
    compare("aiming-camera frame (hole + spot)", FRAME_SETUP, FRAME_STMT, repeat=repeat, rounds=rounds,
            target="≤ 1.0 s", base=b)
    compare("same, workers=2 (new only)", FRAME_SETUP.replace("(rig, real, 0)", "(rig, real, 0, workers=2)"),
            FRAME_STMT, repeat=repeat, rounds=rounds, old=False, target="≤ 1.0 s")
    compare("concentricity search, face +Z", SEARCH_SETUP, SEARCH_STMT, repeat=1, rounds=rounds, base=b)
    import os
    import subprocess

    env = dict(os.environ, PYTHONPATH=str(REPO / "src"))
    subprocess.run([sys.executable, "-c", IDENTITY], env=env, cwd=str(REPO), check=True)


if __name__ == "__main__":
    main()
