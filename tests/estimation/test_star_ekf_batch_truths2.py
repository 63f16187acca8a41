"""run_ekf_batch against the textbook Kalman filter of textbook_ekf.py on the cases the first two files left open:
all five intrinsics with known tangential terms (every column of ∂x/∂θ, p1 ≠ p2), equation sets with fewer
equations than estimated entries, 4-star frames, rank-deficient propagated sets (R's pseudo-inverse, written here
from R's own eigenvectors), the regularisation of their smallest eigenvalues, exactly known centroids there, a full R
conditioned beyond 1e10, frames of differing star counts across filters, the memo cache across models, batches of
one and three, and the call signature."""

import warnings

import numpy as np
import pytest
from star_frames import noisy_frames, true_theta
from textbook_ekf import textbook_ekf_full

import rigsim.estimation.star_ekf_batch as seb
from rigsim.estimation.star_calibration import FrameObs, equation_sets, run_ekf
from rigsim.estimation.star_ekf_batch import run_ekf_batch

ALL5 = ("f", "u0", "v0", "k1", "k2")


@pytest.fixture(scope="module")
def frames(star_rig, star_sky):
    return noisy_frames(star_rig, star_sky, 0.05, np.random.default_rng(41), 3, 8, shuffle=True, spread_sigma=True)


def _first(fo, n, sigma=None):
    """The first n stars of a frame, optionally with new centroid σ (n, 2)."""
    return FrameObs(fo.uv[:n], fo.sigma_uv[:n] if sigma is None else sigma, fo.dirs_icrs[:n], fo.flux[:n])


def _assert_textbook(r, t, x_tol, p_tol, nis_rtol):
    """Estimates in units of the textbook's posterior σ, P relative to its largest entry, NIS, update dimensions."""
    _th, t_P, t_hist, t_nis, t_dof = t
    sig = np.sqrt(np.diagonal(t_P))
    np.testing.assert_allclose((r.history_x - t_hist) / sig, 0.0, atol=x_tol)
    np.testing.assert_allclose(r.P, t_P, rtol=0, atol=p_tol * np.abs(t_P).max())
    np.testing.assert_allclose(r.nis, t_nis, rtol=nis_rtol, atol=1e-12)
    np.testing.assert_array_equal(r.dof, t_dof)


@pytest.fixture
def no_fallback(monkeypatch):
    """Fails a test in which a filter leaves the batched gain update for the single filter's jittered one."""
    calls = []

    def spy(*a):
        calls.append(a)
        raise AssertionError("a positive-definite S took the single filter's jittered path")

    monkeypatch.setattr(seb, "_update", spy)
    return calls


@pytest.mark.parametrize(("model", "equations", "weighting", "n_stars"), [
    ("ad", "framework", "propagated", 8), ("ads", "framework", "diagonal", 8), ("ad", "chain", "propagated", 4)])
def test_all_five_intrinsics_with_tangential_terms(star_rig, frames, no_fallback, model, equations, weighting, n_stars):
    """f, u0, v0, k1, k2 at once with p1 ≠ p2 ≠ 0, H of the textbook filter by central differences: every column
    of ∂x/∂θ and both tangential terms enter. 4 stars is the smallest frame a filter takes; their chain set has 3
    equations for 5 entries, and with centroids 10× more precise and a wide prior H P Hᵀ − R is positive definite
    too (at the first frame), so a sign slip on R would not fall back to the single filter's update."""
    th = true_theta(star_rig)
    p12 = (3e-4, -5e-4)
    starts = np.array([th + [3.0, 1.0, -1.5, 0.01, -0.02], th + [-2.0, -0.5, 2.0, -0.01, 0.01], th])
    if n_stars == 4:
        ps, fr = [10.0, 10.0, 10.0, 0.1, 0.1], [_first(fo, 4, 0.1 * fo.sigma_uv[:4]) for fo in frames[:2]]
    else:
        ps, fr = [5.0, 3.0, 3.0, 0.02, 0.05], [_first(fo, n_stars) for fo in frames[:2]]
    got = run_ekf_batch(fr, starts, model=model, estimate=ALL5, prior_sigma=ps, weighting=weighting,
                        equations=equations, p12=p12, process_sigma=0.01)
    for r, t0 in zip(got, starts, strict=True):
        t = textbook_ekf_full(fr, t0, [0, 1, 2, 3, 4], ps, 0.01, model, weighting, equations, fd_jacobian=True, p12=p12)
        _assert_textbook(r, t, x_tol=1e-3, p_tol=1e-4, nis_rtol=1e-4)
        assert r.n_eq.tolist() == [t[4][0]] * 2
    assert not no_fallback


