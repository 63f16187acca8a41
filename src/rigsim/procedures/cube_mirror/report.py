"""The cube-mirror campaign report: a Markdown page, PNG plots and a JSON record.

Files written to ``out`` (``rigsim run cube-mirror --out DIR``; default renders/cube_mirror_<rig>):

* ``report.md`` — rig summary, truth vs recovered, the Table-1-style search log, measured
  noise, the error budget beside the paper's numbers, wall time by stage;
* ``calibration_residuals.png`` — sun-sensor fit residuals across the detector (quiver, and
  against the true centroid error);
* ``search_path.png`` — each face's measured and exact offsets/readings per frame, with the
  stopping threshold;
* ``budget_histogram.png`` — per-axis error distributions of the Monte-Carlo budget;
* ``rig.png`` — the rig in 3D at the first face's null (rigsim.view, off screen; ``rigsim run
  cube-mirror`` renders it in a child process at the exact null before the campaign, see ``picture``);
* ``campaign.json`` — every number on the page;
* ``report.html`` — the same page, self-contained (images embedded).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from rigsim.files.atomic import atomic_write_text, output_folder, save_figure
from rigsim.frames import ARCSEC_PER_RAD


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _f(x, nd=3) -> str:
    return "—" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{nd}f}"


def plot_calibration_residuals(campaign, path: Path) -> Path:
    plt = _plt()
    sw, cal = campaign.sweep, campaign.calibration
    uv, res = cal.uv, cal.residuals_px
    err = sw.uv - campaign.sweep_truth.uv_centre  # the comparison with truth
    fig, axs = plt.subplots(1, 2, figsize=(12, 5.4))
    ax = axs[0]
    W, H = campaign_rig_size(campaign)
    scale = 0.05 * W / max(float(np.max(np.hypot(*res.T))), 1e-12)
    ax.quiver(uv[:, 0], uv[:, 1], res[:, 0], res[:, 1], np.hypot(*res.T), angles="xy", scale_units="xy",
              scale=1.0 / scale, cmap="viridis", width=0.003)
    marks = [(cal.outliers, "x", "tab:red", "outliers"), (cal.outside_field, "+", "tab:grey", "outside the field")]
    for rows, marker, colour, what in marks:
        if len(rows):
            ax.plot(*sw.uv[rows].T, marker, color=colour, ms=7, ls="none", label=f"{len(rows)} left out: {what}")
    if len(cal.outliers) or len(cal.outside_field):
        ax.legend(loc="lower right", fontsize=8)
    ax.set_xlim(0, W)
    ax.set_ylim(H, 0)
    ax.set_aspect("equal")
    ax.set_title(f"fit residuals (measured − model), ×{scale:.0f}\nrms {cal.rms_px:.4f} px over {cal.n_points} frames")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax = axs[1]
    ax.plot(np.hypot(uv[:, 0] - W / 2, uv[:, 1] - H / 2), np.hypot(*res.T), ".", ms=3, label="|fit residual|")
    ax.plot(np.hypot(sw.uv[:, 0] - W / 2, sw.uv[:, 1] - H / 2), np.hypot(*err.T), ".", ms=3, alpha=0.6,
            label="|measured − exact sun-centre projection|" + (", every frame" if len(err) > len(uv) else ""))
    if len(err) > len(uv):
        ax.set_yscale("log")
    ax.set_xlabel("distance from the detector centre (px)")
    ax.set_ylabel("px")
    ax.set_title("residual vs field position")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def campaign_rig_size(campaign) -> tuple[int, int]:
    cam = campaign.calibration.camera
    return int(cam.width), int(cam.height)


def plot_search_path(campaign, path: Path) -> Path:
    plt = _plt()
    n = len(campaign.searches)
    fig, axs = plt.subplots(1, n, figsize=(6 * n, 5.6))
    axs = np.atleast_1d(axs)
    for ax, s in zip(axs, campaign.searches):
        m = np.array([st.measured for st in s.steps])
        t = np.array([st.true for st in s.steps])
        ax.plot(m[:, 0], m[:, 1], "o-", label="measured (what the operator sees)")
        ax.plot(t[:, 0], t[:, 1], "x--", alpha=0.7, label="exact (truth)")
        for i, (x, y) in enumerate(m):
            ax.annotate(str(i), (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
        th = s.threshold
        ax.add_patch(plt.Rectangle((-th, -th), 2 * th, 2 * th, fill=False, ls=":", color="k", label=f"threshold ±{th:g} {s.unit}"))
        lim = max(float(np.max(np.abs(np.vstack([m, t])))), 2 * th) * 1.15
        ax.set_xlim(-lim, lim)
        ax.set_ylim(-lim, lim)
        ax.axhline(0, color="0.8", lw=0.5)
        ax.axvline(0, color="0.8", lw=0.5)
        ax.set_aspect("equal")
        ax.set_xlabel(f"x ({s.unit})")
        ax.set_ylabel(f"y ({s.unit})")
        ax.set_title(f"face {s.face}: {len(s.steps)} frames, {'converged' if s.converged else 'NOT converged'}")
        if lim > 4 * th:  # inset: zoom on the threshold box (only when the panel does not already show it large)
            ins = ax.inset_axes([0.62, 0.62, 0.36, 0.36])
            ins.plot(m[:, 0], m[:, 1], "o-", ms=3)
            ins.plot(t[:, 0], t[:, 1], "x--", ms=3, alpha=0.7)
            ins.add_patch(plt.Rectangle((-th, -th), 2 * th, 2 * th, fill=False, ls=":", color="k"))
            ins.set_xlim(-2 * th, 2 * th)
            ins.set_ylim(-2 * th, 2 * th)
            ins.set_aspect("equal")
            ins.tick_params(labelsize=6)
    # one legend under the panels: inside a panel it hides the path wherever the path runs
    fig.legend(*axs[0].get_legend_handles_labels(), loc="lower center", ncol=3, fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_budget_histogram(budget, path: Path, paper_rss: float | None = None) -> Path:
    plt = _plt()
    names = [budget.together_row, "all sources together"]
    fig, axs = plt.subplots(len(names), 3, figsize=(13, 3.4 * len(names)), squeeze=False)
    for i, name in enumerate(names):
        e = budget.errors[name]
        for k, lab in enumerate(("x", "y", "z")):
            ax = axs[i, k]
            ax.hist(e[:, k], bins=30, color="C0", alpha=0.8)
            sd = float(np.std(e[:, k], ddof=1))
            for sgn in (-1, 1):
                ax.axvline(sgn * sd, color="C1", ls="--", lw=1, label="±1σ (Monte Carlo)" if sgn > 0 else None)
                if paper_rss:
                    ax.axvline(sgn * paper_rss, color="C3", ls=":", lw=1, label=f"±{paper_rss}″ (paper's RSS)" if sgn > 0 else None)
            ax.set_title(f"{name[:45]}\naxis {lab}: σ = {sd:.2f}″ (n = {len(e)})", fontsize=9)
            ax.set_xlabel("error of R(cube←sun) (arcsec)")
            if k == 0:
                ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def rig_summary_md(rig) -> list[str]:
    """The rig's key values (what the reader needs to judge the numbers)."""
    L = ["## Rig", ""]
    tt = rig.turntable
    axes = "; ".join(f"{a.name} {a.label}′ (encoder σ {a.encoder_sigma_arcsec:g}″, bias {a.encoder_bias_arcsec:g}″)"
                     for a in tt.axes)
    L.append(f"* **Turntable** {tt.kind}, outermost first: {axes}; perpendicularity σ {tt.perpendicularity_sigma_arcsec:g}″.")
    sm = rig.sun_simulator
    L.append(f"* **Sun simulator** Ø{sm.aperture_mm:g} mm, full divergence {sm.collimation_full_angle_arcmin:g}′, "
             f"{sm.distance_mm:g} mm away.")
    ss = rig.sun_sensor
    L.append(f"* **Sun sensor** {ss.resolution_px[0]}×{ss.resolution_px[1]} px of {ss.pixel_pitch_um:g} µm, "
             f"f = {ss.focal_length_mm:g} mm ({ss.fx_px:.1f} px), Brown k1 {ss.distortion.k1:g}, k2 {ss.distortion.k2:g}, "
             f"p1 {ss.distortion.p1:g}, p2 {ss.distortion.p2:g}.")
    L.append(f"* **Cube** {rig.cube.edge_mm:g} mm; faces measured {', '.join(rig.procedure.faces)}; "
             f"sweep ±{rig.procedure.sweep_range_deg:g}° every {rig.procedure.sweep_step_deg:g}°.")
    if rig.diaphragm_screen is not None:
        ds, ac = rig.diaphragm_screen, rig.aiming_camera
        L.append(f"* **Diaphragm screen** hole Ø{ds.hole_diameter_mm:g} mm, {ds.distance_to_cube_mm:g} mm from the cube; "
                 f"**aiming camera** {ac.resolution_px[0]}×{ac.resolution_px[1]} px, {ac.object_pixel_mm * 1e3:.1f} µm per "
                 f"pixel on the screen, {ac.view_angle_deg:g}° off the screen normal; stop below "
                 f"{ac.concentric_threshold_px:g} px; commands in {rig.procedure.command_resolution_deg:g}° steps; "
                 f"mounting σ3 {ac.mounting_sigma_arcsec:g}″.")
    if rig.autocollimator is not None:
        a = rig.autocollimator
        L.append(f"* **Autocollimator** f = {a.focal_length_mm:g} mm, Ø{a.aperture_mm:g} mm, "
                 f"{a.resolution_px[0]}×{a.resolution_px[1]} px of {a.pixel_pitch_um:g} µm, {a.distance_mm:g} mm from the "
                 f"mirror; stop below {a.null_threshold_arcsec:g}″.")
    if rig.plane_mirror is not None:
        L.append(f"* **Plane mirror** on the inner frame, perpendicularity spec {rig.plane_mirror.perpendicularity_spec_arcsec:g}″.")
    L.append("")
    return L


