"""run_ekf_batch: several seed-004 EKFs at once, each equal to run_ekf on its own frames.

Both run the same filter; only the order of floating-point sums differs, so the estimates agree to
rounding amplified by the filter (seen ≤ 2e-8 px), far below the filters' own σ (~0.01-0.1 px)."""

import itertools

import numpy as np
import pytest
from star_frames import noisy_frames, true_theta

from rigsim.estimation.star_calibration import EQUATIONS, WEIGHTINGS, FrameObs, run_ekf
from rigsim.estimation.star_ekf_batch import run_ekf_batch

THETA_TOL_PX = 1e-6     # 4 orders below the filters' σ
SIGMA_RTOL = 1e-8


@pytest.fixture(scope="module")
def sequences(star_rig, star_sky):
    """Two trials: shuffled stars with spread σ, and one whose third frame has fewer stars (own batch)."""
    a = noisy_frames(star_rig, star_sky, 0.05, np.random.default_rng(1), 6, 10, shuffle=True, spread_sigma=True)
    b = noisy_frames(star_rig, star_sky, 0.08, np.random.default_rng(2), 6, 10)
    b[2] = FrameObs(b[2].uv[:7], b[2].sigma_uv[:7], b[2].dirs_icrs[:7], b[2].flux[:7])
    return a, b


def _starts(star_rig):
    th = true_theta(star_rig)
    return [th + [1.5, -4.0, 3.0, 0.0, 0.0], th + [-2.0, 2.0, -1.0, 0.0, 0.0]]


def _assert_same(r, ref):
    np.testing.assert_allclose(r.theta, ref.theta, rtol=0, atol=THETA_TOL_PX)
    np.testing.assert_allclose(r.sigma, ref.sigma, rtol=SIGMA_RTOL)
    np.testing.assert_allclose(r.history_x, ref.history_x, rtol=0, atol=THETA_TOL_PX)
    np.testing.assert_allclose(r.nis, ref.nis, rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(r.n_eq, ref.n_eq)
    np.testing.assert_array_equal(r.dof, ref.dof)


@pytest.mark.parametrize(("equations", "weighting"), list(itertools.product(EQUATIONS, WEIGHTINGS)))
@pytest.mark.parametrize("model", ["ad", "ads"])
def test_each_filter_of_a_batch_is_run_ekf(star_rig, sequences, equations, weighting, model):
    starts = _starts(star_rig)
    seqs = [s for s in sequences for _ in starts]
    th0s = np.array([t for _ in sequences for t in starts])
    for estimate, ps in ((("u0", "v0"), [8.0, 8.0]), (("f", "u0", "v0"), [5.0, 8.0, 8.0])):
        got = run_ekf_batch(seqs, th0s, model=model, estimate=estimate, prior_sigma=ps, weighting=weighting,
                            equations=equations, process_sigma=0.01, cache={})
        assert len(got) == len(seqs)
        for fr, th, r in zip(seqs, th0s, got):
            ref = run_ekf(fr, th, model=model, estimate=estimate, prior_sigma=ps, weighting=weighting,
                          equations=equations, process_sigma=0.01)
            _assert_same(r, ref)


def test_improved_ads_and_shared_frames(star_rig, sequences):
    """One frame sequence for every filter (the focal-length cases of a trial) is the same as passing it per
    filter; the improved ADS model too (converging here: a small start offset)."""
    a = sequences[0]
    th = true_theta(star_rig)
    th0s = np.array([th + [0.0, 0.5, -0.5, 0, 0], th + [1.0, 0.5, -0.5, 0, 0]])
    for model in ("ads", "ads_improved"):
        shared = run_ekf_batch(a, th0s, model=model)
        per = run_ekf_batch([a, a], th0s, model=model)
        for s, p, t in zip(shared, per, th0s):
            ref = run_ekf(a, t, model=model)
            _assert_same(s, ref)
            _assert_same(p, ref)


def test_frames_with_too_few_stars_are_skipped_like_run_ekf(star_rig, sequences):
    a = list(sequences[0])
    a[1] = FrameObs(a[1].uv[:3], a[1].sigma_uv[:3], a[1].dirs_icrs[:3], a[1].flux[:3])
    th = true_theta(star_rig)
    (r,) = run_ekf_batch(a, [th])
    ref = run_ekf(a, th)
    _assert_same(r, ref)
    assert r.n_eq[1] == 0 and np.isnan(r.nis[1])


def test_bad_arguments(star_rig, sequences):
    th = true_theta(star_rig)
    with pytest.raises(ValueError, match="frame sequences"):
        run_ekf_batch([sequences[0]], [th, th])
    with pytest.raises(ValueError, match="weighting"):
        run_ekf_batch(sequences[0], [th], weighting="robust")
