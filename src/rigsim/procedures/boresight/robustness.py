"""The boresight rig's robustness trials: the whole seed-003 orbit run (render the four CMOS ROIs at
the reference and at every measurement → centroids → DVAD and the simplified formulas → relative
angle of the cameras) with a chosen set of ``[effects]`` switched on, scored against the truth.
"""

from __future__ import annotations

import time

import numpy as np

from rigsim.procedures.robustness import ALL, IDEAL, Quantity, RobustnessResult, rig_with, run_family

__all__ = ["DEFAULT_TRIALS", "DESCRIPTION", "boresight_trial", "effect_names", "frames_figure", "pipeline_variants",
           "quantities", "run_robustness"]

DESCRIPTION = ("the boresight pipeline (render the CMOS ROIs of the orbit → thresholded centroids of the ROI or of "
               "the peak's blob → DVAD and the simplified formulas → relative angle of the cameras, Δf)")
DEFAULT_TRIALS = 4

_AXES = ("roll", "pitch", "yaw")
_METHODS = {"dvad": "DVAD", "simplified": "simplified"}


def quantities(rig) -> tuple[Quantity, ...]:
    """Every recovered quantity of a run: the relative angle's error per axis (RMS over the orbit,
    budget the paper's 0.1″ precision), its pitch amplitude, Δf (RMS over the orbit and the cameras)
    for both methods, and the measured spot centroids against the exact spot centres (bias per axis
    and scatter, budget the seed's centroid error ``study.centroid_sigma_px``)."""
    qs = []
    for m, label in _METHODS.items():
        qs += [Quantity(f"{m}_rel_{a}_arcsec", f"relative {a}, {label} (rms over the orbit)", "arcsec", budget=0.1)
               for a in _AXES]
        qs.append(Quantity(f"{m}_pitch_amplitude_arcsec", f"relative pitch amplitude, {label}", "arcsec", budget=0.1))
        qs.append(Quantity(f"{m}_delta_f_um", f"Δf, {label} (rms over the orbit, both cameras)", "um"))
    sig = rig.study.centroid_sigma_px
    qs += [Quantity("centroid_bias_u_px", "spot centroid − exact centre, u (mean)", "px", budget=sig),
           Quantity("centroid_bias_v_px", "spot centroid − exact centre, v (mean)", "px", budget=sig),
           Quantity("centroid_scatter_px", "spot centroid − exact centre (σ per axis)", "px", budget=sig),
           Quantity("failed_runs_count", "runs whose spots were not measurable", "count", kind="count",
                    lower_is_better=True)]
    return tuple(qs)


def effect_names(rig) -> tuple[str, ...]:
    """The effects a boresight rig can switch on."""
    return rig.effects.names()


def _score(res: dict) -> dict:
    out = {}
    for m in _METHODS:
        e = res["estimates"][m]
        for a, v in zip(_AXES, e["relative_rms_arcsec"]):
            out[f"{m}_rel_{a}_arcsec"] = float(v)
        pf = e["pitch_fit"]
        out[f"{m}_pitch_amplitude_arcsec"] = float(pf["amplitude_arcsec"] - pf["true_amplitude_arcsec"])
        out[f"{m}_delta_f_um"] = float(np.sqrt(np.mean(np.square(e["delta_f_rms_um"]))))
    ce = res["centroid_error_px"]
    out.update(centroid_bias_u_px=float(ce["mean"][0]), centroid_bias_v_px=float(ce["mean"][1]),
               centroid_scatter_px=float(np.sqrt(np.mean(np.square(ce["std"])))), failed_runs_count=0.0)
    return out


def pipeline_variants(rig) -> dict[str, str]:
    """The centroiders every run's frames go through (name → centroider): the rig's ``[orbit]
    centroider`` first, then the other one (the whole ROI's thresholded centroid ↔ the peak's blob)."""
    own = rig.orbit.centroider
    other = "tcom_peak" if own == "tcom" else "tcom"
    return {f"as configured ({_CENTROIDERS[own]})": own, _CENTROIDERS[other]: other}


_CENTROIDERS = {"tcom": "thresholded centroid of the ROI", "tcom_peak": "thresholded centroid of the peak's blob"}


