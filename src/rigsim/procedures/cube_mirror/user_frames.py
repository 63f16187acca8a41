"""The rendered campaign's frames for a user's own pipeline: written as bare files (no sidecar, no
truth) with the angle and null logs (``run cube-mirror --export-frames``), measured by a user's
Python centroider on the same frames (``--centroider PKG.MODULE:FUNC``) or by a centroid table
the user made from an earlier export (``--import-centroids``); the sweep is then calibrated again
with the user's centroids and compared with the same truth, beside rigsim's own result."""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rigsim.errors import CliError, InputError
from rigsim.files import write_image, write_table
from rigsim.frames import ARCSEC_PER_RAD, small_angle_error
from rigsim.procedures.cube_mirror.campaign import compare
from rigsim.procedures.cube_mirror.pipeline import estimate
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import TurntableReading

__all__ = ["load_centroider", "CampaignFrames", "user_comparison", "sweep_frame_name"]


def sweep_frame_name(pose_index: int, suffix: str = ".png") -> str:
    """The file name of the sweep frame at a sweep pose (the same in every run of a rig and seed)."""
    return f"sweep_{pose_index:04d}{suffix}"


def load_centroider(spec: str) -> Callable[[np.ndarray], tuple[float, float]]:
    """``PKG.MODULE:FUNC`` → the callable (a frame ``img[v, u]`` in DN → (u, v) in detector px, pixel
    (0, 0)'s centre at (0, 0); NaN for no spot)."""
    mod, sep, func = spec.partition(":")
    if not sep or not mod or not func.isidentifier():
        raise CliError(f"--centroider = {spec!r}: expected PKG.MODULE:FUNC (a Python callable frame → (u, v))")
    try:
        m = importlib.import_module(mod)
    except ImportError as exc:
        raise CliError(f"--centroider = {spec!r}: cannot import {mod!r} ({exc})") from None
    f = getattr(m, func, None)
    if not callable(f):
        raise CliError(f"--centroider = {spec!r}: {mod} has no callable {func!r}")
    return f


@dataclass
class CampaignFrames:
    """Collects the sweep's frames as the campaign renders them: the reading of every frame, rigsim's
    spot, the exact sun centre (truth, for the comparison only), optionally writes each frame as a
    bare file and runs a user's centroider on it."""

    rig: CubeMirrorRig
    out_dir: Path | None = None
    centroider: Callable | None = None
    centroider_name: str = ""
    suffix: str = ".png"
    seed: int = 0
    names: list[str] = field(default_factory=list)
    readings: list[dict] = field(default_factory=list)
    rigsim_uv: list = field(default_factory=list)
    user_uv: list = field(default_factory=list)
    exact_uv: list = field(default_factory=list)
    null_rows: list[dict] = field(default_factory=list)

    def _full(self, fr) -> np.ndarray:
        from rigsim.render.frame import full_detector_frame

        ss = int(np.random.SeedSequence([self.seed, len(self.names)]).generate_state(1)[0])
        return full_detector_frame(fr, self.rig.sun_sensor.detector, seed=ss)

    def sweep_frame(self, fr, spots, k, reading_rad: dict, pose_index: int | None = None) -> None:
        name = sweep_frame_name(len(self.names) if pose_index is None else pose_index, self.suffix)
        img = self._full(fr) if (self.out_dir is not None or self.centroider is not None) else None
        if self.out_dir is not None:
            write_image(self.out_dir / name, img)
        if self.centroider is not None:
            self.user_uv.append(self._call_user(img, name))
        self.names.append(name)
        self.readings.append(dict(reading_rad))
        self.rigsim_uv.append((math.nan, math.nan) if k is None else (float(spots.u[k]), float(spots.v[k])))
        self.exact_uv.append(tuple(fr.sidecar["truth"]["spot"]["center_uv"]))

    def _call_user(self, img: np.ndarray, name: str) -> tuple[float, float]:
        try:
            out = self.centroider(img)
            u, v = (float(x) for x in out)
        except Exception as exc:  # noqa: BLE001 — a user's code: report it in one line
            raise CliError(f"--centroider {self.centroider_name}: on frame {name}: {type(exc).__name__}: {exc}") from None
        return (u, v) if math.isfinite(u) and math.isfinite(v) else (math.nan, math.nan)

    def null_frame(self, kind: str, dn: np.ndarray, info: dict) -> None:
        """A frame of a null search (aiming camera or autocollimator) as rendered."""
        name = f"{kind}_{len(self.null_rows):03d}{self.suffix}"
        if self.out_dir is not None:
            write_image(self.out_dir / name, np.asarray(dn))
        row = {"frame": name, "kind": kind, "face": info.get("face", "")}
        row.update({f"{a.lower()}_deg": float(v) for a, v in info.get("reading_deg", {}).items()})
        m = info.get("measured_offset_px", info.get("measured_arcsec"))
        unit = "px" if "measured_offset_px" in info else "arcsec"
        row.update({f"measured_x_{unit}": m[0], f"measured_y_{unit}": m[1]} if m is not None else {})
        if "null_offset_px" in info:  # the offset at which the operator's aiming camera shows concentricity
            row.update({"null_offset_x_px": info["null_offset_px"][0], "null_offset_y_px": info["null_offset_px"][1]})
        self.null_rows.append(row)

    def write_logs(self, null_readings: list[TurntableReading], faces) -> dict[str, Path]:
        """angles.csv (every sweep frame's reading), nulls.csv (the readings at the two nulls), null_frames.csv."""
        if self.out_dir is None:
            return {}
        labels = [a.label for a in self.rig.turntable.axes]
        files = {"angles": write_table(self.out_dir / "angles.csv", {
            "frame": self.names, **{f"{a.lower()}_deg": [math.degrees(r[a]) for r in self.readings] for a in labels}})}
        files["nulls"] = write_table(self.out_dir / "nulls.csv", {
            "face": list(faces), **{f"{a.lower()}_deg": [math.degrees(r[a]) for r in null_readings] for a in labels}})
        if self.null_rows:
            keys = list(dict.fromkeys(k for r in self.null_rows for k in r))
            files["null_frames"] = write_table(self.out_dir / "null_frames.csv",
                                               {k: [r.get(k, math.nan) for r in self.null_rows] for k in keys})
        return files

    def import_centroids(self, path) -> None:
        """The user's centroids of these frames from a table (frame, u_px, v_px[, spot, flags])."""
        from rigsim.procedures.cube_mirror.files import read_spot_table

        spots = read_spot_table(path)
        known = set(self.names)
        unknown = [f for f in spots if f not in known]
        if unknown:
            raise InputError(f"{path}: line {spots[unknown[0]][3]}, column frame: {unknown[0]!r} is not a frame of this "
                             f"campaign (expected names like {self.names[0] if self.names else 'sweep_0000.png'}: "
                             "export them with --export-frames, same rig, seed and sweep options)")
        self.user_uv = [(s[0], s[1]) if (s := spots.get(n)) and np.isfinite(s[:2]).all() else (math.nan, math.nan)
                        for n in self.names]