@pytest.mark.parametrize(("model", "n_stars", "sigma_lo"), [
    ("ad", 4, None), ("ad", 5, None), ("ad", 6, None), ("ad", 8, None), ("ad", 6, 1e-3), ("ads", 6, None),
    ("ads", 6, 1e-3)])
def test_rank_deficient_sets_are_the_pseudo_inverse_update(frames, star_rig, model, n_stars, sigma_lo):
    """``all`` sets have more equations than the 2N − 3 independent angles (AD: 6 of 5 at N = 4, ...), so R = G Σ Gᵀ
    is singular: the update is the textbook gain form on the range of R (R's own eigenvectors above 1e-10 of the
    largest, eigenvalues raised by 1e-9 of their mean), against the batch's projection through AᵀA. With two stars
    100× more precise than the rest (``sigma_lo``) R spans 1e4 and the 1e-9 floor moves the smallest weights by ~1e-5:
    the tolerances hold it. The information form returns an exactly symmetric P and no floating-point warnings."""
    th = true_theta(star_rig)
    starts = np.array([th + [3.0, 1.0, -1.5, 0, 0], th + [-2.0, -0.5, 2.0, 0, 0], th])
    ps = [5.0, 3.0, 3.0]
    fr = []
    for fo in frames[:2]:
        sig = None
        if sigma_lo is not None:
            sig = np.full((n_stars, 2), 0.1)
            sig[np.argsort(-fo.flux[:n_stars])[:2]] = sigma_lo
        fr.append(_first(fo, n_stars, sig))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        got = run_ekf_batch(fr, starts, model=model, estimate=("f", "u0", "v0"), prior_sigma=ps, equations="all",
                            process_sigma=0.01)
    m = len(equation_sets(fr[0].uv, "all")[0 if model == "ad" else 1])
    assert m > 2 * n_stars - 3
    for r, t0 in zip(got, starts, strict=True):
        t = textbook_ekf_full(fr, t0, [0, 1, 2], ps, 0.01, model, "propagated", "all", pinv=True)
        assert t[4].tolist() == [2 * n_stars - 3] * 2
        _assert_textbook(r, t, x_tol=1e-7, p_tol=1e-8, nis_rtol=1e-7)
        assert r.n_eq.tolist() == [m, m]
        np.testing.assert_array_equal(r.P, r.P.T)


def test_exactly_known_centroids_in_an_all_set_give_no_update(star_rig, frames):
    """σ = 0 with an ``all`` set: R = 0 has an empty range, so its pseudo-inverse carries no information: no step,
    P = prior + Q, NIS 0 and update dimension 0 (the batch's floor is then 0/0, discarded: that warning is allowed)."""
    exact = [FrameObs(fo.uv, np.zeros_like(fo.sigma_uv), fo.dirs_icrs, fo.flux) for fo in frames]
    th = true_theta(star_rig)
    starts = np.array([th + [0, 1.0, -1.0, 0, 0], th + [0, -0.5, 0.5, 0, 0]])
    with np.errstate(invalid="ignore"):
        got = run_ekf_batch(exact, starts, equations="all", prior_sigma=[3.0, 3.0], process_sigma=0.01)
    for r, t0 in zip(got, starts, strict=True):
        t = textbook_ekf_full(exact, t0, [1, 2], [3.0, 3.0], 0.01, "ad", "propagated", "all", pinv=True)
        np.testing.assert_array_equal(r.history_x, [t0[1:3]] * 4)
        np.testing.assert_allclose(r.P, np.diag([9.0 + 3e-4] * 2), rtol=1e-14)
        _assert_textbook(r, t, x_tol=0, p_tol=1e-14, nis_rtol=0)
        assert r.dof.tolist() == [0, 0, 0]


