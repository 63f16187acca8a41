"""The star sensor's robustness trials: the whole seed-004 run (render → extract → identify → EKFs
and batch least squares) with a chosen set of ``[effects]`` switched on, scored against the truth.
"""

from __future__ import annotations

import time

import numpy as np

from rigsim.procedures.robustness import ALL, IDEAL, Quantity, RobustnessResult, rig_with, run_family
from rigsim.rig.effects import STAR_EFFECTS

__all__ = ["DEFAULT_TRIALS", "DESCRIPTION", "QUANTITIES", "effect_names", "frames_figure", "pipeline_variants",
           "run_robustness", "star_trial"]

DESCRIPTION = "the star pipeline (render → extract → identify → EKFs and batch least squares)"
DEFAULT_TRIALS = 8

QUANTITIES = (
    Quantity("lsq_f_px", "f, batch LSQ", "px"),
    Quantity("lsq_u0_px", "u0, batch LSQ", "px"),
    Quantity("lsq_v0_px", "v0, batch LSQ", "px"),
    Quantity("ads_f_px", "f, ADS EKF (f joint)", "px"),
    Quantity("ads_u0_px", "u0, ADS EKF (f joint)", "px"),
    Quantity("ads_v0_px", "v0, ADS EKF (f joint)", "px"),
    Quantity("ad_u0_px", "u0, AD EKF (f joint)", "px"),
    Quantity("ad_v0_px", "v0, AD EKF (f joint)", "px"),
    Quantity("centroid_rms_px", "centroid error of identified stars (rms)", "px"),
    Quantity("identified_count", "identified stars (whole run)", "count", kind="count"),
    Quantity("wrong_count", "wrong identifications (whole run)", "count", kind="count", lower_is_better=True),
    Quantity("frames_identified_count", "frames identified", "count", kind="count"),
)

_SKY: dict = {}  # the star catalogue per [sky] table, loaded once per process


def effect_names(rig) -> tuple[str, ...]:
    """The effects a star-sensor rig can switch on."""
    return STAR_EFFECTS


def _describe(cal, sensor) -> str:
    return (f"single-pixel filter {'on' if cal.single_pixel_filter else 'off'}, fixed pattern: {cal.fixed_pattern}, "
            f"poor fits {'rejected against the ' + cal.poor_fit_reference if cal.reject_poor_fits else 'kept'}"
            + ("" if sensor.centroid_map is None else ", ground centroid map of the traced lens")
            + ("" if cal.centroid_method == "gauss" else f", centroids: {cal.centroid_method}"))


def pipeline_variants(rig) -> dict[str, object]:
    """The pipelines every robustness run's frames go through (name → nominal rig): as the rig
    configures it, then with each of its defect settings switched the other way in turn (the
    single-pixel filter, the fixed pattern ``none`` ↔ ``sequence``, the rejection of poor fits and,
    when they are rejected, what they are judged against, the ``[nominal] centroid_map``
    ``none`` ↔ ``traced_lens``, and the centroider: the forward model ↔ the Gaussian fit)."""
    nominal = rig.nominal_rig()
    cal = nominal.calibration

    def with_cal(**upd):
        return nominal.model_copy(update={"calibration": cal.model_copy(update=upd)})

    other_pattern = "sequence" if cal.fixed_pattern == "none" else "none"
    out = {f"as configured ({_describe(cal, nominal.sensor)})": nominal}
    alts = [with_cal(single_pixel_filter=not cal.single_pixel_filter), with_cal(fixed_pattern=other_pattern),
            with_cal(reject_poor_fits=not cal.reject_poor_fits)]
    if cal.reject_poor_fits:
        alts.append(with_cal(poor_fit_reference="frame" if cal.poor_fit_reference == "model" else "model"))
    n = rig.nominal_intrinsics
    other_map = "traced_lens" if n.centroid_map == "none" else "none"
    alts.append(rig.model_copy(update={"nominal": n.model_copy(update={"centroid_map": other_map})}).nominal_rig())
    if getattr(cal, "background", "frame") != "map":  # the centroider the other way: the forward model ↔ the Gaussian fit
        alts.append(with_cal(centroid_method="gauss" if cal.centroid_method == "model" else "model"))
    for alt in alts:
        out[_describe(alt.calibration, alt.sensor)] = alt
    return out


def _score(out, truths, rig, sky, truth_theta) -> dict:
    from rigsim.procedures.star.run import compare

    ids, cs = compare(out, truths, rig, sky)
    lsq = np.asarray(out.batch.theta, dtype=float) - truth_theta
    ads = np.asarray(out.ekf[("f_joint", "ads")].theta, dtype=float) - truth_theta
    ad = np.asarray(out.ekf[("f_joint", "ad")].theta, dtype=float) - truth_theta
    return {"lsq_f_px": lsq[0], "lsq_u0_px": lsq[1], "lsq_v0_px": lsq[2],
            "ads_f_px": ads[0], "ads_u0_px": ads[1], "ads_v0_px": ads[2], "ad_u0_px": ad[1], "ad_v0_px": ad[2],
            "centroid_rms_px": float(np.hypot(*cs["rms_px"]) / np.sqrt(2.0)),
            "identified_count": float(ids["identified"]), "wrong_count": float(ids["wrong"]),
            "frames_identified_count": float(ids["frames_identified"])}


