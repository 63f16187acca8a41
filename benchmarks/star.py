"""Seed 004 speed: an analytic 1024² star frame (target ≤ 50 ms) and the EKF over 20 frames (target ≤ 0.5 s).

Run: .venv/bin/python benchmarks/star.py   (prints best-of-N wall times on this machine)
"""

from __future__ import annotations

import time

import numpy as np

from rigsim.detector import apply_detector
from rigsim.estimation.star_calibration import run_ekf
from rigsim.imaging.stars import extract_stars
from rigsim.optics import attitude as att
from rigsim.procedures.star.study import CentroidNoise, case_setup, simulate_frames
from rigsim.render.star import render_stars
from rigsim.rig.load import load_star_rig
from rigsim.truth.star import StarSky


def best(fn, n=10):
    ts = []
    for _ in range(n):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return min(ts), float(np.median(ts))


def main():
    rig = load_star_rig()
    sky = StarSky(rig)
    s = rig.sensor
    seq = att.from_rig(rig.sequence)
    k = 10
    tr = sky.field(seq.R_cam_from_icrs[k], omega_cam_rad_s=seq.omega_cam_rad_s[k], substeps=8, margin_px=-4)
    print(f"# seed-004 benchmark: 1024² frame, {len(tr)} stars (Hp ≤ {rig.sky.magnitude_limit}), PSF σ {s.psf_sigma_px:.2f} px, "
          f"8 smear sub-steps")
    t_field = best(lambda: sky.field(seq.R_cam_from_icrs[k], omega_cam_rad_s=seq.omega_cam_rad_s[k], substeps=8, margin_px=-4))
    t_render = best(lambda: render_stars(tr.uv_substeps, tr.photons, tr.shape_hw, s.psf_sigma_px,
                                         background=tr.background_photons_per_px), 20)
    img = render_stars(tr.uv_substeps, tr.photons, tr.shape_hw, s.psf_sigma_px, background=tr.background_photons_per_px)
    t_det = best(lambda: apply_detector(img, s.detector, seed=1), 5)
    dn = apply_detector(img, s.detector, seed=1).dn
    t_ext = best(lambda: extract_stars(dn, s.detector, s.psf_sigma_px), 5)
    print(f"star field (catalogue cone, projection): best {1e3 * t_field[0]:.1f} ms, median {1e3 * t_field[1]:.1f} ms")
    print(f"analytic photon frame (target ≤ 50 ms):  best {1e3 * t_render[0]:.1f} ms, median {1e3 * t_render[1]:.1f} ms")
    print(f"  + detector model (rigsim.detector):    best {1e3 * t_det[0]:.1f} ms, median {1e3 * t_det[1]:.1f} ms")
    print(f"  field + photons + detector:            {1e3 * (t_field[0] + t_render[0] + t_det[0]):.1f} ms (best)")
    print(f"extraction + centroiding (find_spots):   best {1e3 * t_ext[0]:.1f} ms")
    noise = CentroidNoise.from_rig(rig, background_photons_per_px=sky.background_photons_per_px)
    frames = simulate_frames(sky, seq, noise, np.random.default_rng(0), rig.calibration.max_stars_per_frame)
    for case in ("f_known", "f_joint"):
        th0, est, ps = case_setup(rig, case)
        for model in ("ad", "ads", "ads_improved"):
            t = best(lambda: run_ekf(frames, th0, model=model, estimate=est, prior_sigma=ps), 5)
            print(f"EKF over 20 frames × 20 stars, {case}, {model:12s} (target ≤ 0.5 s): best {1e3 * t[0]:.1f} ms, "
                  f"median {1e3 * t[1]:.1f} ms")


if __name__ == "__main__":
    main()