def boresight_trial(rig, names, config: str, seed: int) -> dict:
    """One rendered orbit run of ``rig`` with ``config`` (IDEAL, an effect name or ALL of ``names``) at
    ``seed`` (frames rendered in this process), its frames measured by every :func:`pipeline_variants`
    centroider: {variant: the errors of :func:`quantities`} and the render time per frame (ms, key
    ``_render_ms_per_frame``). A run whose spots are not measurable scores NaN and counts as failed."""
    import warnings

    from rigsim.errors import GeometryWarning
    from rigsim.procedures.boresight.studies import orbit_from_frames, run_orbit

    r = rig_with(rig, config, names)
    t0 = time.perf_counter()
    n = 4 * (r.orbit.reference_frames + r.orbit.measurements)
    variants = pipeline_variants(rig)
    (first, own), *others = variants.items()
    frames: list = []
    failed = {q.key: np.nan for q in quantities(rig)} | {"failed_runs_count": 1.0}
    out: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        try:
            res = run_orbit(r, seed=int(seed), workers=1, jitter_px=0.0, centroider=own,
                            on_frame=lambda *a: frames.append(a[-1]))
            out[first] = _score(res)
            ms = 1e3 * (res["seconds"] - res["warm_up_seconds"]) / res["frames_rendered"]
        except RuntimeError:   # a spot not measurable: the pipeline fails on this run
            out[first] = dict(failed)
            ms = 1e3 * (time.perf_counter() - t0) / n
        for name, centroider in others:
            try:
                if len(frames) != n:
                    raise RuntimeError("the run stopped before its last frame")
                out[name] = _score(orbit_from_frames(r, frames, seed=int(seed), centroider=centroider))
            except RuntimeError:
                out[name] = dict(failed)
    out["_render_ms_per_frame"] = ms
    return out


def run_robustness(rig, *, trials: int, seed: int = 0, names=None, workers: int = 1,
                   progress=None, store=None) -> list[RobustnessResult]:
    """Every configuration of :func:`configs_for` over ``trials`` seeds (``seed`` …): one
    :class:`RobustnessResult` per :func:`pipeline_variants` centroider, the configured one first (DVAD
    and the simplified formulas are quantities of each)."""
    names = tuple(effect_names(rig) if names is None else names)
    seeds = range(int(seed), int(seed) + int(trials))
    return run_family("boresight", boresight_trial, rig, names, seeds, quantities(rig), pipeline_variants(rig),
                      workers=workers, progress=progress, store=store)


def frames_figure(rig, path, *, seed: int = 0, names=None):
    """The ROI of camera 1's M1 at the reference, ideal and with every effect on, side by side (same
    square-root grey scale, so a 4 % ghost shows)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import PowerNorm

    from rigsim.files.atomic import save_figure
    from rigsim.render.boresight import LoopRenderer

    names = tuple(effect_names(rig) if names is None else names)
    imgs, spots = [], []
    for config in (IDEAL, ALL if len(names) > 1 else names[0]):
        rend = LoopRenderer(rig_with(rig, config, names), 0, 0)
        fr = rend.render(None, 0.0, seed=int(seed))
        imgs.append((fr.dn.astype(float), fr.origin_uv))
        spots.append(fr.truth["spot_uv"])
    lo = float(min(np.percentile(im, 1) for im, _ in imgs))
    hi = float(max(im.max() for im, _ in imgs))
    fig, axs = plt.subplots(1, 2, figsize=(10, 5.2))
    titles = ("ideal", "every effect on: " + ", ".join(n.replace("_", " ") for n in names))
    for ax, (im, (u0, v0)), sp, title in zip(axs, imgs, spots, titles):
        h, w = im.shape
        ax.imshow(im, cmap="gray", norm=PowerNorm(0.5, vmin=lo, vmax=hi, clip=True),
                  extent=(u0 - 0.5, u0 + w - 0.5, v0 + h - 0.5, v0 - 0.5))
        ax.plot(*sp, "+", color="C3", ms=10, label="exact spot centre")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("u (px)")
        ax.set_ylabel("v (px)")
        ax.legend(loc="lower right", fontsize=7)
    fig.suptitle(f"{rig.name}: camera {rig.cameras[0].name}, M1 ROI at the reference, same square-root grey scale "
                 f"(DN {lo:.0f}–{hi:.0f})", fontsize=10)
    fig.tight_layout()
    out = save_figure(fig, path, dpi=110)
    plt.close(fig)
    return out
