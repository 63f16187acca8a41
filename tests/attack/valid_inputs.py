"""Valid inputs for the file commands, cheap to make (no rendering): a sun-sensor sweep's angle log and centroid
table from the analytic campaign, a null log, and the triad/calibration results built from them. The attack suite
and the tests give them to a command whose output option names one of them: without the output checks the command
would run to its writes and destroy them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

RIG = "sun_sensor_2axis_diaphragm"
NULLS = "face,x_deg,y_deg\n+Z,181.398,0.528\n+Y,91.386,-0.048\n"


def sweep_tables(folder, rig: str = RIG, sigma_px: float = 0.03, seed: int = 0) -> tuple[Path, Path]:
    """angles.csv (frame, x_deg, y_deg) and centroids.csv (frame, u_px, v_px) of the analytic sweep of ``rig``."""
    from rigsim.files import write_table
    from rigsim.procedures.cube_mirror import campaign as cm
    from rigsim.rig import load_rig
    from rigsim.truth.cube_mirror.realization import realization_from_rig

    r = load_rig(rig)
    readings, uv = cm.simulate_sweep(r, realization_from_rig(r, ideal=True), cm.Noise(centroid_sigma_px=sigma_px),
                                     np.random.default_rng(seed))
    names = [f"f{k:04d}.png" for k in range(len(uv))]
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    a = write_table(folder / "angles.csv", {"frame": names, **{f"{k.lower()}_deg": np.degrees(v) for k, v in readings.items()}})
    c = write_table(folder / "centroids.csv", {"frame": names, "u_px": uv[:, 0], "v_px": uv[:, 1]})
    return a, c


def nulls(folder) -> Path:
    p = Path(folder) / "nulls.csv"
    p.write_text(NULLS)
    return p
