"""One JSON shape for every boresight result (``boresight solve --json-out`` on a user's spot tables,
``boresight.json`` of ``rigsim run boresight``): per sample and camera the recovered (Δf, α, β, γ) and the
camera's rotation R(reference HRC ← measured HRC) with their covariance; per sample with both cameras the
change of the angle between them (the quantity the rig monitors) with its covariance; and, in rigsim's own
runs, the truth and the error beside each. Published as ``rigsim/schemas/boresight-result.schema.json``.

Covariances are first-order propagations of the centroid noise through the estimator itself: central
differences of the solver with respect to each measured and each reference spot coordinate, with the
reference (the mean of N rows) at σ/√N."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rigsim.estimation.dvad import BoresightEstimate, estimate
from rigsim.files import covariance_block
from rigsim.frames import ARCSEC_PER_RAD
from rigsim.optics.line_camera import CameraGeometry, relative_rotation, small_angles_arcsec
from rigsim.procedures.results import result_header, rotation_block

__all__ = ["BORESIGHT_FORMAT", "PARAMS", "boresight_result_json", "orbit_result_json", "propagated_covariances"]

BORESIGHT_FORMAT = "rigsim.boresight-result/1"
PARAMS = (["delta_f", "alpha", "beta", "gamma"], ["um", "arcsec", "arcsec", "arcsec"])
H_PX = 1e-3  # central-difference step on a spot coordinate


def _params(e: BoresightEstimate) -> np.ndarray:
    """(n, 4): Δf (µm), α, β, γ (arcsec)."""
    return np.column_stack([np.atleast_1d(e.delta_f_mm) * 1e3, np.atleast_2d(e.angles_arcsec)])


def _rotations(e: BoresightEstimate) -> np.ndarray:
    return np.asarray(e.rotation(), float).reshape(-1, 3, 3)


def _jacobians(geom, ref_uv, meas_uv, method, reading, fn):
    """d fn(estimate) / d (measured u1, v1, u2, v2, reference u1, v1, u2, v2): (n, k, 8)."""
    ref = np.asarray(ref_uv, float)
    meas = np.asarray(meas_uv, float).reshape(-1, 2, 2)
    cols = []
    for which in ("meas", "ref"):
        for j in range(4):
            d = np.zeros((2, 2))
            d.flat[j] = H_PX
            if which == "meas":
                p = fn(estimate(geom, ref, meas + d, method, reading))
                m = fn(estimate(geom, ref, meas - d, method, reading))
            else:
                p = fn(estimate(geom, ref + d, meas, method, reading))
                m = fn(estimate(geom, ref - d, meas, method, reading))
            cols.append((p - m) / (2 * H_PX))
    return np.stack(cols, axis=-1)


def _weights(sigma_meas: np.ndarray, sigma_ref: np.ndarray) -> np.ndarray:
    """(n, 8) variances of the 8 inputs: measured (u1, v1, u2, v2) per row, then the reference's."""
    sm = np.broadcast_to(np.asarray(sigma_meas, float), (sigma_meas.shape[0], 4)) ** 2
    return np.column_stack([sm, np.broadcast_to(np.asarray(sigma_ref, float) ** 2, (sm.shape[0], 4))])


def propagated_covariances(geom: CameraGeometry, ref_uv, meas_uv, sigma_meas, sigma_ref, *, method="dvad",
                           reading="consistent") -> np.ndarray:
    """(n, 4, 4) covariance of (Δf µm, α″, β″, γ″) per row. ``sigma_meas`` (n, 4) or scalar px per measured
    coordinate (u1, v1, u2, v2); ``sigma_ref`` (4,) or scalar px of the reference's coordinates."""
    n = np.asarray(meas_uv).reshape(-1, 2, 2).shape[0]
    J = _jacobians(geom, ref_uv, meas_uv, method, reading, _params)
    W = _weights(np.broadcast_to(np.asarray(sigma_meas, float), (n, 4)), sigma_ref)
    return np.einsum("nka,na,nla->nkl", J, W, J)


