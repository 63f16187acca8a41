"""The Cramér–Rao bound the sweep's frames put on R(sun←rot), and one sweep's error against it.

Renders a cube-mirror rig's sun-sensor sweep (the procedure's poses, the rig's detector, an ideal
turntable so that the exact spot centres fit the calibration model exactly) with the chosen
effects, fits every frame with the forward-model centroider (each frame's σ is its inverse Fisher
information about the spot's position, flux and background solved with it), and propagates those
σ through the sweep fit's Jacobian: the weighted fit of the *exact* centres with the measured σ has
zero residuals, so its covariance is (Σ Jᵢᵀ Cᵢ⁻¹ Jᵢ)⁻¹, the information of every frame about
R(sun←rot) and the intrinsics — the bound no unbiased estimator on these frames can beat. The
measured centroids' own weighted fit gives one sample of the error against it.

    python scripts/sweep_fisher_bound.py sun_sensor_2axis_diaphragm --effects pinhole_diffraction --seed 0
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from rigsim.estimation.sun_calibration import calibrate_sun_sensor
from rigsim.frames import ARCSEC_PER_RAD, small_angle_error
from rigsim.procedures.cube_mirror import campaign as cm
from rigsim.procedures.cube_mirror.pipeline import default_axis_order
from rigsim.procedures.robustness import ALL, IDEAL, rig_with
from rigsim.procedures.cube_mirror.sweep import render_sweep
from rigsim.rig import load_rig
from rigsim.rig.turntable import TurntableModel
from rigsim.truth.cube_mirror.realization import realization_from_rig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rig")
    ap.add_argument("--effects", default="", help="comma-separated effect names (default: ideal frames)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--field-deg", type=float, nargs="*", default=[90.0, 62.0], help="field limits to report")
    ap.add_argument("--out", help="write the numbers as JSON")
    a = ap.parse_args()
    names = tuple(n for n in a.effects.split(",") if n)
    rig = load_rig(a.rig)
    r = rig_with(rig, (names[0] if len(names) == 1 else ALL) if names else IDEAL, names)
    real = realization_from_rig(r, ideal=True)
    t0 = time.perf_counter()
    obs, truth = render_sweep(r, real, cm.Noise(), a.seed)
    ss = r.sun_sensor
    order = default_axis_order(r)
    tt = TurntableModel.nominal(list(order))
    out = {"rig": r.name, "effects": list(names), "seed": a.seed, "frames": len(obs.uv),
           "render_s": round(time.perf_counter() - t0, 1), "by_field_limit": {}}
    for lim in a.field_deg:
        kw = dict(f_guess_px=ss.fx_px, sigma_uv=obs.sigma_uv, weighted=True, max_field_deg=lim)
        bound = calibrate_sun_sensor(obs.readings, truth.uv_centre, tt, *ss.resolution_px, **kw)
        meas = calibrate_sun_sensor(obs.readings, obs.uv, tt, *ss.resolution_px, **kw)
        sd = np.sqrt(np.diag(bound.rotation_covariance_rad2)) * ARCSEC_PER_RAD
        err = small_angle_error(meas.R_sun_from_rot, real.R_sun_from_mount) * ARCSEC_PER_RAD
        out["by_field_limit"][f"{lim:g}"] = {
            "frames_used": int(bound.n_points), "bound_sun_rot_arcsec": [round(float(x), 3) for x in sd],
            "measured_error_arcsec": [round(float(x), 3) for x in err],
            "measured_chi2_dof": round(float(meas.fit.chi2_dof), 3) if meas.fit else None,
            "centroid_sigma_median_px": round(float(np.median(obs.sigma_uv)), 4)}
        print(f"{r.name} {','.join(names) or 'ideal'} field ≤ {lim:g}°: {bound.n_points} frames, bound on R(sun←rot) "
              f"{sd[0]:.3f} / {sd[1]:.3f} / {sd[2]:.3f}″; this sweep's error {err[0]:+.3f} / {err[1]:+.3f} / "
              f"{err[2]:+.3f}″ (χ²/dof {out['by_field_limit'][f'{lim:g}']['measured_chi2_dof']})", flush=True)
    if a.out:
        with open(a.out, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
