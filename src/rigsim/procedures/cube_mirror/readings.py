"""This run's numbers under every reading of the documents that the estimator's last step depends on: the
recorded null readings through TRIAD under each axis nesting and each reading of seed 000's eq 8, against the
rig's truth; and, on a seed-001 rig, the analysis of the patent's printed R(ref←sun). The report's
"Readings" section and campaign.json's ``readings`` block."""

from __future__ import annotations

import math

import numpy as np

from rigsim.estimation.cube_attitude import EQ8_READINGS, cube_from_rot_triad
from rigsim.estimation.triad import triad_conditioning
from rigsim.frames import ARCSEC_PER_RAD, small_angle_error
from rigsim.optics.cube import FACE_NORMALS
from rigsim.procedures.cube_mirror.files import axis_orders

__all__ = ["campaign_readings", "readings_markdown"]


def campaign_readings(result, rig) -> dict:
    """R(cube←rot) and R(cube←sun) (with this run's R(sun←rot)) from this run's two null readings under every
    (axis nesting, eq 8) reading, with the error against the truth and the TRIAD conditioning. ``result``: a
    :class:`~rigsim.procedures.cube_mirror.campaign.CampaignResult`. The sweep fit is not redone: under another
    nesting it would also change (docs/readings.md)."""
    labels = sorted(a.label for a in rig.turntable.axes)
    faces = list(rig.procedure.faces)
    readings = [{k: math.radians(v) for k, v in p.items()} for p in result.null_poses_deg]
    rows = []
    for order in [o for o in axis_orders(rig) if sorted(o) == labels]:
        for eq8 in EQ8_READINGS:
            R, r1, r2 = cube_from_rot_triad(readings, faces, order, eq8=eq8)
            c = triad_conditioning(FACE_NORMALS[faces[0]], FACE_NORMALS[faces[1]], r1, r2)
            e_cube = small_angle_error(R, result.R_cube_from_rot_true) * ARCSEC_PER_RAD
            e_cs = small_angle_error(R @ result.R_sun_from_rot_est.T, result.R_cube_from_sun_true) * ARCSEC_PER_RAD
            rows.append({"axis_order": order, "eq8": eq8, "default": order == result.axis_order and eq8 == "beam",
                         "cube_from_rot_error_arcsec": e_cube.tolist(), "cube_from_sun_error_arcsec": e_cs.tolist(),
                         "cube_from_sun_error_norm_arcsec": float(np.linalg.norm(e_cs)), **c})
    out = {"triad": rows}
    if rig.procedure.method == "diaphragm":
        from rigsim.procedures.readings import seed000_budget_readings

        out["budget"] = seed000_budget_readings(rig)
    if rig.seed_document == "001":
        from rigsim.estimation.rotation_check import analyse_rotation_matrix
        from rigsim.procedures.readings import PATENT_R_REF_FROM_SUN

        out["printed_matrix"] = analyse_rotation_matrix(PATENT_R_REF_FROM_SUN)
    return out


def readings_markdown(rd: dict, claim_arcsec: float | None) -> list[str]:
    """The report section. ``claim_arcsec``: the document's accuracy claim (seed 000: 4″), or None."""
    L = ["## Readings of the document (this run's nulls under each)", "",
         ("The two null readings of this run through TRIAD under each reading of the turntable's axis nesting and of "
         "seed 000's eq 8 (`rigsim readings` lists them all), against the rig's truth; R(cube←sun) uses this run's "
         "sweep fit. The default row is the one reported above."), "",
         "| axis order | eq 8 | ∠(r1, r2) | amplification | R(cube←rot) error [″] | R(cube←sun) error [″] | ‖error‖ [″] |"
         + (" claim |" if claim_arcsec else ""),
         "|---|---|---:|---:|---:|---:|---:|" + ("---|" if claim_arcsec else "")]
    for r in rd["triad"]:
        ec, es = r["cube_from_rot_error_arcsec"], r["cube_from_sun_error_arcsec"]
        name = f"**{r['axis_order']}**" if r["default"] else r["axis_order"]
        line = (f"| {name} | {r['eq8']} | {r['angle_r_deg']:.3f}° | ×{r['amplification']:.1f} | "
                f"{ec[0]:+.1f}, {ec[1]:+.1f}, {ec[2]:+.1f} | {es[0]:+.1f}, {es[1]:+.1f}, {es[2]:+.1f} | "
                f"{r['cube_from_sun_error_norm_arcsec']:.1f} |")
        if claim_arcsec:
            ok = max(abs(x) for x in es) < claim_arcsec
            line += f" {'holds' if ok else 'fails'} (< {claim_arcsec:g}″ per axis) |"
        L.append(line)
    L.append("")
    if "budget" in rd:
        L += ["The paper's budget (eq 14: σ1 ⊕ 2″ ⊕ 2″ ⊕ 0.4″) and its < 4″ claim under each reading of σ1 (σ1 derived "
              "from this rig's aiming camera):", "", "| σ1 reading | σ1 [″] | RSS [″] | < 4″ |", "|---|---:|---:|---|"]
        L += [f"| {b['sigma1_reading']} | {b['sigma1_arcsec']:.3f} | {b['rss_arcsec']:.2f} | "
              f"{'holds' if b['claim_holds'] else 'fails'} |" for b in rd["budget"]]
        L.append("")
    if "printed_matrix" in rd:
        m = rd["printed_matrix"]
        rep = m["sign_repair"]
        L += ["The patent's printed example R(ref←sun) (`rigsim check-matrix`): determinant "
              f"{m['determinant']:+.4f}, max |M·Mᵀ − I| = {m['max_abs_MMt_minus_I']:.3f}: "
              + ("not a rotation. " if not m["proper"] else "a rotation. ")
              + (f"Flipping the sign of {rep['change']} alone makes it one (det {rep['determinant']:+.5f}, "
                 f"max |M·Mᵀ − I| {rep['max_abs_MMt_minus_I']:.1e}; xyz Euler "
                 + ", ".join(f"{a:.2f}°" for a in rep["euler_xyz_deg"]) + "); rigsim does not reproduce the printed "
                 "matrix." if rep else ""), ""]
    return L
