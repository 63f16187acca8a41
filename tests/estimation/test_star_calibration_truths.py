"""The seed-004 EKF and batch least squares against second derivations written here: the textbook Kalman
filter (gain K = P Hᵀ S⁻¹ by numpy's solve, P⁺ = (I − K H) P), the weighted least-squares normal equations with
the Jacobian by central finite differences, χ² and residuals by hand; the frame selection (brightest stars,
skipped frames) by hand."""

import numpy as np
import pytest
from star_frames import noisy_frames, true_theta
from textbook_ekf import textbook_ekf

from rigsim.estimation.star_calibration import (
    THETA_NAMES,
    FrameObs,
    _cho,
    batch_lsq,
    equation_sets,
    frame_system,
    run_ekf,
)


@pytest.fixture(scope="module")
def frames(star_rig, star_sky):
    fr = noisy_frames(star_rig, star_sky, 0.05, np.random.default_rng(21), 4, 9, shuffle=True, spread_sigma=True)
    # a frame of 3 stars between them: skipped by the filter and by the batch
    fr.insert(2, FrameObs(fr[1].uv[:3], fr[1].sigma_uv[:3], fr[1].dirs_icrs[:3], fr[1].flux[:3]))
    return fr


@pytest.mark.parametrize("model", ["ad", "ads"])
@pytest.mark.parametrize("weighting", ["propagated", "diagonal", "unweighted"])
def test_ekf_is_the_textbook_kalman_filter(star_rig, frames, model, weighting):
    th = true_theta(star_rig)
    start = th + [2.0, -1.5, 1.0, 0.0, 0.0]
    names = ("f", "u0", "v0")
    est = [THETA_NAMES.index(e) for e in names]
    ps, q = [4.0, 3.0, 3.0], 0.2
    r = run_ekf(frames, start, model=model, estimate=names, prior_sigma=ps, process_sigma=q, weighting=weighting)
    t_th, t_P, t_hist, t_nis = textbook_ekf(frames, start, est, ps, q, model, weighting)
    np.testing.assert_allclose(r.history_x, t_hist, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.x, t_th[est], rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.theta, t_th, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.P, t_P, rtol=1e-7, atol=1e-7 * np.abs(t_P).max())
    np.testing.assert_allclose(r.sigma, np.sqrt(np.diag(t_P)), rtol=1e-7)
    np.testing.assert_allclose(r.history_sigma[-1], np.sqrt(np.diag(t_P)), rtol=1e-7)
    np.testing.assert_allclose(r.history_sigma[0], ps, rtol=1e-15)
    np.testing.assert_allclose(r.nis, t_nis, rtol=1e-7)
    m = [0 if len(fo) < 4 else (2 * len(fo) - 3 if model == "ad" else 2 * len(fo) - 4) for fo in frames]
    np.testing.assert_array_equal(r.n_eq, m)
    np.testing.assert_array_equal(r.dof, m)
    assert r.names == names and r.model == model


def test_ekf_default_prior_is_10_px(star_rig, frames):
    """Without ``prior_sigma`` the prior is 10 (px) per estimated entry: the textbook filter from P = 100·I."""
    th = true_theta(star_rig)
    start = th + [0.0, 1.0, -1.0, 0.0, 0.0]
    r = run_ekf(frames, start)
    t_th, t_P, t_hist, _ = textbook_ekf(frames, start, [1, 2], [10.0, 10.0], 0.0, "ad", "propagated")
    np.testing.assert_allclose(r.history_sigma[0], [10.0, 10.0], rtol=1e-15)
    np.testing.assert_allclose(r.history_x, t_hist, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.P, t_P, rtol=1e-7, atol=1e-7 * np.abs(t_P).max())


