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
from rigsim.imaging import NoiseModel
from rigsim.imaging.frame_spots import FRAME_METHODS, measure_frame, single_spot
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
    on_frame: Callable | None = None,
) -> tuple[SweepObservation, SweepTruth]:
    """Render, centroid and record the sweep (module docstring): (observation, truth). ``noiseless``: detector noise off
    (rendering noise and quantisation stay). ``step_deg`` overrides the procedure's sweep step.
    ``centroider``: a method of :func:`rigsim.imaging.frame_spots.measure_frame` (the ``rigsim
    centroid`` stage): ``"scurve"`` (default: first moment with the disk's pixel-phase correction)
    or ``"tcom"``/``"wcom"``/``"gauss"``. ``on_frame(frame, spots, k, reading_rad, pose_index)`` sees
    every rendered frame, its spots, the index of the one measured (None: rejected), the turntable
    reading and the sweep pose's index."""
    if centroider not in FRAME_METHODS:
        raise ValueError(f"centroider = {centroider!r}: allowed {', '.join(FRAME_METHODS)}")
    import time

    from rigsim.render.cube_mirror.sun_sensor import SunSensorScene

    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    proc = rig.procedure
    fixed = {a.label: 0.0 for a in rig.turntable.axes if a.label not in proc.sweep_axes}
    step = proc.sweep_step_deg if step_deg is None else float(step_deg)
    poses = sweep_poses(proc.sweep_axes, proc.sweep_range_deg, step, fixed)
    n = len(next(iter(poses.values())))
    # what the encoders read at every pose (true + bias + noise), drawn before the frames
    read = {k: v + real.encoder_bias_rad.get(k, 0.0) + rng.normal(0.0, noise.encoder_sigma_rad.get(k, 0.0), n)
            for k, v in poses.items()}
    scene = SunSensorScene(rig, real, spp=spp)
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
        det = rig.sun_sensor.detector
        spots = measure_frame(fr.dn, NoiseModel.from_detector(det), method=centroider, saturation_dn=det.max_dn,
                              threshold_dn=0.5 if noiseless else None, origin_uv=fr.origin_uv,
                              detector_shape=fr.detector_shape)
        k = single_spot(spots)
        if on_frame is not None:
            on_frame(fr, spots, k, {a: float(r[i]) for a, r in read.items()}, i)
        if k is None:
            rejected += 1
        else:
            keep.append(i)
            uv.append([float(spots.u[k]), float(spots.v[k])])
            uv_true.append(fr.sidecar["truth"]["spot"]["pixel_centroid_uv"])
            uv_centre.append(fr.sidecar["truth"]["spot"]["center_uv"])
        if progress:
            progress(1)
    keep = np.array(keep, dtype=int)
    readings = TurntableReading({a: r[keep] for a, r in read.items()})
    obs = SweepObservation(readings, np.array(uv), rendered, rejected, time.perf_counter() - t0)
    return obs, SweepTruth(TruePose({k: v[keep] for k, v in poses.items()}), np.array(uv_true), np.array(uv_centre))


def calibrate_from_sweep(rig: CubeMirrorRig, sweep: SweepObservation, axis_order: str | None = None) -> SunCalibration:
    order = list(axis_order) if axis_order else [a.label for a in rig.turntable.axes]
    ss = rig.sun_sensor
    return calibrate_sun_sensor(sweep.readings, sweep.uv, TurntableModel.nominal(order), *ss.resolution_px,
                                f_guess_px=ss.fx_px, d_rot=NOMINAL_D)
