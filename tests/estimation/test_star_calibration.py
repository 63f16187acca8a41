"""AD / ADS models, EKF, batch LSQ and observability against truth."""

import numpy as np
import pytest
from star_frames import noisy_frames, true_theta

from rigsim.estimation.observability import observability
from rigsim.estimation.star_calibration import (
    MODELS,
    THETA_NAMES,
    FrameObs,
    batch_lsq,
    frame_system,
    pair_sets,
    run_ekf,
)
from rigsim.procedures.star.study import CentroidNoise, random_slew, simulate_frames


def _truth(star_rig):
    return true_theta(star_rig)


def _frames(star_rig, star_sky, sigma, rng, n=None):
    return noisy_frames(star_rig, star_sky, sigma, rng, n)


def test_jacobians_match_finite_differences(star_rig, star_sky):
    fo = _frames(star_rig, star_sky, 0.05, np.random.default_rng(0), 1)[0]
    th = _truth(star_rig)
    for model in MODELS:
        s0 = frame_system(fo, th, model)
        for p in range(5):
            e = np.zeros(5)
            e[p] = 1e-3 if p < 3 else 1e-6
            fd = (frame_system(fo, th + e, model).h - frame_system(fo, th - e, model).h) / (2 * e[p])
            # central differences: truncation ~ (step)² h''' ≪ 1e-5 of the derivative
            assert np.abs(fd - s0.H[:, p]).max() <= 1e-5 * np.abs(fd).max(), (model, THETA_NAMES[p])
        uv = fo.uv.copy()
        uv[2, 1] += 1e-4
        fo2 = FrameObs(uv, fo.sigma_uv, fo.dirs_icrs)
        fd = (frame_system(fo2, th, model, sets=pair_sets(fo.uv)).h - s0.h) / 1e-4
        assert np.abs(fd - s0.G[:, 5]).max() <= 1e-4 * np.abs(s0.G[:, 5]).max()


def test_models_at_truth_noise_free(star_rig, star_sky):
    """Exact models vanish at the truth (to the Newton undistortion, 1e-12); eq 12's approximation
    leaves ≈ (r_k² − r_i²)/(2f²), up to ~0.03 for this 20° field: a bias of the model itself."""
    fo = _frames(star_rig, star_sky, 0.0, np.random.default_rng(0), 1)[0]
    th = _truth(star_rig)
    for model in ("ad", "ads"):
        s = frame_system(fo, th, model)
        assert np.abs(s.z - s.h).max() < 1e-11
        assert s.R.shape[0] == (2 * len(fo) - 3 if model == "ad" else 2 * len(fo) - 4)
    s = frame_system(fo, th, "ads_improved")
    assert np.abs(s.z - s.h).max() > 1e-3


def test_ekf_and_batch_recover_truth(star_rig, star_sky):
    th = _truth(star_rig)
    fr = _frames(star_rig, star_sky, 0.0, np.random.default_rng(0))
    prior = th.copy()
    prior[1:3] = star_rig.nominal_rig().sensor.principal_point_px
    r = run_ekf(fr, prior, model="ad")  # noise-free: converges to the truth (σ floor 1e-4 px)
    assert np.abs(r.x - th[1:3]).max() < 1e-3
    start = np.array([th[0] + 3.0, *star_rig.nominal_rig().sensor.principal_point_px, 0.0, 0.0])
    b = batch_lsq(fr, start)
    # noise-free: the batch solution is the truth to the solver tolerance (1e-4 px, 1e-6 in k)
    assert np.all(np.abs(b.theta - th) < [1e-4, 1e-4, 1e-4, 1e-6, 1e-5]), b.theta - th
    # noisy: within 4σ of the truth, and the filter's σ matches the batch σ (same information)
    fr = _frames(star_rig, star_sky, 0.05, np.random.default_rng(1))
    r = run_ekf(fr, prior, model="ad")
    b = batch_lsq(fr, prior, estimate=("u0", "v0"))
    assert np.all(np.abs(r.x - th[1:3]) < 4 * r.sigma)
    np.testing.assert_allclose(r.sigma, b.sigma, rtol=0.05)
    o = observability(fr, th, model="ad")
    # whitened SVD: 1/σ_i are the semi-axes of the LSQ error ellipse = sqrt(eig(cov))
    np.testing.assert_allclose(np.sort(1 / o.sv_whitened), np.sort(np.sqrt(np.linalg.eigvalsh(b.cov))), rtol=0.02)


@pytest.mark.slow
def test_batch_covariance_matches_monte_carlo(star_rig, star_sky):
    """mrcal-style check: the batch covariance predicts the scatter of 60 noisy runs (χ² test on the
    5 normalised errors: mean of e·C⁻¹·e over runs within 5 ± 3·sqrt(10/60))."""
    noise = CentroidNoise.from_rig(star_rig, background_photons_per_px=star_sky.background_photons_per_px)
    th = _truth(star_rig)
    rng = np.random.default_rng(7)
    seq = random_slew(star_rig, rng)
    m = []
    for _ in range(60):
        fr = simulate_frames(star_sky, seq, noise, rng, 20)
        b = batch_lsq(fr, np.array([th[0] + 3, *star_rig.nominal_rig().sensor.principal_point_px, 0, 0]))
        e = b.theta - th
        m.append(e @ np.linalg.solve(b.cov, e))
    assert abs(np.mean(m) - 5.0) < 3 * np.sqrt(10 / 60)


def test_batch_recovers_a_camera_that_opencv_projected_with_tangential_terms(star_rig, star_sky):
    """A known answer computed another way: the rig's sky through a camera with tangential distortion, projected
    by OpenCV's cv2.projectPoints (not rigsim's camera, which the estimator shares), noise-free. The batch must
    return that camera's θ: a tangential term applied to the wrong axis in rigsim's model (which simulation and
    fit would share, passing every round trip) moves the fitted principal point by ~3 px."""
    import cv2

    from rigsim.optics import attitude as att

    th = np.array([2886.7, 514.3, 508.6, -0.06, 0.10])
    p12 = (4e-4, -3e-4)  # 0.3 px at the detector's corner
    K = np.array([[th[0], 0.0, th[1]], [0.0, th[0], th[2]], [0.0, 0.0, 1.0]])
    dist = np.array([th[3], th[4], *p12, 0.0])
    seq = att.from_rig(star_rig.sequence)
    frames = []
    for k in range(0, len(seq), max(1, len(seq) // 12)):
        R = seq.R_cam_from_icrs[k]
        tr = star_sky.field(R)
        d = tr.dirs_icrs @ R.T
        uv, _ = cv2.projectPoints(d.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, dist)
        uv = uv.reshape(-1, 2)
        inside = np.flatnonzero((uv >= 5).all(1) & (uv[:, 0] < 1019) & (uv[:, 1] < 1019) & (d[:, 2] > 0))
        idx = inside[np.argsort(-tr.photons[inside])][:20]
        frames.append(FrameObs(uv[idx], np.full((idx.size, 2), 1e-4), tr.dirs_icrs[idx], tr.photons[idx]))
    start = np.array([th[0] + 3.0, 511.5, 511.5, 0.0, 0.0])
    b = batch_lsq(frames, start, p12=p12)
    assert np.all(np.abs(b.theta - th) < [1e-3, 1e-3, 1e-3, 1e-6, 1e-5]), b.theta - th