def test_ekf_on_the_brightest_stars_is_the_filter_on_frames_cut_by_hand(star_rig, frames):
    th = true_theta(star_rig)
    start = th + [0.0, 1.0, -1.0, 0.0, 0.0]
    cut = []
    for fo in frames:
        o = sorted(range(len(fo)), key=lambda i: -fo.flux[i])[:6]
        cut.append(FrameObs(fo.uv[o], fo.sigma_uv[o], fo.dirs_icrs[o], fo.flux[o]))
    r = run_ekf(frames, start, max_stars=6)
    t_th, t_P, t_hist, t_nis = textbook_ekf(cut, start, [1, 2], [10.0, 10.0], 0.0, "ad", "propagated")
    np.testing.assert_allclose(r.history_x, t_hist, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.nis, t_nis, rtol=1e-7)
    # brightest(n): the n largest fluxes; without fluxes the n smallest σ; n ≥ the count: the frame itself
    fo = frames[0]
    b = fo.brightest(4)
    np.testing.assert_array_equal(np.sort(b.flux), np.sort(fo.flux)[-4:])
    assert fo.brightest(len(fo)) is fo and fo.brightest(len(fo) + 1) is fo
    nf = FrameObs(fo.uv, fo.sigma_uv, fo.dirs_icrs)
    small = np.argsort(np.hypot(fo.sigma_uv[:, 0], fo.sigma_uv[:, 1]))[:4]
    np.testing.assert_array_equal(np.sort(nf.brightest(4).uv[:, 0]), np.sort(fo.uv[small, 0]))
    assert nf.brightest(4).flux is None and len(fo.brightest(len(fo) - 1)) == len(fo) - 1
    # a frame is shared by many filters (and memoised by its identity): it cannot be changed
    import dataclasses

    with pytest.raises(dataclasses.FrozenInstanceError):
        fo.uv = fo.uv * 2


def test_ekf_and_batch_refuse_unknown_settings(star_rig, frames):
    th = true_theta(star_rig)
    for kw, word in (({"model": "adx"}, "model"), ({"model": "a"}, "model"), ({"equations": "every"}, "equations"),
                     ({"equations": "a"}, "equations")):
        with pytest.raises(ValueError, match=word):
            run_ekf(frames, th, **kw)
    with pytest.raises(TypeError):                 # the options are keyword-only
        batch_lsq(frames, th, ("u0", "v0"))
    with pytest.raises(TypeError):
        run_ekf(frames, th, "ads")
    for model in ("adz", "a", "ac"):               # names on both sides of "ad" in string order
        with pytest.raises(ValueError, match="model"):
            frame_system(frames[0], th, model)


def test_batch_is_the_weighted_least_squares_solution(star_rig, frames):
    """At the batch solution: the normal equations' gradient Σ Hᵀ R⁻¹ (z − h) vanishes, with H by central finite
    differences of h; the covariance is (Σ Hᵀ R⁻¹ H)⁻¹; χ² = Σ (z − h)ᵀ R⁻¹ (z − h) over the equations of the
    frames with ≥ 4 stars; the residuals are z − h per frame."""
    th = true_theta(star_rig)
    start = th + [3.0, -2.0, 2.0, 0.0, 0.0]
    for weighting in ("propagated", "diagonal"):
        b = batch_lsq(frames, start, weighting=weighting)
        used = [fo for fo in frames if len(fo) >= 4]
        info, grad, chi2, n = np.zeros((5, 5)), np.zeros(5), 0.0, 0
        for fo, res in zip(used, b.residuals, strict=True):
            s = frame_system(fo, b.theta, "ad", weighting)
            H = np.empty((s.h.size, 5))
            for p in range(5):
                e = np.zeros(5)
                e[p] = 1e-3 if p < 3 else 1e-6
                H[:, p] = (frame_system(fo, b.theta + e, "ad").h - frame_system(fo, b.theta - e, "ad").h) / (2 * e[p])
            Ri = np.linalg.inv(s.R)
            r = s.z - s.h
            np.testing.assert_allclose(res, r, rtol=0, atol=1e-15)
            info += H.T @ Ri @ H
            grad += H.T @ Ri @ r
            chi2 += r @ Ri @ r
            n += r.size
        cov = np.linalg.inv(info)
        step = cov @ grad                     # the Gauss-Newton step still to go: none, against σ
        assert np.all(np.abs(step) < 1e-3 * np.sqrt(np.diag(cov))), step / np.sqrt(np.diag(cov))
        # to 1e-3 of σᵢσⱼ (R is whitened at the previous pass's solution, H here by finite differences)
        sd = np.sqrt(np.diag(cov))
        np.testing.assert_allclose(b.cov / np.outer(sd, sd), cov / np.outer(sd, sd), rtol=0, atol=1e-3)
        np.testing.assert_allclose(b.sigma, sd, rtol=1e-3)
        assert b.n_eq == n and b.chi2 == pytest.approx(chi2, rel=1e-6)
        assert b.chi2_reduced == pytest.approx(chi2 / (n - 5), rel=1e-6)
        assert b.success and b.message and b.names == THETA_NAMES
        np.testing.assert_array_equal(b.x, b.theta)