def _rig_picture(rig, out: Path, pose_deg) -> tuple[Path | None, str]:
    try:
        from rigsim.view import rig_picture

        return rig_picture(rig, out / "rig.png", pose_deg=pose_deg, size=(1400, 800)), ""
    except Exception as e:  # no off-screen OpenGL here: the report goes on without the picture
        return None, f"{type(e).__name__}: {e}"


def _search_table_md(s) -> list[str]:
    a, b = s.free_axes
    u = s.unit
    out = [f"| # | {a} (°) | {b} (°) | x ({u}) | y ({u}) | exact x | exact y |", "|---:|---:|---:|---:|---:|---:|---:|"]
    for row in s.table_rows():
        out.append(f"| {row[0]} | {row[1]:.4f} | {row[2]:.4f} | {row[3]:.3f} | {row[4]:.3f} | {row[5]:.3f} | {row[6]:.3f} |")
    return out


def write_report(out: Path, campaign, rig, *, budget=None, rig_path: str | None = None,
                 wall_times: dict | None = None, command: str | None = None, user: dict | None = None,
                 picture: tuple[bytes | None, str] | None = None) -> dict[str, Path]:
    """Write the report's files into ``out``; returns them by kind.

    ``picture``: the rig picture made beforehand, ``(PNG bytes of the rig at the first face's exact
    null, "")`` or ``(None, why it is missing)``; by default it is rendered here, in this process, at
    the first face's null as the search found it.
    """
    out = Path(out)
    output_folder(out)
    files = {"calibration_residuals": plot_calibration_residuals(campaign, out / "calibration_residuals.png"),
             "search_path": plot_search_path(campaign, out / "search_path.png")}
    if budget is not None:
        files["budget_histogram"] = plot_budget_histogram(
            budget, out / "budget_histogram.png", 3.69 if rig.procedure.method == "diaphragm" else None)
    r = campaign.result
    L = [f"# Cube-mirror campaign on rendered frames — {rig.name} (seed {rig.seed_document})", ""]
    if command:
        L += [f"Command: `{command}`", ""]
    L += [rig.description, "",
          f"Rig file: `{rig_path or '—'}` · campaign seed {campaign.seed} · faces {', '.join(rig.procedure.faces)} · "
          f"readings: axis order {r.axis_order}, eq 8 `beam` (every number below unless a table says otherwise; "
          "`rigsim readings`)", ""]
    L += rig_summary_md(rig)
    if picture is None:
        first = r.null_poses_deg[0] if r.null_poses_deg else None
        pic, why = _rig_picture(rig, out, {k: v for k, v in first.items()} if first else None)
        caption = "the rig at the first face's null (rigsim view)"
    else:
        png, why = picture
        pic = None
        if png is not None:
            from rigsim.files.atomic import atomic_write_bytes

            pic = out / "rig.png"
            atomic_write_bytes(pic, png)
        caption = "the rig at the first face's exact null (rigsim view)"
    if pic is not None:
        files["rig_picture"] = pic
        L += [f"![{caption}]({pic.name})", ""]
    else:
        L += [f"(rig picture unavailable: {why})", ""]
    L += ["## Truth vs recovered", "",
          "Small-angle error of each recovered rotation against the rig's truth, about the target frame's axes (arcsec).", "",
          "| quantity | x | y | z | |error| |", "|---|---:|---:|---:|---:|"]
    for name, e in (("R(sun←rot), sweep least squares", r.sun_error_arcsec),
                    ("R(cube←rot), null search + TRIAD", r.cube_error_arcsec),
                    ("**R(cube←sun)** (the product)", r.error_arcsec)):
        L.append(f"| {name} | {e[0]:+.3f} | {e[1]:+.3f} | {e[2]:+.3f} | {np.linalg.norm(e):.3f} |")
    cal = campaign.calibration
    sd = np.sqrt(np.diag(cal.rotation_covariance_rad2)) * ARCSEC_PER_RAD
    L += ["", f"The sweep fit's own 1σ for R(sun←rot): {sd[0]:.3f}″, {sd[1]:.3f}″, {sd[2]:.3f}″ "
          f"(fit rms {cal.rms_px:.4f} px over {cal.n_points} frames; {campaign.sweep.n_rejected} frames rejected"
          + (f", {len(cal.outliers)} left out of the fit as outliers" if len(cal.outliers) else "")
          + (f", {len(cal.outside_field)} beyond {rig.procedure.sweep_max_field_deg:g}° of the axis"
             if len(cal.outside_field) else "") + ").", ""]
    ss = rig.sun_sensor
    truth = {"fx": ss.fx_px, "fy": ss.fx_px * ss.fy_over_fx, "cx": ss.principal_point_px[0], "cy": ss.principal_point_px[1],
             "k1": ss.distortion.k1, "k2": ss.distortion.k2, "p1": ss.distortion.p1, "p2": ss.distortion.p2}
    L += ["Sun-sensor intrinsics:", "", "| parameter | true | recovered | 1σ (fit) | error / σ |", "|---|---:|---:|---:|---:|"]
    sig = cal.sigma
    for k, tv in truth.items():
        if k in cal.param_names:
            v = float(cal.params[cal.param_names.index(k)])
            L.append(f"| {k} | {tv:.9g} | {v:.9g} | {sig[k]:.2g} | {(v - tv) / sig[k]:+.2f} |")
    L += ["", "Null readings (turntable, degrees):", "", "| face | " + " | ".join(sorted(r.null_poses_deg[0])) + " |",
          "|---|" + "---:|" * len(r.null_poses_deg[0])]
    for f, p in zip(rig.procedure.faces, r.null_poses_deg):
        L.append(f"| {f} | " + " | ".join(f"{p[k]:.5f}" for k in sorted(p)) + " |")
    L += ["", "## Null search log (the form of the paper's Table 1)", ""]
    if campaign.step_a is not None:
        sa = campaign.step_a
        L += [f"Step A (plane mirror): {len(sa.measured_arcsec)} frames, readings (arcsec): "
              + ", ".join(f"({m[0]:+.3f}, {m[1]:+.3f})" for m in sa.measured_arcsec), ""]
    for s in campaign.searches:
        L += [f"Face {s.face}: {'converged' if s.converged else 'NOT converged — ' + s.message} in {len(s.steps)} frames "
              f"(threshold {s.threshold:g} {s.unit}).", ""] + _search_table_md(s) + [""]
    L += ["![search path](search_path.png)", "", "![calibration residuals](calibration_residuals.png)", ""]
    mn = campaign.measured_noise
    L += ["## Measured image noise (this run's rendered frames vs the exact model)", "",
          f"* sun-sensor centroid − exact sun-centre projection: {mn['sun_centroid_rms_px']:.4f} px rms "
          f"(u {mn['sun_centroid_rms_px_xy'][0]:.4f}, v {mn['sun_centroid_rms_px_xy'][1]:.4f})",
          f"* null measurement − exact: {mn['null_measurement_rms']:.4f} {mn['null_measurement_unit']} rms "
          f"(x {mn['null_measurement_rms_xy'][0]:.4f}, y {mn['null_measurement_rms_xy'][1]:.4f}; {mn['null_measurement_n']} frames near the null)", ""]
    if budget is not None:
        L += ["## Error budget (Monte Carlo)", "",
              f"{budget.rows[0].n} campaigns per row. Each draws the rig errors of its row and runs the same procedure "
              "as above (sweep least squares, null search with the same threshold, command steps and feedback rule, TRIAD), "
              "with the image measurements replaced by exact values plus the noise measured above "
              f"(sun centroid {budget.sun_centroid_sigma_px:.4f} px, null {budget.null_sigma:.4f} {budget.null_unit}). "
              "Per-axis σ of the R(cube←sun) error about the cube axes (arcsec).", "",
              "| source | σx | σy | σz | paper |", "|---|---:|---:|---:|---:|"]
        for row in budget.rows:
            s = row.sigma_arcsec
            L.append(f"| {row.source} | {s[0]:.2f} | {s[1]:.2f} | {s[2]:.2f} | {_f(row.paper_arcsec, 2) if row.paper_arcsec else '—'} |")
        rss = budget.rss_of_sources()
        tog = budget.together().sigma_arcsec
        L += ["", f"RSS of the rows {', '.join(n.split(' (')[0] for n in budget.paper_rows)}: "
              f"{rss[0]:.2f} / {rss[1]:.2f} / {rss[2]:.2f}″; simulated together: {tog[0]:.2f} / {tog[1]:.2f} / {tog[2]:.2f}″ "
              f"(ratio {tog[0] / rss[0]:.2f} / {tog[1] / rss[1]:.2f} / {tog[2] / rss[2]:.2f})."]
        if rig.procedure.method == "diaphragm":
            L += [f"The paper's RSS is 3.69″ (eq 14) and it claims better than 4″ (1σ). Here the paper's four sources "
                  f"together give {tog[0]:.2f} / {tog[1]:.2f} / {tog[2]:.2f}″ per axis; everything together "
                  + " / ".join(f"{x:.2f}" for x in budget.rows[-1].sigma_arcsec) + "″. docs/campaign.md explains the "
                  "differences (σ1 from the search is smaller than the paper's 1 px; the sun-sensor calibration is left out of "
                  "the paper's budget)."]
        L += ["", "![budget histogram](budget_histogram.png)", ""]
    from rigsim.procedures.cube_mirror.readings import campaign_readings, readings_markdown

    rd = campaign_readings(r, rig)
    L += readings_markdown(rd, 4.0 if rig.seed_document == "000" else None)
    if user is not None:
        from rigsim.procedures.cube_mirror.user_frames import comparison_markdown

        L += comparison_markdown(user)
    if wall_times:
        L += ["## Wall time by stage", "", "| stage | s |", "|---|---:|"]
        for k, v in wall_times.items():
            L.append(f"| {k} | {v:.2f} |")
        L.append("")
    atomic_write_text((out / "report.md"), "\n".join(L) + "\n")
    files["report"] = out / "report.md"
    from rigsim.procedures.cube_mirror.result_json import campaign_json

    rec = campaign_json(r, rig, mode="rendered", seed=campaign.seed, rig_file=rig_path)
    rec.update({"searches": [s.as_dict() for s in campaign.searches], "measured_noise": campaign.measured_noise,
                "times_s": wall_times or campaign.times, "readings": rd})
    if user is not None:
        rec["user_centroider"] = user
    if budget is not None:
        rec["budget"] = [{"source": b.source, "sigma_arcsec": b.sigma_arcsec.tolist(), "paper_arcsec": b.paper_arcsec,
                          "n": b.n} for b in budget.rows]
    atomic_write_text((out / "campaign.json"), json.dumps(rec, indent=1, default=float))
    files["json"] = out / "campaign.json"
    from rigsim.reporting import markdown_to_html

    files["html"] = markdown_to_html(out / "report.md")
    return files
