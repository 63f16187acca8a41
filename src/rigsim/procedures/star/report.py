"""Report of a seed-004 run: Markdown + PNG plots + JSON (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rigsim.estimation.star_calibration import MODELS
from rigsim.files import write_json
from rigsim.files.atomic import atomic_write_text, output_folder, save_figure
from rigsim.procedures.star.pipeline import per_star_residuals
from rigsim.procedures.star.study import CASES, CLAIM

__all__ = ["readings_lines", "summary_lines", "write_report"]

MODEL_LABEL = {"ad": "AD", "ads": "ADS (exact, eq 10)", "ads_improved": "improved ADS (eq 12)"}
CASE_LABEL = {"f_known": "f known", "f_biased": "f biased", "f_joint": "f estimated jointly",
              "f_nominal": "f fixed at nominal"}


def _fmt(x, nd=3):
    return "—" if x is None or not np.isfinite(x) else f"{x:+.{nd}f}"


def _plot_frame(path, res):
    import matplotlib.pyplot as plt

    fr = res.sample_frame
    dn = fr.dn.astype(float)
    off = res.rig.sensor.detector.offset_dn * res.rig.sensor.detector.code_step_dn  # frame DN
    img = np.log10(np.clip(dn - off, 1, None))
    fig, ax = plt.subplots(1, 2, figsize=(12, 6), gridspec_kw={"width_ratios": [1.6, 1]})
    ax[0].imshow(img, cmap="gray", origin="upper", vmin=0.3, vmax=np.percentile(img, 99.97))
    ident = res.ident[0]
    fo = res.frames_obs[0]
    ax[0].scatter(fo.uv[:, 0], fo.uv[:, 1], s=60, facecolors="none", edgecolors="tab:orange", linewidths=0.8,
                  label=f"identified ({len(ident)})")
    ax[0].set_title(f"frame 0 (rendered: {res.renderer}), log10(DN − offset)\norange: stars identified against Hipparcos 2")
    ax[0].set_xlabel("u [px]")
    ax[0].set_ylabel("v [px]")
    ax[0].legend(loc="lower right", fontsize=8)
    # zoom on the brightest usable star
    i = int(np.argmax(fo.flux)) if len(fo) else 0
    u, v = (fo.uv[i] if len(fo) else (512, 512))
    u0, v0 = int(round(u)) - 8, int(round(v)) - 8
    crop = dn[max(v0, 0):v0 + 17, max(u0, 0):u0 + 17] - off
    ax[1].imshow(crop, cmap="viridis", origin="upper", extent=(u0 - 0.5, u0 + 16.5, v0 + 16.5, v0 - 0.5))
    ax[1].plot(u, v, "r+", ms=14, label=f"centroid ({u:.2f}, {v:.2f})")
    ax[1].set_title("zoom on the brightest identified star (DN − offset)\ndefocused PSF σ = %.2f px" % res.rig.sensor.psf_sigma_px)
    ax[1].set_xlabel("u [px]")
    ax[1].set_ylabel("v [px]")
    ax[1].legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def _plot_residuals(path, res):
    import matplotlib.pyplot as plt

    n = res.rig.nominal_rig().sensor
    W, H = n.resolution_px
    nominal = res.nominal_theta
    d = nominal - res.truth_theta
    panels = [("before calibration: the nominal intrinsics\n(f %+.1f px, principal point %+.1f / %+.1f px, k1 %+.3f, k2 %+.3f from the truth)"
               % tuple(d), nominal),
              ("after batch least squares of (f, u0, v0, k1, k2)", res.batch.theta)]
    fig, axes = plt.subplots(1, 2, figsize=(13, 6.4))
    for ax, (title, th) in zip(axes, panels):
        uv, r = per_star_residuals(res.frames_obs, th, (n.p1, n.p2), W, H)
        rms = np.sqrt(np.mean(r**2, axis=0))
        mag = 10.0 ** np.floor(np.log10(60.0 / max(3.0 * float(np.sqrt(np.mean(r**2))), 1e-6)))
        ax.quiver(uv[:, 0], uv[:, 1], r[:, 0], r[:, 1], angles="xy", scale_units="xy", scale=1.0 / mag,
                  width=0.002, color="tab:blue")
        title = f"{title}\narrows magnified {mag:g}×"
        ax.set_xlim(-0.5, W - 0.5)
        ax.set_ylim(H - 0.5, -0.5)
        ax.set_aspect("equal")
        ax.set_xlabel("u [px]")
        ax.set_ylabel("v [px]")
        ax.set_title(f"{title}\nrms residual u {rms[0]:.3f} px, v {rms[1]:.3f} px ({len(uv)} stars, 20 frames)", fontsize=9)
        ax.plot(*res.truth_theta[1:3], "r+", ms=12, mew=2)
        ax.plot(*th[1:3], "kx", ms=9, mew=1.5)
    axes[0].text(0.01, 0.01, "red +: true principal point   black ×: the intrinsics used", transform=axes[0].transAxes, fontsize=8)
    fig.suptitle("Star residuals across the field (measured − re-projected catalogue star, attitude fitted per frame); "
                 "arrows magnified", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def _plot_ekf(path, res):
    import matplotlib.pyplot as plt

    cases = sorted({c for c, _ in res.ekf}, key=list(CASE_LABEL).index)
    fig, axes = plt.subplots(2, len(cases), figsize=(4.7 * len(cases), 7.5), sharex=True, squeeze=False)
    colors = {"ad": "tab:blue", "ads": "tab:orange"}
    for j, case in enumerate(cases):
        for i, (name, col) in enumerate((("u0", 1), ("v0", 2))):
            ax = axes[i, j]
            for model in ("ad", "ads"):
                e = res.ekf[(case, model)]
                k = e.names.index(name)
                err = e.history_x[:, k] - res.truth_theta[col]
                sig = e.history_sigma[:, k]
                x = np.arange(err.size)
                ax.plot(x, err, "-o", ms=3, color=colors[model], label=f"{MODEL_LABEL[model]}")
                ax.fill_between(x, err - sig, err + sig, color=colors[model], alpha=0.15)
            imp = res.ekf[(case, "ads_improved")]
            ki = imp.names.index(name)
            ax.axhline(0.0, color="k", lw=0.7)
            ax.set_ylim(-15, 15)
            ax.text(0.02, 0.04, f"improved ADS (eq 12) ends at {imp.history_x[-1, ki] - res.truth_theta[col]:+.1f} px (off scale)",
                    transform=ax.transAxes, fontsize=7.5, color="tab:red")
            ax.set_title(f"{CASE_LABEL[case]}: {name} error", fontsize=10)
            ax.set_ylabel(f"{name} estimate − truth [px]")
            ax.grid(alpha=0.3)
            if i == 1:
                ax.set_xlabel("frames processed")
            ax.xaxis.set_major_locator(plt.MaxNLocator(integer=True))
    axes[0, 0].legend(fontsize=8, loc="upper right")
    fig.suptitle("EKF convergence over the image sequence (band: ±1σ predicted by the filter); prior = the nominal "
                 "principal point", fontsize=11)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def _plot_study(path, study, weighting):
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    x = np.arange(len(CASES))
    for ax, (name, k) in zip(axes, (("u0", 0), ("v0", 1))):
        for off, model, col in ((-0.2, "ad", "tab:blue"), (0.2, "ads", "tab:orange")):
            rms = [study.rms((c, model, weighting))[k] for c in CASES]
            ax.bar(x + off, rms, width=0.38, color=col, label=MODEL_LABEL[model])
            for xi, r in zip(x + off, rms):
                ax.text(xi, r * 1.08, f"{r:.3g}", ha="center", fontsize=8)
        ax.set_yscale("log")
        ax.set_xticks(x, [CASE_LABEL[c] for c in CASES])
        ax.set_ylabel(f"RMS {name} error over {study.trials} trials [px] (log)")
        ax.set_title(f"{name}: AD vs ADS (weighting: {weighting})", fontsize=10)
        ax.grid(alpha=0.3, axis="y")
        top = max(study.rms((c, m, weighting))[k] for c in CASES for m in ("ad", "ads"))
        ax.set_ylim(top / 300, top * 3)
    axes[0].legend(fontsize=8, loc="upper left")
    fig.suptitle("Monte-Carlo study: principal-point accuracy of the EKF (improved ADS is off scale: see the report)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def _plot_observability(path, res):
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    labels = list(MODELS)
    x = np.arange(2)
    for ax, kind in zip(axes, ("raw", "whitened")):
        for i, (model, col) in enumerate(zip(labels, ("tab:blue", "tab:orange", "tab:red"))):
            o = res.observability[(model, "u0,v0")]
            sv = o.sv_raw if kind == "raw" else o.sv_whitened
            ax.bar(x + (i - 1) * 0.27, sv, width=0.25, color=col, label=MODEL_LABEL[model])
            for xi, v in zip(x + (i - 1) * 0.27, sv):
                ax.text(xi, v * 1.1, f"{v:.3g}", ha="center", fontsize=7)
        ax.set_yscale("log")
        ax.set_xticks(x, ["σ1 (largest)", "σ2"])
        if kind == "raw":
            ax.set_title("raw SVD of H (the patent's measure; units of the equations)", fontsize=10)
            ax.set_ylabel("singular value [equation units per px]")
        else:
            ax.set_title("SVD of R^-1/2 H (noise-whitened): 1/σ = 1σ error in px", fontsize=10)
            ax.set_ylabel("singular value [1/px]")
        ax.grid(alpha=0.3, axis="y")
    axes[0].legend(fontsize=8)
    fig.suptitle("Observability of the principal point (u0, v0) over the 20-frame sequence, f and k known", fontsize=11)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def readings_lines(readings) -> list[str]:
    """The AD-vs-ADS-under-every-estimator study as a Markdown section (table and verdict)."""
    imps = readings.improvements()
    widths = np.array([hi - lo for _, lo, hi in imps.values()])
    intro = (
         f"AD and exact ADS EKFs on the same {readings.trials} random 20-frame slews per cell (centroid noise "
         f"{readings.noise_scale:.3f} × CRLB; mean {np.mean(readings.n_stars):.1f} stars per frame), under every "
         "equation set (framework: 2N−3 pairs / 2N−4 triplets; all: every pair / every triplet; chain: consecutive "
         "stars by brightness) × weighting (propagated R = GΣGᵀ; diagonal; unweighted R = σ²I). Cases: f fixed at the "
         "truth, at the truth ±1 px and ±3 px, or estimated jointly from the nominal value. Improvement = "
         "1 − RMS(ADS)/RMS(AD) with a paired bootstrap 95 % interval; with "
         f"{readings.trials} trials the mean interval width is {100 * widths[:, 0].mean():.0f} points (u0) and "
         f"{100 * widths[:, 1].mean():.0f} points (v0).")
    L = ["## AD vs ADS under every estimator", "", intro, "",
         "| case | equations | weighting | RMS u0 / v0 AD [px] | RMS u0 / v0 ADS [px] | ADS u0 (95 % CI) | ADS v0 (95 % CI) |",
         "|---|---|---|---:|---:|---:|---:|"]
    for c in readings.cases:
        for e in readings.estimators:
            a, b = readings.rms(c, e, "ad"), readings.rms(c, e, "ads")
            m, lo, hi = imps[(c, e)]
            L.append(f"| {c} | {e[0]} | {e[1]} | {a[0]:.3g} / {a[1]:.3g} | {b[0]:.3g} / {b[1]:.3g} | "
                     f"{100 * m[0]:+.1f} % [{100 * lo[0]:+.1f}, {100 * hi[0]:+.1f}] | "
                     f"{100 * m[1]:+.1f} % [{100 * lo[1]:+.1f}, {100 * hi[1]:+.1f}] |")
    L += ["", f"**Claim (+64.0 % u0, +21.7 % v0): {readings.verdict(imps)}.**", ""]
    return L


def summary_lines(res, study=None, readings=None) -> list[str]:
    """Key numbers as plain text lines (printed by the CLI, repeated in the report); ``readings``
    adds the verdict of the AD-vs-ADS study under every estimator."""
    t = res.truth_theta
    L = []
    cs = res.centroid_stats
    ist = res.ident_stats
    L.append(f"identification: {ist['frames_identified']}/{ist['frames']} frames, {ist['identified']} stars identified "
             f"of {ist['usable']} usable detections ({ist['wrong']} wrong); a-priori attitude error {ist['attitude_error_deg']}°")
    L.append(f"centroids vs truth: rms {cs['rms_px'][0]:.4f} / {cs['rms_px'][1]:.4f} px (u / v), "
             f"error/σ rms {cs['chi_rms'][0]:.2f} / {cs['chi_rms'][1]:.2f}, error/CRLB {cs['error_over_crlb_rms']:.3f}")
    b = res.batch
    e = b.theta - t
    L.append(f"batch LSQ (f, u0, v0, k1, k2) − truth: f {e[0]:+.3f}±{b.sigma[0]:.3f} px, u0 {e[1]:+.3f}±{b.sigma[1]:.3f} px, v0 {e[2]:+.3f}±{b.sigma[2]:.3f} px, "
             f"k1 {e[3]:+.5f}±{b.sigma[3]:.5f}, k2 {e[4]:+.4f}±{b.sigma[4]:.4f} (χ²/dof {b.chi2_reduced:.2f})")
    for case in sorted({c for c, _ in res.ekf}, key=list(CASE_LABEL).index):
        parts = []
        for model in MODELS:
            r = res.ekf[(case, model)]
            d = r.theta[1:3] - t[1:3]
            parts.append(f"{MODEL_LABEL[model].split(' (')[0]} ({d[0]:+.2f}, {d[1]:+.2f})")
        L.append(f"EKF u0/v0 error [px], {CASE_LABEL[case]}: " + "; ".join(parts))
    if study is not None:
        w = study.weightings[0]
        eq = "" if study.equations == "framework" else f", equations {study.equations}"
        L.append(f"study ({study.trials} trials, weighting {w}{eq}): RMS u0 / v0 error [px]")
        for case in CASES:
            a = study.rms((case, "ad", w))
            s_ = study.rms((case, "ads", w))
            si = study.rms((case, "ads_improved", w))
            L.append(f"  {CASE_LABEL[case]:20s} AD {a[0]:.3f} / {a[1]:.3f}   ADS {s_[0]:.3f} / {s_[1]:.3f}   "
                     f"improved ADS {si[0]:.3g} / {si[1]:.3g}")
        tab = study.improvement_table(w, "ads")
        tab_i = study.improvement_table(w, "ads_improved")
        for case in CASES:
            (est, lo, hi), (ei, _, _) = tab[case], tab_i[case]
            L.append(f"  improvement over AD, {CASE_LABEL[case]:20s}: ADS u0 {100 * est[0]:+.1f}% [{100 * lo[0]:+.1f}, {100 * hi[0]:+.1f}], "
                     f"v0 {100 * est[1]:+.1f}% [{100 * lo[1]:+.1f}, {100 * hi[1]:+.1f}];  improved ADS u0 {100 * ei[0]:+.3g}%, v0 {100 * ei[1]:+.3g}%")
        L.append(f"  claim (+{100 * CLAIM['u0']:.1f}% u0, +{100 * CLAIM['v0']:.1f}% v0): " + claim_verdict(study))
    if readings is not None:
        L.append(f"AD vs ADS under every estimator ({readings.trials} trials per cell, "
                 f"{len(readings.cases)} focal-length cases × {len(readings.estimators)} estimators): {readings.verdict()}")
    worst = max((float(np.max(np.abs(r.theta[1:3] - t[1:3]))) for (case, model), r in res.ekf.items()
                 if model == "ads_improved"), default=0.0)
    if worst > 20:
        L.append(f"  note: improved ADS (the patent's eq 12) ends up to {worst:.0f} px off"
                 + (", and its 'improvement' over AD is a large negative %" if study is not None else "")
                 + ": not a bug; its approximation D_iD_j ≈ D_jD_k drops a term as large as the one it keeps "
                   "(≈ r²/f²), so its filter converges to a wrong point (docs/star_calibration.md)")
    return L


def claim_verdict(study) -> str:
    """Claim reproduced = the 95 % interval of ADS's improvement reaches the claimed value on both axes."""
    w = study.weightings[0]
    better, reproduced = [], []
    for model in ("ads", "ads_improved"):
        tab = study.improvement_table(w, model)
        for case in CASES:
            est, lo, hi = tab[case]
            if lo[0] > 0 and lo[1] > 0:
                better.append(f"{MODEL_LABEL[model]} / {CASE_LABEL[case]} by {100 * est[0]:+.1f} % / {100 * est[1]:+.1f} %")
            if hi[0] >= CLAIM["u0"] and hi[1] >= CLAIM["v0"]:
                reproduced.append(f"{MODEL_LABEL[model]} / {CASE_LABEL[case]}")
    if reproduced:
        return "reproduced in: " + ", ".join(reproduced)
    tail = ("; significantly better than AD only " + ", ".join(better)) if better else \
        "; no ADS variant is significantly better than AD on both axes"
    return "NOT reproduced in any case (no 95 % interval reaches +64.0 % / +21.7 %)" + tail


