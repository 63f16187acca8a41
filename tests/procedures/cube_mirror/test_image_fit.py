"""The image-based sun-sensor calibration (every frame's pixels jointly) against a synthetic sweep
whose frames come from a second method: the disk's directions through the rig's true camera,
histogrammed on 1/8 px (not the model's quadrature and grid), with the detector's noise. The true
R(sun←mount) and intrinsics are known exactly; the nominal turntable is the true one here."""

import math

import numpy as np
import pytest

from rigsim.estimation.sun_calibration import sweep_poses
from rigsim.frames import small_angle_error
from rigsim.imaging import NoiseModel
from rigsim.imaging.frame_spots import measure_frame
from rigsim.optics.sun_disk import disk_directions
from rigsim.procedures.cube_mirror.image_fit import fit_sweep_images
from rigsim.procedures.cube_mirror.pipeline import default_axis_order, fit_sun_sensor
from rigsim.procedures.cube_mirror.spot_fit import model_centroids
from rigsim.rig import load_rig
from rigsim.rig.turntable import NOMINAL_D, TurntableModel, TurntableReading

RIG = load_rig("sun_sensor_2axis_diaphragm")
pytestmark = pytest.mark.slow  # 40 frames from a 200 000-point quadrature each and a joint fit: ~10 s


@pytest.fixture(scope="module")
def sweep():
    ss = RIG.sun_sensor
    cam = ss.camera()
    A = math.radians(RIG.sun_simulator.collimation_full_angle_arcmin / 60.0)
    order = default_axis_order(RIG)
    tt = TurntableModel.nominal(list(order))
    poses = sweep_poses(["X", "Y"], 50.0, 12.5, {})
    R_sm = ss.R_sun_from_mount.matrix()
    det = ss.detector
    noise = NoiseModel.from_detector(det)
    rng = np.random.default_rng(4)
    shape = (ss.resolution_px[1], ss.resolution_px[0])
    frames, keep, W, m = [], [], 32, 8
    for i in range(len(poses["X"])):
        pose = {k: float(v[i]) for k, v in poses.items()}
        s = R_sm @ (tt.R_rot_from_mount(pose).T @ NOMINAL_D)
        c = cam.project_valid(s[None, :])[0][0]
        if not cam.on_detector(c[None, :], margin_px=20.0)[0]:
            continue
        o = np.floor(c + 0.5).astype(int) - W // 2
        d = disk_directions(s, A, 200_000)
        uv, _ = cam.project_valid(d)
        img, _, _ = np.histogram2d((uv[:, 1] - o[1] + 0.5) * m, (uv[:, 0] - o[0] + 0.5) * m, bins=[W * m] * 2,
                                   range=[[0, W * m]] * 2, weights=d[:, 2] / d[:, 2].sum())
        mu_e = 1.2e5 * s[2] ** 4 * img.reshape(W, m, W, m).sum(axis=(1, 3))
        dn = np.round((rng.poisson(mu_e) + rng.normal(0, det.read_noise_e, mu_e.shape)) * noise.gain_dn_per_e
                      + noise.offset_dn)
        frames.append((dn, o, measure_frame(dn, noise, method="scurve", saturation_dn=det.saturation_dn,
                                            origin_uv=o, detector_shape=shape)))
        keep.append(i)
    readings = {k: v[keep] for k, v in poses.items()}
    ks = model_centroids(RIG, frames, readings, shape, order)
    assert all(k == 0 for k in ks)
    uv = np.array([[sp.u[0], sp.v[0]] for _, _, sp in frames])
    sig = np.array([[sp.sigma_u[0], sp.sigma_v[0]] for _, _, sp in frames])
    start = fit_sun_sensor(RIG, TurntableReading(readings), uv, order, sigma_uv=sig)
    im = fit_sweep_images(RIG, [(dn, o) for dn, o, _ in frames], readings, start, uv, order)
    return start, im, R_sm, cam


def test_the_image_fit_recovers_the_truth_within_its_sigma(sweep):
    """Both routes land within 4σ of the true R(sun←mount) and focal length; the pixels' χ²/dof is 1
    within 2 % (the frames hold nothing the model lacks); the image fit's σ are no larger than the
    centroid-then-fit route's (it uses each frame's whole Fisher information, u–v correlations
    included)."""
    start, im, R_sm, cam = sweep
    for c in (start, im.calibration):
        e = small_angle_error(c.R_sun_from_rot, R_sm)
        sd = np.sqrt(np.diag(c.rotation_covariance_rad2))
        assert np.all(np.abs(e) < 4 * sd + 1e-7), (e / sd)
        assert abs(c.params[0] - cam.fx) < 4 * math.sqrt(c.covariance[0, 0]) + 1e-3
    assert im.fit.chi2_dof == pytest.approx(1.0, abs=0.02)
    assert np.all(np.sqrt(np.diag(im.calibration.rotation_covariance_rad2))
                  <= 1.05 * np.sqrt(np.diag(start.rotation_covariance_rad2)))
    assert im.iterations < 15  # converged before the cap (8 steps of Gauss–Newton here: the guarded start fits 77 of 79 frames)
