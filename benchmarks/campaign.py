"""Wall time of the rendered cube-mirror campaign, split by stage (issue 5).

    .venv/bin/python benchmarks/campaign.py [--rig sun_sensor_2axis_diaphragm] [--trials 200] [--seed 2009]

Runs exactly what ``rigsim run cube-mirror`` runs (default rig, default settings) and prints the
seconds per stage, the frames rendered and the truth-vs-recovered error. Load on the machine
matters: the Mitsuba renders use one thread each (bit-reproducible frames), the budget is numpy.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

from rigsim.truth.cube_mirror.realization import realization_from_rig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rig", default="sun_sensor_2axis_diaphragm")
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--seed", type=int, default=2009)
    ap.add_argument("--repeat-frames", type=int, default=4)
    ap.add_argument("--aiming-workers", type=int, default=1)
    a = ap.parse_args()

    t_import = time.perf_counter()
    from rigsim.procedures.cube_mirror import rendered_campaign as rc
    from rigsim.render.backend import ensure_variant
    from rigsim.rig import load_rig

    variant = ensure_variant()
    t_import = time.perf_counter() - t_import
    rig = load_rig(a.rig)
    real = realization_from_rig(rig)
    print(f"rig {rig.name}, variant {variant}, load average {os.getloadavg()[0]:.2f}, import + variant {t_import:.1f} s")
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        camp = rc.run_rendered_campaign(rig, real, seed=a.seed, repeat_frames=a.repeat_frames,
                                        aiming_workers=a.aiming_workers)
    t_camp = time.perf_counter() - t0
    mn = camp.measured_noise
    t0 = time.perf_counter()
    rc.rendered_error_budget(rig, a.trials, a.seed + 1, null_sigma=mn["null_measurement_rms"],
                             centroid_sigma_px=mn["sun_centroid_rms_px"])
    t_budget = time.perf_counter() - t0
    frames = camp.sweep.n_rendered + sum(len(s.steps) for s in camp.searches) + a.repeat_frames
    print(f"\n{'stage':<45} {'s':>8}")
    for k, v in camp.times.items():
        print(f"{k:<45} {v:>8.2f}")
    print(f"{'error budget (' + str(a.trials) + ' campaigns per row)':<45} {t_budget:>8.2f}")
    print(f"{'total (campaign + budget)':<45} {t_camp + t_budget:>8.2f}")
    print(f"\nframes rendered: {frames} (sweep {camp.sweep.n_rendered}, search "
          f"{[len(s.steps) for s in camp.searches]}, repeat {a.repeat_frames})")
    print(f"sweep: {camp.times['sweep render + centroid'] / camp.sweep.n_rendered * 1e3:.0f} ms per sun-sensor frame")
    e = camp.error_arcsec
    print(f"R(cube←sun) error: {e[0]:+.3f} {e[1]:+.3f} {e[2]:+.3f}″ (|δ| {np.linalg.norm(e):.3f}″)")
    print(f"measured: sun centroid {mn['sun_centroid_rms_px']:.4f} px rms, null measurement "
          f"{mn['null_measurement_rms']:.4f} {mn['null_measurement_unit']} rms")


if __name__ == "__main__":
    main()