def test_batch_of_two_entries_on_the_brightest_stars(star_rig, frames):
    """estimate=(u0, v0), max_stars=6: the solution of the frames cut by hand, the other entries kept at the start;
    χ²/(n − 2)."""
    th = true_theta(star_rig)
    start = th + [0.0, 1.5, -1.0, 0.0, 0.0]
    cut = []
    for fo in frames:
        o = sorted(range(len(fo)), key=lambda i: -fo.flux[i])[:6]
        cut.append(FrameObs(fo.uv[o], fo.sigma_uv[o], fo.dirs_icrs[o], fo.flux[o]))
    b = batch_lsq(frames, start, estimate=("u0", "v0"), max_stars=6)
    c = batch_lsq(cut, start, estimate=("u0", "v0"))
    np.testing.assert_allclose(b.theta, c.theta, rtol=0, atol=1e-9)
    assert b.theta[0] == start[0] and b.theta[3] == start[3]
    assert b.n_eq == sum(2 * 6 - 3 for fo in cut if len(fo) >= 4)
    assert b.chi2_reduced == pytest.approx(b.chi2 / (b.n_eq - 2), rel=1e-12)


def test_chain_without_fluxes_keeps_the_given_order():
    uv = np.array([[10.0, 20.0], [500.0, 40.0], [300.0, 900.0], [60.0, 700.0], [800.0, 800.0]])
    pairs, trip = equation_sets(uv, "chain")
    np.testing.assert_array_equal(pairs, [[0, 1], [1, 2], [2, 3], [3, 4]])
    np.testing.assert_array_equal(trip, [[0, 1, 2], [1, 2, 3], [2, 3, 4]])
    pairs, trip = equation_sets(uv, "chain", flux=np.array([5.0, 1.0, 4.0, 2.0, 3.0]))
    np.testing.assert_array_equal(pairs, [[0, 2], [2, 4], [4, 3], [3, 1]])
    for bad in ("every", "b", "c", "a"):          # names on both sides of "all" and "chain" in string order
        with pytest.raises(ValueError, match="equations"):
            equation_sets(uv, bad)


def test_cholesky_of_an_indefinite_covariance_takes_the_smallest_jitter_that_works():
    """S = diag(2, 1, −δ) fails a plain Cholesky; the factor returned is that of S + εI with ε = 1e-9 of the mean
    diagonal, or 100 times that when δ exceeds it (the jitter grows by 100 a try). A zero mean diagonal takes 1 as
    the scale (diag(1, −1, 0) needs 10, the 7th try); 8 tries at most (diag(3000, 3000, −5995): the 8th jitter,
    1000 × 5/3, is short of 5995)."""
    for delta, eps in ((1e-12, 1e-9), (1e-8, 1e-7)):
        S = np.diag([2.0, 1.0, -delta])
        e = eps * np.mean(np.diag(S))
        L = np.tril(_cho(S)[0])
        np.testing.assert_allclose(np.diag(L), np.sqrt([2.0 + e, 1.0 + e, e - delta]), rtol=1e-12)
    np.testing.assert_allclose(np.diag(_cho(np.diag([1.0, -1.0, 0.0]))[0]), np.sqrt([11.0, 9.0, 10.0]), rtol=1e-12)
    # diag(3000, 3000, −5970): scale 10, the 7th jitter (100) fails, the 8th (10⁴) works
    np.testing.assert_allclose(np.diag(_cho(np.diag([3000.0, 3000.0, -5970.0]))[0]),
                               np.sqrt(np.array([3000.0, 3000.0, -5970.0]) + 1e4), rtol=1e-12)
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        _cho(np.diag([3000.0, 3000.0, -5995.0]))