def test_a_full_rank_r_conditioned_beyond_1e10_keeps_every_equation(star_rig, frames):
    """A chain set has fewer equations than independent angles, so R is full rank and the update is the gain form with
    all of it, however ill-conditioned: here the two brightest stars (one chain equation) have σ = 1e-6 px against
    0.1 px, R spans > 1e10 (what a projection would cut) and that equation dominates the update."""
    th = true_theta(star_rig)
    fr = []
    for fo in frames[:2]:
        sig = np.full((6, 2), 0.1)
        sig[np.argsort(-fo.flux[:6])[:2]] = 1e-6
        fr.append(_first(fo, 6, sig))
    starts = np.array([th + [3.0, 1.0, -1.5, 0, 0], th + [-2.0, -0.5, 2.0, 0, 0]])
    got = run_ekf_batch(fr, starts, estimate=("f", "u0", "v0"), prior_sigma=[5.0, 3.0, 3.0], equations="chain",
                        process_sigma=0.01)
    for r, t0 in zip(got, starts, strict=True):
        t = textbook_ekf_full(fr, t0, [0, 1, 2], [5.0, 3.0, 3.0], 0.01, "ad", "propagated", "chain")
        _assert_textbook(r, t, x_tol=1e-6, p_tol=1e-8, nis_rtol=1e-6)
        assert r.dof.tolist() == [5, 5]


def test_filters_whose_frames_differ_in_star_counts(star_rig, frames, monkeypatch):
    """Four filters on their own sequences; at the second frame they see 4, 3, 0 and 6 stars (three batches: a
    4-star frame is taken, 3 and 0 are skipped alike, 6 runs apart). Each filter is its textbook filter, and each
    filter's frame goes through one batched update, not more."""
    th = true_theta(star_rig)
    counts = [4, 3, 0, 6]
    seqs = [[_first(frames[0], 6), _first(frames[1], c), _first(frames[2], 6)] for c in counts]
    starts = np.array([th + [0, 1.0 * b, -0.5 * b, 0, 0] for b in range(4)])
    seen = []
    real = seb._frame_update

    def counting(fos, thetas, *a):
        seen.append(thetas.shape[0])
        return real(fos, thetas, *a)

    monkeypatch.setattr(seb, "_frame_update", counting)
    got = run_ekf_batch(seqs, starts, prior_sigma=[3.0, 3.0], process_sigma=0.01)
    assert sum(seen) == sum(2 + (c >= 4) for c in counts)
    for r, seq, t0, c in zip(got, seqs, starts, counts, strict=True):
        t = textbook_ekf_full(seq, t0, [1, 2], [3.0, 3.0], 0.01, "ad", "propagated")
        _assert_textbook(r, t, x_tol=1e-6, p_tol=1e-8, nis_rtol=1e-6)
        assert r.n_eq.tolist() == [9, 5 if c == 4 else 9 if c == 6 else 0, 9]


def test_one_cache_across_models(star_rig, frames, monkeypatch):
    """One memo cache for AD, then ADS, then AD again on the same frames: AD's pairs and ADS's triplets measure
    different things, so each model's filter is its own textbook filter; the repeated AD run finds every frame's sets
    in the cache (no new star sets drawn)."""
    drawn = []
    real = seb.equation_sets

    def counting(*a, **k):
        drawn.append(1)
        return real(*a, **k)

    monkeypatch.setattr(seb, "equation_sets", counting)
    th = true_theta(star_rig)
    starts = np.array([th + [0, 1.0, -1.0, 0, 0], th + [0, -0.5, 0.5, 0, 0]])
    cache, new = {}, []
    for model in ("ad", "ads", "ad"):
        before = len(drawn)
        got = run_ekf_batch(frames, starts, model=model, prior_sigma=[3.0, 3.0], process_sigma=0.01, cache=cache)
        new.append(len(drawn) - before)
        for r, t0 in zip(got, starts, strict=True):
            t = textbook_ekf_full(frames, t0, [1, 2], [3.0, 3.0], 0.01, model, "propagated")
            _assert_textbook(r, t, x_tol=1e-6, p_tol=1e-8, nis_rtol=1e-6)
    assert new == [len(frames), len(frames), 0]