def star_trial(rig, names, config: str, seed: int) -> dict:
    """One rendered run of ``rig`` with ``config`` (IDEAL, an effect name or ALL of ``names``) at
    ``seed``, through every :func:`pipeline_variants`: {variant: the errors and counts of
    :data:`QUANTITIES`} and the render time per frame (ms, key ``_render_ms_per_frame``)."""
    from rigsim.procedures.star.pipeline import StarPipeline
    from rigsim.procedures.star.run import generate
    from rigsim.truth.star import StarSky

    r = rig_with(rig, config, names)
    key = rig.sky.model_dump_json()  # the catalogue depends on the sky table (limit, epoch), not the rig's name
    if key not in _SKY:
        _SKY[key] = StarSky(rig).sky
    sky = StarSky(r, sky=_SKY[key])
    extractions: dict = {}  # the variants' extractions with equal settings, made once per frame (the frames are held)
    pipes = {v: StarPipeline(nom, sky.sky, extractions=extractions) for v, nom in pipeline_variants(r).items()}
    truths, held, t_render = [], [], 0.0
    t0 = time.perf_counter()
    for obs, truth, _fr in generate(r, seed=int(seed), sky=sky):
        t_render += time.perf_counter() - t0
        truths.append(truth)
        held.append(obs)
        t0 = time.perf_counter()
    n = len(held)
    first = None  # the fixed pattern depends on the frames only: computed once for every variant using it
    for p in pipes.values():
        if p.nominal.calibration.fixed_pattern == "sequence":
            if first is None:
                p.set_sequence_pattern(held)
                first = p
            else:
                p.fixed_pattern, p.fixed_pattern_note = first.fixed_pattern, first.fixed_pattern_note
        for obs in held:
            p.add(obs)
    s = r.sensor
    truth_theta = np.array([s.f_px, *s.principal_point_px, s.k1, s.k2])
    out = {v: _score(p.calibrate(), truths, r, sky, truth_theta) for v, p in pipes.items()}
    out["_render_ms_per_frame"] = 1e3 * t_render / max(1, n)
    return out


def run_robustness(rig, *, trials: int, seed: int = 0, names=None, workers: int = 1,
                   progress=None, store=None) -> list[RobustnessResult]:
    """Every configuration of :func:`configs_for` over ``trials`` seeds (``seed`` …): one
    :class:`RobustnessResult` per pipeline variant, the configured pipeline first."""
    names = tuple(STAR_EFFECTS if names is None else names)
    seeds = range(int(seed), int(seed) + int(trials))
    return run_family("star", star_trial, rig, names, seeds, QUANTITIES, pipeline_variants(rig),
                      workers=workers, progress=progress, store=store)


def frames_figure(rig, path, *, seed: int = 0, names=None, crop: int = 256):
    """One frame of the rig's sequence, ideal and with every effect on, side by side (a crop of
    ``crop`` px at the detector's bright-edge side, same grey scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rigsim.files.atomic import save_figure
    from rigsim.optics import attitude as att
    from rigsim.render.star import frame_seed, render_frame
    from rigsim.truth.star import StarSky, true_sequence

    names = tuple(STAR_EFFECTS if names is None else names)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 4004]))
    commanded = att.from_rig(rig.sequence, rng, jitter=False)
    true_seq = true_sequence(rig, commanded, rng)
    base = StarSky(rig)
    imgs = []
    for r in (rig_with(rig, IDEAL, names), rig_with(rig, ALL, names)):
        sky = StarSky(r, sky=base.sky)
        fr = render_frame(sky, true_seq.R_cam_from_icrs[0], seed=frame_seed(seed, 0), fits_header=False,
                          omega_cam_rad_s=true_seq.omega_cam_rad_s[0], substeps=rig.sequence.smear_substeps)
        imgs.append(fr.dn.astype(float))
    H, W = imgs[0].shape
    c = min(crop, H, W)
    win = (slice(0, c), slice(W - c, W))
    from matplotlib.colors import PowerNorm

    lo = np.percentile(imgs[0][win], 1)
    hi = max(float(imgs[0][win].max()), lo + 1)  # the brightest star of the crop, square-root stretch
    fig, axs = plt.subplots(1, 2, figsize=(10, 5.2))
    for ax, im, title in zip(axs, imgs, ("ideal", "every effect on: " + ", ".join(n.replace("_", " ") for n in names))):
        ax.imshow(im[win], cmap="gray", norm=PowerNorm(0.5, vmin=lo, vmax=hi, clip=True),
                  extent=(W - c - 0.5, W - 0.5, c - 0.5, -0.5))
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("u (px)")
        ax.set_ylabel("v (px)")
    fig.suptitle(f"{rig.name}: frame 0, top-right {c}×{c} px (the stray light's side), same square-root grey "
                 f"scale (DN {lo:.0f}–{hi:.0f})", fontsize=10)
    fig.tight_layout()
    out = save_figure(fig, path, dpi=110)
    plt.close(fig)
    return out
