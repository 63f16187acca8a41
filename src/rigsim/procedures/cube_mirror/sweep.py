"""Seed 000 step 1 / seed 001 step B on rendered frames: the sun-sensor calibration sweep.

For every sweep pose: render the sun-sensor frame (Mitsuba + detector model) at the *true*
pose, record the turntable *reading* (true + encoder bias + noise), extract the spot with
rigsim.imaging and centroid it, then fit intrinsics + R(sun←rot) by least squares with the
nominal turntable. The estimator sees readings and centroids only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rigsim.estimation.sun_calibration import SunCalibration, calibrate_sun_sensor, sweep_poses
from rigsim.imaging import Flag, centroid_tcom
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import NOMINAL_D, TruePose, TurntableModel, TurntableReading
from rigsim.truth.cube_mirror.realization import Noise, Realization


@dataclass
class SweepObservation:
    """What the rig records: the turntable's readings and the measured centroid of every kept frame."""

    readings: TurntableReading  # arrays (N,) per axis
    uv: np.ndarray  # measured centroids (N, 2)
    n_rendered: int
    n_rejected: int  # frames whose spot was flagged (edge, saturated, …) and left out
    seconds: float


@dataclass
class SweepTruth:
    """The same frames' truth (for the comparison step only)."""

    poses: TruePose  # true turntable angles (N,) per axis
    uv_pixel_centroid: np.ndarray  # exact pixel-binned centroid of each spot (N, 2)
    uv_centre: np.ndarray  # exact projection of the sun's centre (what the calibration model predicts) (N, 2)


def render_sweep(
    rig: CubeMirrorRig,
    real: Realization,
    noise: Noise,
    seed: int,
    *,
    spp: int = 256,
    progress: Callable[[int], None] | None = None,
    noiseless: bool = False,
    step_deg: float | None = None,
    centroider: str = "scurve",
) -> tuple[SweepObservation, SweepTruth]:
    """Render, centroid and record the sweep (module docstring): (observation, truth). ``noiseless``: detector noise off
    (rendering noise and quantisation stay). ``step_deg`` overrides the procedure's sweep step.
    ``centroider``: ``"scurve"`` (default: first moment with the disk's pixel-phase correction,
    :mod:`rigsim.imaging.scurve`) or ``"tcom"`` (thresholded first moment, biased by up to 0.02 px
    on this 2.5 px sun disk)."""
    if centroider not in ("scurve", "tcom"):
        raise ValueError(f"centroider = {centroider!r}: must be 'scurve' or 'tcom'")
    import time

    from rigsim.imaging.scurve import centroid_disk_scurve
    from rigsim.render.cube_mirror.sun_sensor import SunSensorScene

    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    proc = rig.procedure
    fixed = {a.label: 0.0 for a in rig.turntable.axes if a.label not in proc.sweep_axes}
    step = proc.sweep_step_deg if step_deg is None else float(step_deg)
    poses = sweep_poses(proc.sweep_axes, proc.sweep_range_deg, step, fixed)
    n = len(next(iter(poses.values())))
    scene = SunSensorScene(rig, real, spp=spp)
    offset = rig.sun_sensor.detector.offset_dn
    keep, uv, uv_true, uv_centre = [], [], [], []
    rejected = 0
    rendered = 0
    for i in range(n):
        pose = {k: float(v[i]) for k, v in poses.items()}
        s = scene.sun_dir_cam(pose)
        c, ok = scene.camera.project_valid(s[None, :])
        if not (ok[0] and scene.camera.on_detector(c, margin_px=3.0)[0]):
            if progress:
                progress(1)
            continue  # the sun is outside the field at this pose: no spot to record
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fr = scene.render(pose, seed=int(rng.integers(2**31)), truth_points=200_000, full_frame=False,
                                 noiseless=noiseless)
        rendered += 1
        f = fr.sidecar["flags"]
        roi = fr.dn.astype(float) - offset  # the crop window, at fr.origin_uv on the detector
        cen = centroid_tcom(roi, origin_uv=fr.origin_uv, saturation=rig.sun_sensor.detector.max_dn - offset)
        bad = Flag.INVALID | Flag.SATURATED | Flag.EDGE
        if f["spot_cut_by_edge"] or f["saturated"] or (cen.flags & bad):
            rejected += 1
        else:
            keep.append(i)
            if centroider == "scurve":
                det = rig.sun_sensor.detector
                # above the noise (5σ of the read noise, ≥ 3 DN); a noise-free frame only needs to
                # clear the quantisation, and every faint rim pixel matters to the S-curve model
                thr = 0.5 if noiseless else max(3.0, 5.0 * det.read_noise_e * det.gain_dn_per_e)
                c, _w = centroid_disk_scurve(roi, fr.origin_uv, threshold=thr)
                uv.append([float(c[0]), float(c[1])])
            else:
                uv.append([cen.u, cen.v])
            uv_true.append(fr.sidecar["truth"]["spot"]["pixel_centroid_uv"])
            uv_centre.append(fr.sidecar["truth"]["spot"]["center_uv"])
        if progress:
            progress(1)
    keep = np.array(keep, dtype=int)
    readings = TurntableReading({
        k: v[keep] + real.encoder_bias_rad.get(k, 0.0) + rng.normal(0.0, noise.encoder_sigma_rad.get(k, 0.0), keep.size)
        for k, v in poses.items()
    })
    obs = SweepObservation(readings, np.array(uv), rendered, rejected, time.perf_counter() - t0)
    return obs, SweepTruth(TruePose({k: v[keep] for k, v in poses.items()}), np.array(uv_true), np.array(uv_centre))


def calibrate_from_sweep(rig: CubeMirrorRig, sweep: SweepObservation, axis_order: str | None = None) -> SunCalibration:
    order = list(axis_order) if axis_order else [a.label for a in rig.turntable.axes]
    ss = rig.sun_sensor
    return calibrate_sun_sensor(sweep.readings, sweep.uv, TurntableModel.nominal(order), *ss.resolution_px,
                                f_guess_px=ss.fx_px, d_rot=NOMINAL_D)