def user_comparison(rig: CubeMirrorRig, frames: CampaignFrames, campaign, real, axis_order: str) -> dict:
    """The campaign again with the user's sweep centroids (same frames, readings and nulls): the
    errors of R(sun←rot) and R(cube←sun) against the truth beside rigsim's, and both centroiders'
    error against the exact sun centre."""
    uv = np.array(frames.user_uv, float).reshape(-1, 2)
    ok = np.all(np.isfinite(uv), axis=1)
    labels = list(frames.readings[0]) if frames.readings else []
    readings = TurntableReading({a: np.array([r[a] for r in frames.readings])[ok] for a in labels})
    null_readings = [s.final_reading_rad for s in campaign.searches]
    est = estimate(rig, null_readings, axis_order, sweep_readings=readings, sweep_uv=uv[ok])
    res = compare(rig, est, real)
    exact = np.array(frames.exact_uv, float)
    mine = np.array(frames.rigsim_uv, float)

    def stats(m):
        good = np.all(np.isfinite(m), axis=1)
        d = m[good] - exact[good]
        return {"n": int(good.sum()), "rms_px": np.sqrt(np.mean(d**2, axis=0)).tolist() if good.any() else [math.nan] * 2,
                "mean_px": d.mean(axis=0).tolist() if good.any() else [math.nan] * 2}

    ours = campaign.result
    return {"centroider": frames.centroider_name or "imported table",
            "rigsim": {"centroids": stats(mine), "R_sun_from_rot_error_arcsec": ours.sun_error_arcsec.tolist(),
                       "R_cube_from_sun_error_arcsec": ours.error_arcsec.tolist()},
            "user": {"centroids": stats(uv), "R_sun_from_rot_error_arcsec": res.sun_error_arcsec.tolist(),
                     "R_cube_from_sun_error_arcsec": res.error_arcsec.tolist(),
                     "fit_rms_px": est.calibration.rms_px, "frames_used": int(ok.sum())},
            "R_cube_from_sun_user_vs_rigsim_arcsec": (small_angle_error(res.R_cube_from_sun_est, ours.R_cube_from_sun_est)
                                                       * ARCSEC_PER_RAD).tolist()}


def comparison_markdown(cmp: dict) -> list[str]:
    """The report section: the user's centroider beside rigsim's on the same frames."""
    L = ["## Your centroider beside rigsim's (same frames, same readings and nulls)", "",
         f"Centroider: `{cmp['centroider']}`. The sweep was calibrated again with its centroids; the null readings "
         "and TRIAD are the campaign's. Errors against the rig's truth.", "",
         "| | frames | centroid − exact u, v (rms px) | mean u, v (px) | R(sun←rot) error x, y, z (″) | "
         "R(cube←sun) error x, y, z (″) |", "|---|---:|---:|---:|---:|---:|"]
    for who in ("rigsim", "user"):
        c = cmp[who]
        s = c["centroids"]
        L.append(f"| {'rigsim' if who == 'rigsim' else 'yours'} | {s['n']} | {s['rms_px'][0]:.4f}, {s['rms_px'][1]:.4f} | "
                 f"{s['mean_px'][0]:+.4f}, {s['mean_px'][1]:+.4f} | "
                 + ", ".join(f"{x:+.3f}" for x in c["R_sun_from_rot_error_arcsec"]) + " | "
                 + ", ".join(f"{x:+.3f}" for x in c["R_cube_from_sun_error_arcsec"]) + " |")
    L.append("")
    return L
