"""Speed and accuracy of the analytic cube-mirror campaign (issue 2). Prints measured numbers.

    .venv/bin/python benchmarks/campaign_analytic.py
"""

import time

import numpy as np

from rigsim.errors import GeometryError
from rigsim.estimation.cube_attitude import cube_from_rot_triad
from rigsim.frames import ARCSEC_PER_RAD, random_rotations, rotation_angle
from rigsim.optics.cube import FACE_NORMALS
from rigsim.procedures.cube_mirror import campaign as cm
from rigsim.rig import load_rig
from rigsim.rig.turntable import TurntableModel
from rigsim.truth.cube_mirror.realization import realization_from_rig


def timeit(fn, n):
    t = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t) / n


def main():
    for name in ("sun_sensor_2axis_diaphragm", "sun_sensor_3axis_autocollimator"):
        rig = load_rig(name)
        rng = np.random.default_rng(0)
        real, noise = realization_from_rig(rig), cm.noise_from_rig(rig)
        t_full = timeit(lambda: cm.run_campaign(rig, real, noise, rng), 20)
        t_nofit = timeit(lambda: cm.run_campaign(rig, real, noise, rng, fit_calibration=False), 50)
        ideal = cm.run_campaign(rig, realization_from_rig(rig, ideal=True), cm.Noise(), rng)
        print(f"{name}: campaign with sweep fit {t_full * 1e3:.1f} ms, without {t_nofit * 1e3:.1f} ms; "
              f"ideal-rig error |δ| = {np.linalg.norm(ideal.error_arcsec):.2e}″")

    # round trip: random orientations → exact null angles → TRIAD
    model = TurntableModel.nominal(["X", "Y"])
    d = np.array([0.0, 0.0, 1.0])
    starts = [{"X": np.radians(x), "Y": np.radians(y)} for x in (0, 90, 180, 270) for y in (-60, 0, 60)]
    errs = []
    t = time.perf_counter()
    for R in random_rotations(500, np.random.default_rng(1)):
        poses = []
        for f in ("+Z", "+Y"):
            for s in starts:
                try:
                    poses.append(model.solve_alignment(R.T @ FACE_NORMALS[f], d, ["X", "Y"], s, max_move_rad=np.pi))
                    break
                except GeometryError:
                    pass
        errs.append(rotation_angle(cube_from_rot_triad(poses, ["+Z", "+Y"], "XY")[0], R))
    dt = (time.perf_counter() - t) / 500
    errs = np.array(errs)
    print(f"round trip over 500 random orientations: max {errs.max():.2e} rad ({errs.max() * ARCSEC_PER_RAD:.2e}″), "
          f"median {np.median(errs):.2e} rad; {dt * 1e3:.2f} ms each")

    rig = load_rig("sun_sensor_2axis_diaphragm")
    t = time.perf_counter()
    cm.error_budget(rig, 100, 1)
    print(f"error budget, 7 rows × 100 campaigns: {time.perf_counter() - t:.1f} s")


if __name__ == "__main__":
    main()