def boresight_result_json(rig, geoms: dict[str, CameraGeometry], ref: dict[str, np.ndarray], samples: Sequence[str],
                          cams: Sequence[str], uv: np.ndarray, sigma_meas: np.ndarray, sigma_ref: dict[str, np.ndarray],
                          *, method: str = "dvad", reading: str = "consistent", mode: str = "files", seed=None,
                          rig_file=None, sigma_source: str = "", truth=None) -> dict:
    """The result record. ``uv`` (n, 2, 2) spot rows (M1, M2 × u, v) of ``cams``/``samples``; ``sigma_meas``
    (n, 4) px per row; ``sigma_ref`` per camera (4,) px. ``truth``: optional {(sample, camera): (Δf mm, E)} and
    {sample: ΔR relative} as ``truth["camera"]``, ``truth["relative"]`` (rigsim's own runs only)."""
    uv = np.asarray(uv, float).reshape(-1, 2, 2)
    sigma_meas = np.asarray(sigma_meas, float).reshape(-1, 4)
    truth = truth or {}
    names, units = PARAMS
    out = {**result_header(BORESIGHT_FORMAT, "boresight", mode, rig, seed=seed, rig_file=rig_file),
           "method": method, "reading": reading,
           "parameters": {"names": names, "units": units,
                          "convention": "α, β, γ: intrinsic XYZ Euler angles of R(reference HRC ← measured HRC) about "
                                        "X_HRC, Y_HRC, Z_HRC; Δf: the focal-length change"},
           "centroid_sigma_source": sigma_source,
           "reference": {c: {"uv_px": np.asarray(r).tolist(), "sigma_px": np.asarray(sigma_ref[c]).tolist()}
                         for c, r in ref.items()},
           "samples": [], "relative": []}
    rows_of = {c: [k for k, x in enumerate(cams) if x == c] for c in dict.fromkeys(cams)}
    per_row: dict[int, dict] = {}
    for c, rows in rows_of.items():
        g = geoms[c]
        e = estimate(g, ref[c], uv[rows], method, reading)
        P, R = _params(e), _rotations(e)
        C = propagated_covariances(g, ref[c], uv[rows], sigma_meas[rows], sigma_ref[c], method=method, reading=reading)
        for i, k in enumerate(rows):
            t = truth.get("camera", {}).get((samples[k], c))
            C_rot = C[i, 1:, 1:] / ARCSEC_PER_RAD**2
            rec = {"sample": samples[k], "camera": c, "delta_f_um": P[i, 0], "angles_arcsec": P[i, 1:].tolist(),
                   "covariance": covariance_block(names, C[i], units),
                   "R_ref_from_meas": rotation_block(R[i], C_rot, None if t is None else t[1]),
                   "true_delta_f_um": None if t is None else float(t[0]) * 1e3,
                   "delta_f_error_um": None if t is None else float(P[i, 0] - t[0] * 1e3)}
            out["samples"].append(rec)
            per_row[k] = {"camera": c, "R": R[i]}
    # the angle between the cameras, for every sample that both of the rig's first two cameras measured
    cam_names = [x.name for x in rig.cameras][:2]
    if len(cam_names) == 2 and all(c in rows_of for c in cam_names):
        by_sample = {}
        for k, s in enumerate(samples):
            by_sample.setdefault(s, {})[cams[k]] = k
        pairs = [(s, d[cam_names[0]], d[cam_names[1]]) for s, d in by_sample.items() if all(c in d for c in cam_names)]
        if pairs:
            out["relative"] = _relative(rig, geoms, ref, cam_names, pairs, uv, sigma_meas, sigma_ref, method, reading,
                                        truth.get("relative", {}))
    return out


def _relative(rig, geoms, ref, cam_names, pairs, uv, sigma_meas, sigma_ref, method, reading, true_rel) -> list:
    g1, g2 = geoms[cam_names[0]], geoms[cam_names[1]]
    k1 = [p[1] for p in pairs]
    k2 = [p[2] for p in pairs]
    E1 = _rotations(estimate(g1, ref[cam_names[0]], uv[k1], method, reading))
    E2 = _rotations(estimate(g2, ref[cam_names[1]], uv[k2], method, reading))
    dR = relative_rotation(E1, E2, g1, g2)
    # Jacobian of the relative angles with respect to each camera's 8 inputs (the other camera held)
    J1 = _jacobians(g1, ref[cam_names[0]], uv[k1], method, reading,
                    lambda e: small_angles_arcsec(relative_rotation(_rotations(e), E2, g1, g2)))
    J2 = _jacobians(g2, ref[cam_names[1]], uv[k2], method, reading,
                    lambda e: small_angles_arcsec(relative_rotation(E1, _rotations(e), g1, g2)))
    C = (np.einsum("nka,na,nla->nkl", J1, _weights(sigma_meas[k1], sigma_ref[cam_names[0]]), J1)
         + np.einsum("nka,na,nla->nkl", J2, _weights(sigma_meas[k2], sigma_ref[cam_names[1]]), J2))
    out = []
    for i, (s, _, _) in enumerate(pairs):
        t = true_rel.get(s)
        out.append({"sample": s, "cameras": list(cam_names), "angles_arcsec": small_angles_arcsec(dR[i]).tolist(),
                    "R_change": rotation_block(dR[i], C[i] / ARCSEC_PER_RAD**2, t)})
    return out


def orbit_result_json(rig, spots: dict, *, seed, reading: str, mode: str = "rendered", rig_file=None) -> dict:
    """The result record of the rendered orbit scenario (``run_orbit``'s ``_spots``): DVAD on every measurement,
    σ of each centroid coordinate measured as the scatter of the reference frames (the reference, their mean,
    at σ/√N), the truth beside each estimate."""
    names = [c.name for c in rig.cameras][:2]
    geoms = dict(zip(names, spots["geoms"]))
    ref_uv, meas, truth = spots["ref_uv"], spots["meas"], spots["truth"]
    n = meas.shape[1]
    std = np.asarray(spots["ref_std"], float).reshape(2, 4)           # per camera: u1, v1, u2, v2
    k_ref = int(spots["reference_frames"])
    samples, cams, uv, sig = [], [], [], []
    for k in range(n):
        for c in range(2):
            samples.append(str(k))
            cams.append(names[c])
            uv.append(meas[c, k])
            sig.append(std[c])
    true_cam = {(str(k), names[c]): (truth.delta_f_mm[c][k], truth.E[c][k]) for k in range(n) for c in range(2)}
    true_rel = {str(k): truth.relative_R[k] for k in range(n)}
    return boresight_result_json(
        rig, geoms, {names[c]: ref_uv[c] for c in range(2)}, samples, cams, np.array(uv), np.array(sig),
        {names[c]: std[c] / np.sqrt(k_ref) for c in range(2)}, method="dvad", reading=reading, mode=mode, seed=seed,
        rig_file=rig_file, sigma_source=f"measured: the scatter of the {k_ref} rendered reference frames per coordinate",
        truth={"camera": true_cam, "relative": true_rel})
