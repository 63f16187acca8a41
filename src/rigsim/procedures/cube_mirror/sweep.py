"""Seed 000 step 1 / seed 001 step B on rendered frames: the sun-sensor calibration sweep.

For every sweep pose: render the sun-sensor frame (Mitsuba + detector model) at the *true*
pose (every frame's spot in a few batched Mitsuba launches), record the turntable *reading* (true + encoder bias + noise), extract the spot with
rigsim.imaging and centroid it, then fit intrinsics + R(sun←rot) by least squares with the
nominal turntable. The estimator sees readings and centroids only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from rigsim.estimation.sun_calibration import SunCalibration, sweep_poses
from rigsim.imaging import NoiseModel
from rigsim.imaging.frame_spots import FRAME_METHODS, measure_frame, single_spot
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.sun_disk import spot_truth
from rigsim.procedures.cube_mirror.spot_fit import model_centroids
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import TruePose, TurntableReading
from rigsim.truth.cube_mirror.realization import Noise, Realization

SWEEP_CENTROIDERS = ("model", *FRAME_METHODS)
"""``model``: the forward-model fit of the spot the rig's optics predict
(:func:`rigsim.procedures.cube_mirror.spot_fit.model_centroids`); the others: a method of
:func:`rigsim.imaging.frame_spots.measure_frame`."""


@dataclass
class SweepObservation:
    """What the rig records: the turntable's readings and the measured centroid of every kept frame."""

    readings: TurntableReading  # arrays (N,) per axis
    uv: np.ndarray  # measured centroids (N, 2)
    n_rendered: int
    n_rejected: int  # frames whose spot was flagged (edge, saturated, …) and left out
    seconds: float
    sigma_uv: np.ndarray | None = None  # the centroider's 1σ of each kept centroid (N, 2), px
    windows: list | None = field(default=None, repr=False)  # ``keep_windows``: (dn, origin_uv) of each kept frame