def test_improved_ads_in_batches_of_one_and_three(star_rig, frames):
    """The improved ADS model's batched terms with B = 3 filters and with a single θ0 given as one row (B = 1)."""
    th = true_theta(star_rig)
    starts = np.array([th + [0.0, 0.3, -0.2, 0, 0], th + [2.0, -0.2, 0.3, 0, 0], th + [-1.0, 0.1, 0.1, 0, 0]])
    for th0s in (starts, starts[1]):
        got = run_ekf_batch(frames[:1], th0s, model="ads_improved", prior_sigma=[1.0, 2.0], process_sigma=0.5)
        assert len(got) == np.atleast_2d(th0s).shape[0]
        for r, t0 in zip(got, np.atleast_2d(th0s), strict=True):
            t = textbook_ekf_full(frames[:1], t0, [1, 2], [1.0, 2.0], 0.5, "ads_improved", "propagated", fd_jacobian=True)
            np.testing.assert_allclose(r.history_x[1] - r.history_x[0], t[2][1] - t[2][0], rtol=1e-6)
            np.testing.assert_allclose(r.P, t[1], rtol=1e-5, atol=1e-5 * np.abs(t[1]).max())
            np.testing.assert_allclose(r.nis, t[3], rtol=1e-5)


@pytest.mark.parametrize(("n_filters", "estimate"), [(3, ("u0", "v0")), (2, ("f", "u0", "v0")), (1, ("u0", "v0"))])
def test_jittered_fallback_with_batch_size_other_than_the_state_size(star_rig, frames, n_filters, estimate):
    """σ = 0 on a framework set: S is singular and every filter takes the single filter's jittered update, which is
    run_ekf's by construction; the batch has 3, 2 or 1 filters for 2, 3 or 2 estimated entries."""
    exact = [FrameObs(fo.uv, np.zeros_like(fo.sigma_uv), fo.dirs_icrs, fo.flux) for fo in frames]
    th = true_theta(star_rig)
    starts = np.array([th + [0.5 * b, 1.0 - b, b - 1.0, 0, 0] for b in range(n_filters)])
    ps = [3.0] * len(estimate)
    got = run_ekf_batch(exact, starts, estimate=estimate, prior_sigma=ps)
    assert len(got) == n_filters
    for r, t0 in zip(got, starts, strict=True):
        ref = run_ekf(exact, t0, estimate=estimate, prior_sigma=ps)
        np.testing.assert_allclose(r.history_x, ref.history_x, rtol=0, atol=1e-5)
        np.testing.assert_allclose(r.P, ref.P, rtol=1e-3, atol=1e-3 * np.abs(ref.P).max())


def test_call_signature(star_rig, frames):
    """frames and theta0s by keyword too; the settings by keyword only; one sequence per filter, no more."""
    th = true_theta(star_rig)
    (r,) = run_ekf_batch(frames=frames, theta0s=[th], prior_sigma=[3.0, 3.0])
    t = textbook_ekf_full(frames, th, [1, 2], [3.0, 3.0], 0.0, "ad", "propagated")
    _assert_textbook(r, t, x_tol=1e-6, p_tol=1e-8, nis_rtol=1e-6)
    with pytest.raises(TypeError):
        run_ekf_batch(frames, [th], "ads")
    with pytest.raises(ValueError, match="3 frame sequences for 2 filters"):
        run_ekf_batch([frames, frames, frames], [th, th])
