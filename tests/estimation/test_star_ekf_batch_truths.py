"""run_ekf_batch against the textbook Kalman filter written here (gain K = P Hᵀ S⁻¹ by numpy's solve,
P⁺ = (I − K H) P, NIS = νᵀ S⁻¹ ν, with H by central finite differences of the catalogue-angle model written
with numpy), on the paths the comparison with run_ekf did not reach: exactly known centroids (S singular:
the jittered fallback), the improved ADS model's batched Jacobian, and the argument checks."""

import numpy as np
import pytest
from star_frames import noisy_frames, true_theta
from textbook_ekf import textbook_ekf

from rigsim.estimation.star_calibration import FrameObs, run_ekf
from rigsim.estimation.star_ekf_batch import run_ekf_batch


@pytest.fixture(scope="module")
def frames(star_rig, star_sky):
    return noisy_frames(star_rig, star_sky, 0.05, np.random.default_rng(31), 4, 8, shuffle=True, spread_sigma=True)


@pytest.mark.parametrize("weighting", ["propagated", "diagonal", "unweighted"])
def test_improved_ads_batch_update_is_the_textbook_update(star_rig, frames, weighting):
    """The improved ADS model's own batched Jacobians (H through the chain rule, G per star) against the textbook
    update with H by finite differences: one frame (the model's bias, ~0.03 against σ ≈ 2e-5, throws a filter far
    off after it, where differences of rounding grow), from two starts (and two focal lengths) at once."""
    th = true_theta(star_rig)
    starts = np.array([th + [0.0, 0.3, -0.2, 0, 0], th + [2.0, -0.2, 0.3, 0, 0]])
    got = run_ekf_batch(frames[:1], starts, model="ads_improved", prior_sigma=[1.0, 2.0], weighting=weighting,
                        process_sigma=0.5)
    for r, t0 in zip(got, starts, strict=True):
        t_th, t_P, t_hist, t_nis = textbook_ekf(frames[:1], t0, [1, 2], [1.0, 2.0], 0.5, "ads_improved", weighting, fd_jacobian=True)
        step = t_hist[1] - t_hist[0]
        np.testing.assert_allclose(r.history_x[1] - r.history_x[0], step, rtol=1e-6)
        np.testing.assert_allclose(r.P, t_P, rtol=1e-5, atol=1e-5 * np.abs(t_P).max())
        np.testing.assert_allclose(r.nis, t_nis, rtol=1e-5)


def test_exactly_known_centroids_take_the_jittered_update(star_rig, frames):
    """σ = 0 for every centroid: R = 0 and S = H P Hᵀ has rank 2 < M, so a batched Cholesky fails and each filter
    takes the single filter's jittered update: the same as run_ekf (the textbook gain needs S⁻¹ and has none)."""
    exact = [FrameObs(fo.uv, np.zeros_like(fo.sigma_uv), fo.dirs_icrs, fo.flux) for fo in frames]
    th = true_theta(star_rig)
    starts = np.array([th + [0, 1.0, -1.0, 0, 0], th + [0, -0.5, 0.5, 0, 0]])
    got = run_ekf_batch(exact, starts)
    for r, t0 in zip(got, starts, strict=True):
        ref = run_ekf(exact, t0)
        np.testing.assert_allclose(r.history_x, ref.history_x, rtol=0, atol=1e-5)
        np.testing.assert_allclose(r.P, ref.P, rtol=1e-3, atol=1e-3 * np.abs(ref.P).max())
        np.testing.assert_allclose(r.nis, ref.nis, rtol=1e-4)


def test_bad_arguments(star_rig, frames):
    th = true_theta(star_rig)
    for kw, word in (({"model": "adx"}, "model"), ({"model": "a"}, "model"), ({"equations": "every"}, "equations"),
                     ({"equations": "a"}, "equations"), ({"weighting": "a"}, "weighting")):
        with pytest.raises(ValueError, match=word):
            run_ekf_batch(frames, [th], **kw)