@dataclass
class SweepTruth:
    """The same frames' truth (for the comparison step only). ``uv_pixel_centroid``, the exact
    pixel-binned centroid of each spot (quadrature of ``quadrature_points`` points), is computed on
    first use: the sweep itself never needs it."""

    poses: TruePose  # true turntable angles (N,) per axis
    uv_centre: np.ndarray  # exact projection of the sun's centre (what the calibration model predicts) (N, 2)
    sun_dir_cam: np.ndarray  # unit vector to the sun in the sensor frame (N, 3)
    camera: PinholeBrown  # the true sensor
    full_angle_rad: float
    response: str = "flux"
    quadrature_points: int = 200_000
    _pixel_centroid: np.ndarray | None = field(default=None, repr=False)

    @property
    def uv_pixel_centroid(self) -> np.ndarray:
        """Exact pixel-binned centroid of each spot (N, 2)."""
        if self._pixel_centroid is None:
            self._pixel_centroid = np.array([
                spot_truth(self.camera, s, self.full_angle_rad, n=self.quadrature_points,
                           response=self.response)["pixel_centroid_uv"] for s in self.sun_dir_cam]).reshape(-1, 2)
        return self._pixel_centroid


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
    centroider: str | None = None,
    on_frame: Callable | None = None,
    keep_windows: bool = False,
) -> tuple[SweepObservation, SweepTruth]:
    """Render, centroid and record the sweep (module docstring): (observation, truth). ``noiseless``: detector noise off
    (rendering noise and quantisation stay). ``step_deg`` overrides the procedure's sweep step.
    ``centroider``: one of :data:`SWEEP_CENTROIDERS` (None: the rig's ``procedure.sweep_centroider``): ``"model"`` (the forward-model fit) or a
    method of :func:`rigsim.imaging.frame_spots.measure_frame` (the ``rigsim centroid`` stage):
    ``"scurve"`` (first moment with the disk's pixel-phase correction), ``"tcom"``/``"wcom"``/``"gauss"``. ``on_frame(frame, spots, k, reading_rad, pose_index)`` sees
    every rendered frame, its spots, the index of the one measured (None: rejected), the turntable
    reading and the sweep pose's index (the frame carries its full sidecar truth). ``keep_windows``:
    the observation keeps each kept frame's readout window (for the image-based calibration,
    :mod:`rigsim.procedures.cube_mirror.image_fit`).

    Every spot in the field is rendered in a few Mitsuba launches (:class:`SunSpotBatch`: tiles just
    large enough for each group of spots, at most three sizes, pasted into the readout window); each
    frame is then digitised with its own detector seed and measured."""
    centroider = rig.procedure.sweep_centroider if centroider is None else centroider
    if centroider not in SWEEP_CENTROIDERS:
        raise ValueError(f"centroider = {centroider!r}: allowed {', '.join(SWEEP_CENTROIDERS)}")
    import time

    from rigsim.detector import apply_detector
    from rigsim.render.cube_mirror.sun_batch import SunSpotBatch, spot_tile_px, tile_groups
    from rigsim.render.cube_mirror.sun_sensor import SunSensorScene, detector_part
    from rigsim.render.scene import mitsuba_seed

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
    cam = scene.camera
    S = np.array([scene.sun_dir_cam({k: float(v[i]) for k, v in poses.items()}) for i in range(n)]).reshape(n, 3)
    c, ok = cam.project_valid(S)
    ok &= cam.on_detector(c, margin_px=3.0)  # elsewhere the sun is outside the field: no spot to record
    field_idx = np.flatnonzero(ok)
    frame_seeds = [int(rng.integers(2**31)) for _ in field_idx]  # one per frame, in pose order, as rendered
    renderer = scene.renderer
    sizes = np.minimum(renderer.window_px, spot_tile_px(cam, S[field_idx], scene.full_angle_rad))
    render_seed = int(rng.integers(2**31))
    tiles: list = [np.zeros((0, 0))] * len(field_idx)  # size 0: outside the camera model, nothing drawn
    for g, (tile, idx) in enumerate(tile_groups(sizes)):  # a launch per tile size: small spots, small tiles
        batch = SunSpotBatch(renderer, tile, len(idx))
        sel = field_idx[idx]
        extra = scene.batch_inputs([{k: float(v[i]) for k, v in poses.items()} for i in sel])  # effects' inputs
        imgs = batch.render(S[sel], np.floor(c[sel] + 0.5).astype(np.int64) - tile // 2, seed=mitsuba_seed(render_seed, g),
                            **extra)
        for j, img in zip(idx, imgs):
            tiles[j] = img
    if progress and n > len(field_idx):
        progress(n - len(field_idx))
    det = rig.sun_sensor.detector
    noise_model = NoiseModel.from_detector(det)
    shape = (rig.sun_sensor.resolution_px[1], rig.sun_sensor.resolution_px[0])
    W = renderer.window_px
    measured = []  # per frame in the field: (dn, origin, spots, index of the measured spot or None, frame or None)
    for j, i in enumerate(field_idx):
        fseed = frame_seeds[j]
        fr = None
        if on_frame is not None:
            import warnings

            pose = {k: float(v[i]) for k, v in poses.items()}
            win = renderer.window(S[i], tiles[j], seed=fseed, batched_tile_px=len(tiles[j]))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fr = scene.frame(pose, win, seed=fseed, noiseless=noiseless, truth_points=200_000, full_frame=False)
            dn, origin = fr.dn, fr.origin_uv
        else:
            origin_w = renderer.window_origin_for(c[i])
            photons = np.zeros((W, W))
            t = len(tiles[j])
            photons[W // 2 - t // 2:W // 2 - t // 2 + t, W // 2 - t // 2:W // 2 - t // 2 + t] = tiles[j]
            photons, origin = detector_part(photons, origin_w, shape)
            dn = apply_detector(photons, det, seed=fseed, noiseless=noiseless, origin_uv=origin,
                                detector_shape=shape).dn
        spots = measure_frame(dn, noise_model, method="scurve" if centroider == "model" else centroider,
                              saturation_dn=det.saturation_dn, threshold_dn=0.5 * det.code_step_dn if noiseless else None,
                              origin_uv=origin, detector_shape=shape)
        measured.append((dn, origin, spots, single_spot(spots), fr))
        if progress:
            progress(1)
    if centroider == "model":  # the forward-model fits, in place of each frame's brightest spot
        ks = model_centroids(rig, [(dn, o, sp) for dn, o, sp, _, _ in measured],
                             {ax: r[field_idx] for ax, r in read.items()}, shape)
        measured = [(dn, o, sp, k, fr) for (dn, o, sp, _, fr), k in zip(measured, ks)]
    keep, uv, sig, wins = [], [], [], []
    rejected = 0
    for i, (dn, origin, spots, k, fr) in zip(field_idx, measured):
        if on_frame is not None:
            on_frame(fr, spots, k, {ax: float(r[i]) for ax, r in read.items()}, int(i))
        if k is None:
            rejected += 1
        else:
            keep.append(int(i))
            if keep_windows:
                wins.append((np.asarray(dn), np.asarray(origin)))
            uv.append([float(spots.u[k]), float(spots.v[k])])
            sig.append([float(spots.sigma_u[k]), float(spots.sigma_v[k])])
    keep = np.array(keep, dtype=int)
    readings = TurntableReading({ax: r[keep] for ax, r in read.items()})
    obs = SweepObservation(readings, np.array(uv).reshape(-1, 2), len(field_idx), rejected, time.perf_counter() - t0,
                           np.array(sig).reshape(-1, 2), wins if keep_windows else None)
    truth = SweepTruth(TruePose({k: v[keep] for k, v in poses.items()}), c[keep].reshape(-1, 2), S[keep],
                       cam, scene.full_angle_rad, renderer.response)
    return obs, truth


def calibrate_from_sweep(rig: CubeMirrorRig, sweep: SweepObservation, axis_order: str | None = None) -> SunCalibration:
    from rigsim.procedures.cube_mirror.pipeline import default_axis_order, fit_sun_sensor

    return fit_sun_sensor(rig, sweep.readings, sweep.uv, axis_order or default_axis_order(rig), sigma_uv=sweep.sigma_uv)
