"""The forward-model star centroider's error against the Cramér–Rao bound (docs/effects-star.md,
"The forward-model centroider"): isolated stars on a grid over the star sensor's detector, rendered
with the renderer's own functions (a pixel-integrated Gaussian, or the traced lens's PSF at the
star's true direction from the true sensor's table), Poisson photon noise, Gaussian read noise and
1-DN rounding; then extracted as the pipeline extracts them (``extract_stars``) with the Gaussian fit
and the forward-model centroider, and scored against the exact positions. The bound is
:func:`rigsim.imaging.crlb.crlb_psf` of the rendered star's own image (u, v, flux and background unknown).

    PYTHONPATH=src .venv/bin/python scripts/star_model_crlb.py [--seeds 4] [--photons 2000]
"""

from __future__ import annotations

import argparse
import math
import types

import numpy as np

from rigsim.imaging import Flag, crlb_psf
from rigsim.imaging.stars import extract_stars
from rigsim.optics.star_image_model import GaussianStarImage, bind_psf_bins
from rigsim.optics.star_psf import bv_temperature_k, photon_spectrum_weights
from rigsim.procedures.star.psf_model import star_image_model
from rigsim.render.star import render_stars, render_stars_psf
from rigsim.render.star_effects import traced_psf_table
from rigsim.rig.load import load_star_rig


def traced_rig(rig):
    tp = rig.effects.traced_psf.model_copy(update={"enabled": True})
    return rig.model_copy(update={"effects": rig.effects.model_copy(update={"traced_psf": tp})})


def run(rig_path: str, seeds: int, photons: float, background_e: float, spacing: int = 64, bv: float = 0.65):
    base = load_star_rig(rig_path)
    det = types.SimpleNamespace(gain_dn_per_e=base.sensor.detector.gain_dn_per_e, read_noise_e=base.sensor.detector.read_noise_e,
                                offset_dn=base.sensor.detector.offset_dn, saturation_dn=4095.0, code_step_dn=1)
    K, R, off = det.gain_dn_per_e, det.read_noise_e, det.offset_dn
    read_eff = math.sqrt(R**2 + (1.0 / 12.0) / K**2)     # read noise and 1-DN rounding, in electrons
    W, H = base.sensor.resolution_px
    rows = []
    for psf in ("gaussian", "traced"):
        rig = traced_rig(base) if psf == "traced" else base
        nom = rig.nominal_rig()
        s = nom.sensor
        true_cam = rig.sensor.camera()
        models = {"gauss": None, "model": star_image_model(nom)}
        if psf == "traced":
            models["model, Gaussian PSF (wrong)"] = GaussianStarImage(float(s.psf_sigma_px))
            table = traced_psf_table(rig)
        sigma_true = rig.sensor.psf_sigma_px
        errs = {m: [] for m in models}
        bounds = []
        for seed in range(seeds):
            rng = np.random.default_rng([seed, 77])
            g = np.arange(spacing // 2, W - spacing // 2, spacing, dtype=float)
            uv = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2) + rng.uniform(-0.5, 0.5, (g.size**2, 2))
            ph = np.full(len(uv), float(photons))
            if psf == "traced":
                d = true_cam.unproject(uv)
                w = photon_spectrum_weights(bv_temperature_k(np.full(len(uv), bv)), table.wavelengths_nm)
                bins, _ = table.star_psfs(d, w)
                img = render_stars_psf(uv, ph, (H, W), bins, table.radius_px, table.oversample, background=background_e)
                exact = bind_psf_bins(bins, table.radius_px, table.oversample)
            else:
                img = render_stars(uv, ph, (H, W), sigma_true, background=background_e)
                exact = GaussianStarImage(sigma_true).bind(uv)
            e = rng.poisson(img) + rng.normal(0.0, R, img.shape)
            dn = np.round(off + K * e)
            # the bound: each star's own rendered image, on a 15 × 15 window
            for i in range(len(uv)):
                o = np.floor(uv[i] + 0.5) - 7
                sub = exact.subset([i])

                def f(shape, u, v, sub=sub, o=o):
                    return sub.pixels(np.array([u]) + o[0], np.array([v]) + o[1], o[None, :], shape)[0][0]

                cr = crlb_psf(f, photons, background_e, read_eff, uv[i, 0] - o[0], uv[i, 1] - o[1], (15, 15))
                bounds.append((cr.sigma_u, cr.sigma_v))
            for m, pm in models.items():
                o = extract_stars(dn, det, s.psf_sigma_px, method="gauss" if pm is None else "model", psf_model=pm)
                dd = np.linalg.norm(o.uv[:, None, :] - uv[None], axis=2)
                j = np.argmin(dd, axis=1)
                hit = (dd[np.arange(len(o)), j] < 1.5) & o.usable
                err = np.full((len(uv), 2), np.nan)
                err[j[hit]] = o.uv[hit] - uv[j[hit]]
                errs[m].append(err)
        b = np.array(bounds)
        for m in models:
            e = np.concatenate(errs[m])
            ok = np.all(np.isfinite(e), axis=1)
            r = e[ok] / b[ok]
            rows.append((psf, m, int(ok.sum()), float(np.sqrt(np.mean(b[ok] ** 2))), float(np.sqrt(np.mean(e[ok] ** 2))),
                         float(np.sqrt(np.mean(r**2))), *np.sqrt(np.mean(r**2, axis=0)), *e[ok].mean(axis=0)))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", default="scenes/star_sensor.toml")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--photons", type=float, default=2000.0, help="electrons per star")
    ap.add_argument("--background", type=float, default=20.0, help="electrons per pixel (sky and dark)")
    a = ap.parse_args()
    rows = run(a.rig, a.seeds, a.photons, a.background)
    print(f"{a.photons:g} e- per star, {a.background:g} e-/px background, {a.seeds} noise seeds")
    print("| frames | centroider | stars | CRLB (px rms) | error (px rms) | error / CRLB | u | v | bias u, v (px) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---|")
    for psf, m, n, cr, er, ratio, ru, rv, bu, bv in rows:
        print(f"| {psf} | {m} | {n} | {cr:.4f} | {er:.4f} | {ratio:.3f} | {ru:.3f} | {rv:.3f} | {bu:+.4f}, {bv:+.4f} |")


if __name__ == "__main__":
    main()