def test_four_stars_all_pairs_are_projected_on_the_range_of_r(star_rig, frames):
    """4 stars: all 6 AD pairs carry 2N − 3 = 5 independent angles, so their propagated R has rank 5 and the EKF
    must use its pseudo-inverse: the information form P⁺ = (P⁻¹ + Hᵀ R⁺ H)⁻¹, Δx = P⁺ Hᵀ R⁺ ν with numpy's pinv
    of G Σ Gᵀ (a full R with the 1e-9 floor would instead weight the noise-free combination by 1e9)."""
    th = true_theta(star_rig)
    start = th + [0.0, 1.0, -1.0, 0.0, 0.0]
    four = [FrameObs(fo.uv[:4], fo.sigma_uv[:4], fo.dirs_icrs[:4], fo.flux[:4]) for fo in frames if len(fo) >= 4]
    r = run_ekf(four, start, equations="all")
    x, P = start.copy(), np.diag([100.0, 100.0])
    for fo in four:
        s = frame_system(fo, x, "ad", equations="all")
        assert s.h.size == 6
        Rp = np.linalg.pinv(s.G @ np.diag(s.var) @ s.G.T, rcond=1e-10, hermitian=True)
        H = s.H[:, 1:3]
        P = np.linalg.inv(np.linalg.inv(P) + H.T @ Rp @ H)
        x[1:3] = x[1:3] + P @ H.T @ Rp @ (s.z - s.h)
    np.testing.assert_allclose(r.x, x[1:3], rtol=0, atol=1e-6)
    np.testing.assert_allclose(r.P, P, rtol=1e-5)
    np.testing.assert_array_equal(r.dof, [5] * len(four))


def test_batch_of_one_four_star_frame(star_rig, frames):
    """A frame of exactly 4 stars is used (2N − 3 = 5 AD equations): with the 5 entries estimated it is exactly
    determined, n_eq = 5, and χ²/dof takes dof = max(1, 0) = 1."""
    th = true_theta(star_rig)
    fo = frames[0]
    four = FrameObs(fo.uv[:4], fo.sigma_uv[:4], fo.dirs_icrs[:4], fo.flux[:4])
    b = batch_lsq([four], th + [0.5, 0.3, -0.3, 0.0, 0.0])
    assert b.n_eq == 5 and b.chi2_reduced == b.chi2


def test_framework_hangs_on_the_two_stars_farthest_apart():
    """(a, b) is the pair at the largest distance, found here by brute force over every pair; here it is not the
    pair with the largest Δu + Δv."""
    import itertools

    uv = np.array([[0.0, 0.0], [10.0, -9.0], [6.0, 6.0], [3.0, 1.0]])
    far = max(itertools.combinations(range(4), 2), key=lambda p: np.hypot(*(uv[p[0]] - uv[p[1]])))
    pairs, trip = equation_sets(uv)
    assert set(pairs[0]) == set(far) == {1, 2}
    others = [j for j in range(4) if j not in far]
    assert len(pairs) == 5 and {tuple(p) for p in pairs[1:]} == {(a, j) for a in pairs[0] for j in others}
    assert {tuple(t) for t in trip} == ({(pairs[0][0], j, pairs[0][1]) for j in others}
                                        | {(j, pairs[0][0], pairs[0][1]) for j in others})


def test_normalized_coordinates_default_to_no_tangential_terms():
    """normalized_with_jacobians(uv, θ) without p12: OpenCV's undistortPoints of the same camera with p1 = p2 = 0."""
    import cv2

    th = np.array([2886.7, 514.3, 508.6, -0.06, 0.10])
    uv = np.array([[30.0, 40.0], [900.0, 120.0], [512.0, 512.0], [100.0, 980.0], [1000.0, 1000.0]])
    K = np.array([[th[0], 0.0, th[1]], [0.0, th[0], th[2]], [0.0, 0.0, 1.0]])
    ref = cv2.undistortPoints(uv.reshape(-1, 1, 2), K, np.array([th[3], th[4], 0.0, 0.0, 0.0]),
                              criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)).reshape(-1, 2)
    from rigsim.estimation.star_calibration import normalized_with_jacobians

    np.testing.assert_allclose(normalized_with_jacobians(uv, th)[0], ref, rtol=0, atol=1e-10)