def write_report(out_dir, res, study=None, *, command: str | None = None, rig_path: str | None = None,
                 readings=None) -> dict:
    """report.md (+ HTML), its plots and star_calibration.json of a run; ``study`` (StudyResult) and
    ``readings`` (the AD-vs-ADS study under every estimator) add their sections and JSON blocks."""
    import matplotlib

    matplotlib.use("Agg")
    out = Path(out_dir)
    output_folder(out)
    files = {}
    files["frame"] = out / "star_frame.png"
    _plot_frame(files["frame"], res)
    files["residuals"] = out / "residuals_field.png"
    _plot_residuals(files["residuals"], res)
    files["ekf"] = out / "ekf_convergence.png"
    _plot_ekf(files["ekf"], res)
    files["observability"] = out / "observability.png"
    _plot_observability(files["observability"], res)
    if study is not None:
        files["study"] = out / "study_rms.png"
        _plot_study(files["study"], study, study.weightings[0])
    rig = res.rig
    s = rig.sensor
    t = res.truth_theta
    md = ["# Seed 004 — star-sensor on-orbit calibration: AD vs ADS", ""]
    if command:
        md += [f"Command: `{command}`", ""]
    md += [f"Rig: `{rig_path or rig.name}` — {rig.description}. Seed {res.seed}, renderer **{res.renderer}**.",
           f"True intrinsics: f = {t[0]:.3f} px, (u0, v0) = ({t[1]:.2f}, {t[2]:.2f}) px, k1 = {t[3]}, k2 = {t[4]}; "
           f"PSF σ = {s.psf_sigma_px:.3f} px; FOV {s.fov_deg[0]:.1f}°. The estimators see only the nominal intrinsics "
           f"(`[nominal]`): f = {res.nominal_theta[0]:.3f} px ({res.nominal_theta[0] - t[0]:+.2f} px from the truth), "
           f"(u0, v0) = ({res.nominal_theta[1]:.2f}, {res.nominal_theta[2]:.2f}) px, k1 = {res.nominal_theta[3]}, "
           f"k2 = {res.nominal_theta[4]}; identification starts from the commanded attitude.",
           "Every equation is a reconstruction documented in docs/star_calibration.md.", ""]
    try:  # the rig in 3D (rigsim.view, off screen); the report goes on without it if OpenGL is unavailable
        from rigsim.view import rig_picture

        files["rig_picture"] = rig_picture(rig, out / "rig.png", size=(1400, 800))
        md += ["![the star sensor, its field of view and catalogue stars at the first attitude (rigsim view)](rig.png)", ""]
    except Exception as e:
        md += [f"(rig picture unavailable: {type(e).__name__}: {e})", ""]
    md += ["## Key numbers", "", "```", *summary_lines(res, study, readings), "```", ""]
    md += ["## Sample frame", "", "![](star_frame.png)", ""]
    md += ["## Residuals across the field", "",
           "Per frame the attitude is fitted (Wahba) with the given intrinsics and every identified catalogue star is "
           "re-projected; arrows are measured − predicted, magnified. Before calibration the pattern is the radial "
           "distortion plus the focal-length and principal-point errors; after the batch fit it is centroid noise.", "",
           "![](residuals_field.png)", ""]
    md += ["## EKF convergence (this run's 20 frames)", "", "![](ekf_convergence.png)", "",
           "| case | model | u0 − truth [px] | v0 − truth [px] | EKF σ u0 / v0 [px] | f − truth [px] |", "|---|---|---:|---:|---:|---:|"]
    for case in sorted({c for c, _ in res.ekf}, key=list(CASE_LABEL).index):
        for model in MODELS:
            r = res.ekf[(case, model)]
            d = r.theta - t
            md.append(f"| {CASE_LABEL[case]} | {MODEL_LABEL[model]} | {d[1]:+.3f} | {d[2]:+.3f} | "
                      f"{r.sigma[-2]:.3f} / {r.sigma[-1]:.3f} | {d[0]:+.3f} |")
    b = res.batch
    md += ["", "## Batch least squares (all five intrinsics, AD equations, no priors)", "",
           "| parameter | truth | estimate | error | 1σ (covariance) | error/σ |", "|---|---:|---:|---:|---:|---:|"]
    for i, n in enumerate(("f [px]", "u0 [px]", "v0 [px]", "k1", "k2")):
        md.append(f"| {n} | {t[i]:.5g} | {b.theta[i]:.6g} | {b.theta[i] - t[i]:+.4g} | {b.sigma[i]:.3g} | "
                  f"{(b.theta[i] - t[i]) / b.sigma[i]:+.2f} |")
    md += ["", f"χ²/dof = {b.chi2_reduced:.3f} over {b.n_eq} equations.", ""]
    md += ["## Observability (SVD of the Jacobians, eqs 20-22)", "", "![](observability.png)", "",
           "| model | state | raw singular values | whitened singular values | 1/σ_whitened [px or state units] |",
           "|---|---|---|---|---|"]
    for (model, label), o in res.observability.items():
        md.append(f"| {MODEL_LABEL[model]} | {label} | {', '.join(f'{v:.3g}' for v in o.sv_raw)} | "
                  f"{', '.join(f'{v:.3g}' for v in o.sv_whitened)} | {', '.join(f'{1 / v:.3g}' for v in o.sv_whitened)} |")
    md += ["", "Raw singular values depend on the units of each equation (an ADS row is a difference of two AD rows, "
           "and the improved-ADS rows drop a term), so they are not an accuracy measure; the whitened ones are.", ""]
    if study is not None:
        w = study.weightings[0]
        md += ["## Monte-Carlo study: does ADS improve u0/v0 over AD?", "", "![](study_rms.png)", "",
               f"{study.trials} trials, each a random 20-frame slew anywhere on the sky; centroid noise "
               f"σ = {study.noise.scale:.3f} × CRLB(star flux) per axis (the factor measured on this run's rendered frames); "
               f"mean {np.mean(study.n_stars):.1f} stars per frame; weighting `{w}`.", "",
               "| case | model | RMS u0 [px] | RMS v0 [px] | mean u0 [px] | mean v0 [px] | mean EKF σ u0 / v0 [px] |",
               "|---|---|---:|---:|---:|---:|---:|"]
        for case in CASES:
            for model in study.models:
                k = (case, model, w)
                r = study.rms(k)
                m = study.errors[k].mean(axis=0)
                sg = study.sigmas[k].mean(axis=0)
                md.append(f"| {CASE_LABEL[case]} | {MODEL_LABEL[model]} | {r[0]:.4g} | {r[1]:.4g} | {m[0]:+.3g} | {m[1]:+.3g} | "
                          f"{sg[0]:.3g} / {sg[1]:.3g} |")
        md += ["", "Improvement over AD = 1 − RMS(model)/RMS(AD), paired bootstrap 95 % interval:", "",
               "| case | ADS u0 | ADS v0 | improved ADS u0 | improved ADS v0 |", "|---|---:|---:|---:|---:|"]
        t1 = study.improvement_table(w, "ads")
        t2 = study.improvement_table(w, "ads_improved")
        for case in CASES:
            (e1, l1, h1), (e2, _, _) = t1[case], t2[case]
            md.append(f"| {CASE_LABEL[case]} | {100 * e1[0]:+.1f}% [{100 * l1[0]:+.1f}, {100 * h1[0]:+.1f}] | "
                      f"{100 * e1[1]:+.1f}% [{100 * l1[1]:+.1f}, {100 * h1[1]:+.1f}] | {100 * e2[0]:+.3g}% | {100 * e2[1]:+.3g}% |")
        md += ["", f"**Claim (+64.0 % u0, +21.7 % v0): {claim_verdict(study)}.**", ""]
        if study.batch_errors is not None:
            be = study.batch_errors
            bs = study.batch_sigmas
            md += [f"Batch LSQ of all five intrinsics on the first {be.shape[0]} trials: RMS error "
                   + ", ".join(f"{n} {v:.3g}" for n, v in zip(("f", "u0", "v0", "k1", "k2"), np.sqrt(np.mean(be**2, axis=0))))
                   + "; mean predicted σ " + ", ".join(f"{n} {v:.3g}" for n, v in zip(("f", "u0", "v0", "k1", "k2"), bs.mean(axis=0))) + ".", ""]
    if readings is not None:
        md += readings_lines(readings)
    md += ["## Wall time (s)", "", ", ".join(f"{k} {v:.2f}" for k, v in res.times.items()), ""]
    files["report"] = out / "report.md"
    atomic_write_text(files["report"], "\n".join(md) + "\n")
    from rigsim.procedures.star.files import star_result_json

    models = tuple(dict.fromkeys(m for _, m in res.ekf))
    data = star_result_json(res.output, [f"star_{k:03d}" for k in range(len(res.ident))], models,
                            mode="analytic" if res.renderer == "analytic" else "rendered", seed=res.seed,
                            true_theta=t, true_R=res.true_R)
    data.update({"renderer": res.renderer, "centroids": res.centroid_stats,
                 "identification": res.ident_stats,
                 "observability": {f"{m}/{lab}": {"raw": o.sv_raw.tolist(), "whitened": o.sv_whitened.tolist()}
                                   for (m, lab), o in res.observability.items()},
                 "times_s": res.times})
    if study is not None:
        w = study.weightings[0]
        data["study"] = {"trials": study.trials, "weighting": w, "noise_scale": study.noise.scale,
                         "rms_px": {f"{c}/{m}": study.rms((c, m, w)).tolist() for c in CASES for m in study.models},
                         "verdict": claim_verdict(study)}
    if readings is not None:
        data["readings_study"] = readings.to_json()
    files["json"] = out / "star_calibration.json"
    write_json(files["json"], data)
    from rigsim.reporting import markdown_to_html

    files["html"] = markdown_to_html(files["report"])
    return files
