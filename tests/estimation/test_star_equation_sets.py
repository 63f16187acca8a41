"""Equation sets (framework | all | chain) × weightings (propagated | diagonal | unweighted) of the
seed-004 AD/ADS estimators, each against an independent derivation."""

import itertools

import numpy as np
import pytest
from star_frames import noisy_frames, true_theta

from rigsim.estimation.star_calibration import (
    EQUATIONS,
    WEIGHTINGS,
    batch_lsq,
    equation_sets,
    frame_system,
    run_ekf,
)
from rigsim.optics.camera import PinholeBrown


def _truth(star_rig):
    return true_theta(star_rig)


def _frames(star_rig, star_sky, sigma, rng, n=None, n_stars=20):
    # shuffled so that the stored order is not the brightness order (chain must sort by flux)
    return noisy_frames(star_rig, star_sky, sigma, rng, n, n_stars, shuffle=True, spread_sigma=True, sigma_floor=1e-6)


def _directions(star_rig, fo, th):
    """Unit vectors of the measured stars through OpenCV's undistortion (an independent path)."""
    W, H = star_rig.sensor.resolution_px
    cam = PinholeBrown(th[0], th[0], th[1], th[2], th[3], th[4], 0.0, 0.0, 0.0, W, H)
    b = cam.unproject(fo.uv)
    return b / np.linalg.norm(b, axis=1, keepdims=True)


def test_all_and_chain_sets_against_direct_loops(star_rig, star_sky):
    fo = _frames(star_rig, star_sky, 0.05, np.random.default_rng(0), 1)[0]
    n = len(fo)
    th = _truth(star_rig)
    w = _directions(star_rig, fo, th)
    # all: every pair i < j, every triplet (i, j, k) with j the middle, i < k, both ≠ j
    pairs, trip = equation_sets(fo.uv, "all")
    assert len(pairs) == n * (n - 1) // 2 and len(trip) == n * (n - 1) * (n - 2) // 2
    assert {tuple(p) for p in pairs} == set(itertools.combinations(range(n), 2))
    assert {tuple(t) for t in trip} == {(i, j, k) for j in range(n) for i, k in itertools.combinations(range(n), 2)
                                        if j not in (i, k)}
    s = frame_system(fo, th, "ad", equations="all")
    h = [w[i] @ w[j] for i, j in pairs]
    z = [fo.dirs_icrs[i] @ fo.dirs_icrs[j] for i, j in pairs]
    np.testing.assert_allclose(s.h, h, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s.z, z, rtol=0, atol=1e-15)
    s = frame_system(fo, th, "ads", equations="all")
    np.testing.assert_allclose(s.h, [w[i] @ w[j] - w[j] @ w[k] for i, j, k in trip], rtol=0, atol=1e-12)
    # chain: consecutive stars in decreasing flux
    o = sorted(range(n), key=lambda i: -fo.flux[i])
    s = frame_system(fo, th, "ad", equations="chain")
    assert s.h.size == n - 1
    np.testing.assert_allclose(s.h, [w[o[m]] @ w[o[m + 1]] for m in range(n - 1)], rtol=0, atol=1e-12)
    s = frame_system(fo, th, "ads", equations="chain")
    assert s.h.size == n - 2
    np.testing.assert_allclose(s.h, [w[o[m]] @ w[o[m + 1]] - w[o[m + 1]] @ w[o[m + 2]] for m in range(n - 2)],
                               rtol=0, atol=1e-12)
    # framework stays rigsim's 2N − 3 / 2N − 4
    assert frame_system(fo, th, "ad").h.size == 2 * n - 3 and frame_system(fo, th, "ads").h.size == 2 * n - 4
    with pytest.raises(ValueError, match="equations"):
        frame_system(fo, th, "ad", equations="every")
    with pytest.raises(ValueError, match="weighting"):
        frame_system(fo, th, "ad", weighting="equal")


def test_weightings_against_the_propagated_covariance(star_rig, star_sky):
    fo = _frames(star_rig, star_sky, 0.05, np.random.default_rng(1), 1, n_stars=12)[0]
    th = _truth(star_rig)
    for eq in EQUATIONS:
        for model in ("ad", "ads"):
            s = frame_system(fo, th, model, "propagated", equations=eq)
            # propagated R = G Σ Gᵀ by an explicit loop over the centroids (the 1e-9 floor aside)
            var = fo.sigma_uv.reshape(-1) ** 2
            R = sum(var[q] * np.outer(s.G[:, q], s.G[:, q]) for q in range(var.size))
            np.testing.assert_allclose(s.R - np.eye(len(R)) * 1e-9 * np.mean(np.diag(R)), R, rtol=1e-12,
                                       atol=1e-12 * R.max())
            d = frame_system(fo, th, model, "diagonal", equations=eq).R
            np.testing.assert_array_equal(d, np.diag(np.diag(d)))
            np.testing.assert_allclose(np.diag(d), np.diag(R), rtol=1e-12)
            u = frame_system(fo, th, model, "unweighted", equations=eq).R
            sigma2 = np.mean(np.diag(R))
            assert np.all(u[~np.eye(len(u), dtype=bool)] == 0.0)
            np.testing.assert_allclose(np.diag(u), sigma2, rtol=1e-12)
            assert np.ptp(np.diag(u)) == 0.0  # exactly σ²I: one scalar


def test_rank_deficient_all_propagated_is_the_framework_information(star_rig, star_sky):
    """All pairs carry 2N − 3 independent angles: the propagated R of all pairs has that rank; the
    EKF projects onto its range, so its update has 2N − 3 dimensions, a NIS per dimension ≈ 1,
    and the same estimate as the AD framework (same information) to ≪ its σ. All triplets span
    the same 2N − 3 dimensions (the framework triplets only 2N − 4): all-triplet ADS with
    propagated weights is the AD framework estimator too."""
    fr = _frames(star_rig, star_sky, 0.05, np.random.default_rng(2))
    th = _truth(star_rig)
    prior = th.copy()
    prior[1:3] = star_rig.nominal_rig().sensor.principal_point_px
    n = len(fr[0])
    s = frame_system(fr[0], th, "ad", equations="all")
    ev = np.linalg.eigvalsh(s.R)
    assert np.sum(ev > 1e-6 * ev[-1]) == 2 * n - 3
    rf = run_ekf(fr, prior, model="ad")
    assert np.all(run_ekf(fr, prior, model="ads").dof == 2 * n - 4)
    for model in ("ad", "ads"):
        ra = run_ekf(fr, prior, model=model, equations="all")
        assert np.all(ra.dof == 2 * n - 3) and np.all(ra.n_eq > 2 * n)
        assert 0.7 < np.mean(ra.nis / ra.dof) < 1.3
        assert np.all(np.abs(ra.x - rf.x) < 0.01 * rf.sigma), (ra.x - rf.x) / rf.sigma
        np.testing.assert_allclose(ra.sigma, rf.sigma, rtol=0.01)


def test_every_estimator_converges_noise_free(star_rig, star_sky):
    """Noise-free centroids (σ = 1e-6 px): batch least squares from the nominal principal point
    (4 px away) and the EKF from 0.01 px away reach the truth to < 1e-6 px for every equation set
    × weighting × model. (An EKF linearises once per frame: from 4 px away its first-frame
    linearisation error, ~(4 px)²·h'', is only averaged down over the frames, not removed.)"""
    th = _truth(star_rig)
    fr = _frames(star_rig, star_sky, 0.0, np.random.default_rng(3), 6)
    start = th.copy()
    start[1:3] = star_rig.nominal_rig().sensor.principal_point_px
    near = th.copy()
    near[1:3] += [0.01, -0.01]
    for eq in EQUATIONS:
        for w in WEIGHTINGS:
            for model in ("ad", "ads"):
                b = batch_lsq(fr, start, estimate=("u0", "v0"), model=model, weighting=w, equations=eq)
                assert np.abs(b.theta - th).max() < 1e-6, (eq, w, model, b.theta - th)
                r = run_ekf(fr, near, model=model, weighting=w, equations=eq, prior_sigma=[1.0, 1.0])
                assert np.abs(r.x - th[1:3]).max() < 1e-6, (eq, w, model, r.x - th[1:3])
