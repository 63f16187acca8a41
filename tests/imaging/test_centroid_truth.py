"""rigsim.imaging.centroid's default centroiders (centroid_gauss for star fields, centroid_tcom for the boresight
cameras and the autocollimator spot) against truths of their own: spots rendered with scipy's normal CDF,
the Fisher matrix by central differences of that rendering, the weighted mean and moments by hand and with
OpenCV. Written from the mutation run (docs/testing.md, "Centroiders")."""

from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from scipy.stats import norm

from rigsim.imaging import Flag, NoiseModel, centroid_gauss, centroid_tcom

K, READ = 2.0, 3.0  # gain DN/e-, read noise e-
NOISE = NoiseModel(K, READ)


def _render(h, w, u, v, F, B, s):
    """Pixel-integrated circular Gaussian: F·Ex(u)·Ey(v) + B, Ex from scipy's normal CDF at the pixel edges."""
    ex = np.diff(norm.cdf((np.arange(w + 1) - 0.5 - u) / s))
    ey = np.diff(norm.cdf((np.arange(h + 1) - 0.5 - v) / s))
    return F * np.outer(ey, ex) + B


def _first(b):
    """The first spot of a CentroidBatch, with its ``extra`` entries."""
    return SimpleNamespace(u=b.u[0], v=b.v[0], sigma_u=b.sigma_u[0], sigma_v=b.sigma_v[0], flux=b.flux[0],
                           background=b.background[0], flags=int(b.flags[0]), extra={k: x[0] for k, x in b.extra.items()})


def _var(mu):
    return K * mu + (K * READ) ** 2


def _fisher_sd(h, w, th, fit_sigma):
    """√diag of the inverse Fisher matrix Jᵀ V⁻¹ J, J by central differences of `_render`."""
    th = np.asarray(th, float)
    f = (lambda t: _render(h, w, *t)) if fit_sigma else (lambda t: _render(h, w, *t, th[4]))
    n = 5 if fit_sigma else 4
    steps = [1e-5, 1e-5, 1e-3 * th[2], 1e-4, 1e-6][:n]
    J = []
    for j in range(n):
        e = np.zeros(n)
        e[j] = steps[j]
        J.append(((f(th[:n] + e) - f(th[:n] - e)) / (2 * steps[j])).ravel())
    J = np.array(J).T
    A = J.T @ (J / _var(_render(h, w, *th)).ravel()[:, None])
    return np.sqrt(np.diag(np.linalg.inv(A)))


# spots on a non-square ROI (h ≠ w), at sub-pixel positions away from the centre, with a background
SPOTS = [(9, 13, 7.3, 3.6, 5.0e4, 40.0, 1.1), (11, 8, 2.8, 6.45, 2.0e4, 15.0, 0.9), (10, 10, 4.5, 5.2, 8.0e3, 25.0, 1.4)]


@pytest.mark.parametrize("fit_sigma", [False, True])
def test_gauss_recovers_a_noise_free_spot_and_its_fisher_sigmas(fit_sigma):
    for h, w, u, v, F, B, s in SPOTS:
        img = _render(h, w, u, v, F, B, s)
        r = _first(centroid_gauss(img[None], sigma_px=s if not fit_sigma else 1.0, fit_sigma=fit_sigma, noise=NOISE))
        assert r.flags == 0
        # to the fit's convergence (its last step < tol_px = 1e-4 px)
        np.testing.assert_allclose([r.u, r.v], [u, v], rtol=0, atol=2e-6)
        np.testing.assert_allclose([r.flux, r.background], [F, B], rtol=1e-6, atol=1e-4)
        assert r.extra["sigma_px"] == pytest.approx(s, abs=1e-6)
        sd = _fisher_sd(h, w, (u, v, F, B, s), fit_sigma)
        np.testing.assert_allclose([r.sigma_u, r.sigma_v, r.extra["sigma_flux"]], sd[:3], rtol=1e-4)
        assert 0 <= r.extra["chi2_red"] < 1e-4  # evaluated before the last step (< tol_px)


def test_gauss_batch_of_spots_converging_at_different_steps():
    """A stack whose spots need different numbers of Gauss–Newton steps (and one flagged INVALID on the way
    in, which is left alone): each spot's fit equals its truth and its own single-spot fit."""
    h = w = 11
    truth = [(5.0, 5.0), (3.7, 6.9), (6.45, 3.2), (5.2, 4.9)]
    img = np.stack([_render(h, w, u, v, 3.0e4, 20.0, 1.2) for u, v in truth])
    fl = np.array([0, 0, int(Flag.INVALID), 0])
    r = centroid_gauss(img, sigma_px=1.2, noise=NOISE, flags=fl)
    ok = [0, 1, 3]
    np.testing.assert_allclose(r.u[ok], [truth[i][0] for i in ok], atol=2e-6)
    np.testing.assert_allclose(r.v[ok], [truth[i][1] for i in ok], atol=2e-6)
    assert r.flags[2] & Flag.INVALID and np.isnan(r.u[2])
    for i in ok:
        one = centroid_gauss(img[i], sigma_px=1.2, noise=NOISE)
        assert (one.u, one.v, one.sigma_u) == pytest.approx((r.u[i], r.v[i], r.sigma_u[i]), abs=1e-9)


def test_gauss_reduced_chi2_by_hand():
    """chi2_red = Σ (data − model)² / var(model) / (n_pix − 4) at the fitted parameters (model rendered with
    scipy), for a noisy spot."""
    rng = np.random.default_rng(3)
    h, w, u, v, F, B, s = SPOTS[0]
    mu = _render(h, w, u, v, F, B, s)
    img = mu + rng.normal(size=mu.shape) * np.sqrt(_var(mu))
    r = _first(centroid_gauss(img[None], sigma_px=s, noise=NOISE))
    m = _render(h, w, r.u, r.v, r.flux, r.background, s)
    want = np.sum((img - m) ** 2 / _var(m)) / (h * w - 4)
    assert r.extra["chi2_red"] == pytest.approx(want, rel=1e-3)
    # fitting σ too: five parameters
    r = _first(centroid_gauss(img[None], sigma_px=s, fit_sigma=True, noise=NOISE))
    m = _render(h, w, r.u, r.v, r.flux, r.background, r.extra["sigma_px"])
    want = np.sum((img - m) ** 2 / _var(m)) / (h * w - 5)
    assert r.extra["chi2_red"] == pytest.approx(want, rel=1e-3)


def _tcom_by_hand(img, T, var):
    wgt = np.where(img > T, img - T, 0.0)
    m = cv2.moments(wgt.astype(np.float64))
    u, v = m["m10"] / m["m00"], m["m01"] / m["m00"]
    vv, uu = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    sel = img > T
    su = np.sqrt(np.sum(var[sel] * (uu[sel] - u) ** 2)) / wgt.sum()
    sv = np.sqrt(np.sum(var[sel] * (vv[sel] - v) ** 2)) / wgt.sum()
    return u, v, su, sv, sel.sum()


def test_tcom_position_sigmas_flux_and_count_by_hand():
    """centroid_tcom with a given threshold and background: the weighted mean (OpenCV's moments of the
    weights), σ_u, σ_v of the weighted mean with each pixel's variance, the flux above background and the
    pixel count, by hand."""
    h, w, u, v, F, B, s = SPOTS[0]
    img = _render(h, w, u, v, F, B, s)
    T = B + 50.0
    r = _first(centroid_tcom(img[None], threshold=T, background=B, noise=NOISE, edge_margin_px=0.0))
    cu, cv_, su, sv, npix = _tcom_by_hand(img, T, _var(img))
    assert (r.u, r.v) == pytest.approx((cu, cv_), abs=1e-12)
    assert (r.sigma_u, r.sigma_v) == pytest.approx((su, sv), rel=1e-12)
    sel = img > T
    assert r.flux == pytest.approx(np.sum(img[sel] - B), rel=1e-12)
    assert r.extra["npix"] == npix and r.extra["threshold"] == T
    assert r.background == B and r.flags == 0


def test_tcom_default_threshold_is_background_plus_3_sigma():
    """No threshold: T = background + 3·σ_bg, σ_bg the read noise with a NoiseModel; a pixel just above T
    counts, one just below does not."""
    B = 100.0
    sd = np.sqrt(_var(B))
    T = B + 3.0 * sd
    img = np.full((7, 7), B)
    img[3, 3] = B + 1000.0
    img[3, 4] = T + 1e-6
    img[2, 3] = T - 1e-6
    r = _first(centroid_tcom(img[None], background=B, noise=NOISE))
    assert r.extra["threshold"] == pytest.approx(T, rel=1e-12)
    assert r.extra["npix"] == 2
    w1, w2 = 1000.0 - 3.0 * sd, 1e-6
    assert r.u == pytest.approx((3 * w1 + 4 * w2) / (w1 + w2), abs=1e-12) and r.v == pytest.approx(3.0, abs=1e-12)


def test_tcom_flags_empty_and_faint():
    B = 10.0
    img = np.full((7, 7), B)
    e = centroid_tcom(img, threshold=B + 5.0, background=B, noise=NOISE)
    assert e.flags & Flag.EMPTY and e.flags & Flag.INVALID
    # one pixel 60 DN above background: snr = 60 / √var(B + 60) by hand; FAINT flips at that min_snr
    img[3, 3] = B + 60.0
    snr = 60.0 / np.sqrt(_var(B + 60.0))
    for min_snr, faint in ((snr * (1 - 1e-9), False), (snr * (1 + 1e-9), True)):
        r = centroid_tcom(img, threshold=B + 5.0, background=B, noise=NOISE, min_snr=min_snr)
        assert bool(r.flags & Flag.FAINT) == faint, min_snr
        assert (r.u, r.v) == (3.0, 3.0)


def test_gauss_flat_image_is_empty():
    """No spot at all: the fitted flux is 0 (to rounding), so the spot is EMPTY and INVALID."""
    r = _first(centroid_gauss(np.full((1, 9, 9), 40.0), sigma_px=1.0, noise=NOISE))
    assert r.flags & Flag.EMPTY and r.flags & Flag.INVALID


@pytest.mark.parametrize("k_sigma,poor", [(4.5, False), (5.5, True)])
def test_gauss_poor_fit_threshold_five_sigma_of_chi2(k_sigma, poor):
    """POOR_FIT when chi2_red > 1 + 5·√(2/dof): a spot whose noise is scaled so that chi2_red, computed by hand
    from the fitted model, lies 4.2–4.8 or 5.2–5.8 of √(2/dof) above 1."""
    h, w, u, v, F, B, s = SPOTS[0]
    mu = _render(h, w, u, v, F, B, s)
    z = np.random.default_rng(5).normal(size=mu.shape)
    dof = h * w - 4
    a = np.sqrt((1 + k_sigma * np.sqrt(2 / dof)) / 0.8209)
    img = mu + a * z * np.sqrt(_var(mu))
    r = _first(centroid_gauss(img[None], sigma_px=s, noise=NOISE))
    m = _render(h, w, r.u, r.v, r.flux, r.background, s)
    k = (np.sum((img - m) ** 2 / _var(m)) / dof - 1) / np.sqrt(2 / dof)
    assert abs(k - k_sigma) < 0.3
    assert bool(r.flags & Flag.POOR_FIT) == poor


def test_solve_spd_fallback_when_lapack_refuses(monkeypatch):
    """_solve_spd's own Cholesky inverse (used when LAPACK's inv raises on a matrix the factorisation found
    positive definite) against scipy's inverse and solve, for 4×4 and 5×5 stacks; a non-SPD matrix is not ok."""
    import scipy.linalg

    from rigsim.imaging.centroid import _solve_spd

    rng = np.random.default_rng(4)
    for P in (4, 5):
        M = rng.normal(size=(3, P, P))
        A = M @ M.transpose(0, 2, 1) + P * np.eye(P)
        A[2] = np.diag(np.r_[1.0, -1.0, np.ones(P - 2)])  # not positive definite
        g = rng.normal(size=(3, P))
        want_inv = [scipy.linalg.inv(a) for a in A[:2]]
        want_x = [scipy.linalg.solve(a, b, assume_a="pos") for a, b in zip(A[:2], g[:2])]

        def refuse(a):
            raise np.linalg.LinAlgError("refused")

        monkeypatch.setattr(np.linalg, "inv", refuse)
        x, inv, ok = _solve_spd(A, g)
        monkeypatch.undo()
        assert ok.tolist() == [True, True, False]
        np.testing.assert_allclose(inv[:2], want_inv, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(x[:2], want_x, rtol=1e-10, atol=1e-12)
        assert np.isnan(inv[2]).all()


@pytest.mark.parametrize("shape", [(2, 9), (9, 2), (2, 2)])
def test_rois_narrower_than_3_px_are_invalid(shape):
    img = np.full((1,) + shape, 10.0)
    img[0, 1, 1] = 500.0
    for r in (centroid_gauss(img, sigma_px=1.0, noise=NOISE), centroid_tcom(img, noise=NOISE),
              centroid_tcom(img, threshold=20.0, background=10.0, noise=NOISE)):
        assert r.flags[0] & Flag.INVALID and np.isnan(r.u[0])


def test_tcom_and_gauss_of_an_empty_batch():
    for r in (centroid_tcom(np.zeros((0, 5, 5)), noise=NOISE), centroid_gauss(np.zeros((0, 5, 5)), sigma_px=1.0, noise=NOISE)):
        assert r.u.shape == (0,) and r.flags.shape == (0,)


def test_three_px_rois_are_fitted():
    for h, w, u, v in ((3, 9, 4.3, 1.1), (9, 3, 0.9, 4.4)):
        img = _render(h, w, u, v, 2.0e4, 30.0, 0.8)[None]
        g = centroid_gauss(img, sigma_px=0.8, noise=NOISE)
        assert not g.flags[0] & Flag.INVALID
        assert (g.u[0], g.v[0]) == pytest.approx((u, v), abs=2e-6)


def test_tcom_unknown_mode_is_refused_and_default_edge_margin_is_one_px():
    img = np.full((7, 7), 10.0)
    img[3, 0] = 500.0  # a one-pixel spot on the first column: centroid u = 0, within 1 px of the edge (-0.5)
    with pytest.raises(ValueError, match="mode must be"):
        centroid_tcom(img, threshold=20.0, mode="weights")
    r = centroid_tcom(img, threshold=20.0, background=10.0, noise=NOISE)
    assert r.u == 0.0 and r.flags & Flag.EDGE


def test_gauss_not_converged_flags_only_spots_it_fitted():
    """One Gauss–Newton step from the 3×3 start does not reach tol_px: a valid spot is NOT_CONVERGED; a spot
    passed in as INVALID is not fitted and does not get that flag; a fully converged spot has neither."""
    img = _render(11, 11, 5.3, 4.8, 2.0e4, 20.0, 1.2)
    imgs = np.stack([img, img])
    b = centroid_gauss(imgs, sigma_px=1.2, noise=NOISE, max_iter=1, flags=np.array([0, int(Flag.INVALID)]))
    f = b.flags.astype(int)
    assert f[0] & Flag.NOT_CONVERGED and not f[0] & Flag.INVALID
    assert f[1] & Flag.INVALID and not f[1] & Flag.NOT_CONVERGED and b.extra["n_iter"][1] == 0
    r = _first(centroid_gauss(img[None], sigma_px=1.2, noise=NOISE))
    assert not r.flags & (Flag.NOT_CONVERGED | Flag.INVALID)


def test_gauss_second_spot_on_a_high_background_is_blended():
    """Two noise-free Gaussians (scipy's CDF) 6 px apart on a 5000 DN background: the fainter one's peak
    (~750 DN above the background) exceeds 5σ of the pixel noise and the dip between them 3σ and 10 % of its
    height, so the ROI is BLENDED (heights taken above the background); the brighter spot alone is not."""
    one = _render(15, 15, 5.2, 7.1, 3.0e4, 5000.0, 1.0)
    two = one + _render(15, 15, 11.2, 7.1, 5.0e3, 0.0, 1.0)
    b = centroid_gauss(np.stack([one, two]), sigma_px=1.0, noise=NOISE)
    f = b.flags.astype(int)
    assert not f[0] & Flag.BLENDED and f[1] & Flag.BLENDED


def test_gauss_fit_sigma_from_a_start_three_times_too_wide():
    """fit_sigma from σ = 3 px on a noise-free σ = 1 px spot (scipy's CDF) converges to the truth: the σ step's
    trust region is ±50 % of the current σ."""
    r = _first(centroid_gauss(_render(15, 15, 7.2, 6.7, 3.0e4, 20.0, 1.0)[None], sigma_px=3.0, fit_sigma=True, noise=NOISE))
    assert not r.flags & (Flag.NOT_CONVERGED | Flag.INVALID)
    assert abs(r.extra["sigma_px"] - 1.0) < 1e-6 and abs(r.u - 7.2) < 1e-6 and abs(r.v - 6.7) < 1e-6


def test_gauss_edge_margin_is_two_sigma():
    """EDGE where the centre lies within 2σ of the ROI's outer pixel boundary (u = −0.5): σ = 1, u = 1.0 (1.5 px
    in) is EDGE, u = 1.7 (2.2 px in) is not; the brightest pixel is off the border in both."""
    for u, edge in ((1.0, True), (1.7, False)):
        r = _first(centroid_gauss(_render(15, 15, u, 7.0, 3.0e4, 20.0, 1.0)[None], sigma_px=1.0, noise=NOISE))
        assert abs(r.u - u) < 1e-6 and bool(r.flags & Flag.EDGE) == edge, u


def test_tcom_default_edge_margin_is_not_two_px_and_its_options_are_keyword_only():
    """A one-pixel spot on the second column (u = 1, 1.5 px inside the edge −0.5) is not EDGE with the default
    1 px margin; centroid_tcom(img=…) is allowed, a positional threshold is not."""
    img = np.full((7, 7), 10.0)
    img[3, 1] = 500.0
    r = centroid_tcom(img=img, threshold=20.0, background=10.0, noise=NOISE)
    assert r.u == 1.0 and r.v == 3.0 and not r.flags & Flag.EDGE
    with pytest.raises(TypeError):
        centroid_tcom(img, 20.0)


@pytest.mark.parametrize("s", [0.0, -1.0, np.inf])
def test_gauss_refuses_a_sigma_that_is_not_finite_and_positive(s):
    with pytest.raises(ValueError, match="sigma_px must be finite and > 0"):
        centroid_gauss(_render(9, 9, 4.0, 4.0, 1.0e4, 10.0, 1.0)[None], sigma_px=s, noise=NOISE)


def test_gauss_faint_threshold_is_snr_five():
    """SNR = F / σ_F with σ_F from the Fisher matrix (`_fisher_sd`): a noise-free spot at SNR ≈ 5.5 is not FAINT
    with the default min_snr, FAINT with min_snr = 6."""
    h, w, u, v, B, s = 11, 11, 5.3, 4.8, 40.0, 1.2
    F = 325.0
    snr = F / _fisher_sd(h, w, (u, v, F, B, s), False)[2]
    assert 5.2 < snr < 5.8
    img = _render(h, w, u, v, F, B, s)[None]
    assert not _first(centroid_gauss(img, sigma_px=s, noise=NOISE)).flags & Flag.FAINT
    assert _first(centroid_gauss(img, sigma_px=s, noise=NOISE, min_snr=6.0)).flags & Flag.FAINT
    F = 270.0  # SNR ≈ 4.6: FAINT with the default
    assert 4.3 < F / _fisher_sd(h, w, (u, v, F, B, s), False)[2] < 4.8
    assert _first(centroid_gauss(_render(h, w, u, v, F, B, s)[None], sigma_px=s, noise=NOISE)).flags & Flag.FAINT


def test_tcom_mask_mode_weights_are_above_the_background():
    """mode="mask": the pixels above T weigh (I − B), by hand: (3·490 + 4·190) / 680 along u; a pixel at T is not above it."""
    img = np.full((7, 7), 10.0)
    img[3, 3], img[3, 4] = 500.0, 200.0
    r = centroid_tcom(img, threshold=20.0, background=10.0, noise=NOISE, mode="mask")
    assert r.u == pytest.approx((3 * 490 + 4 * 190) / 680, abs=1e-12) and r.v == pytest.approx(3.0, abs=1e-12)
    img[4, 3] = 20.0  # exactly at T: not above it, not counted
    r = centroid_tcom(img, threshold=20.0, background=10.0, noise=NOISE, mode="mask")
    assert r.u == pytest.approx((3 * 490 + 4 * 190) / 680, abs=1e-12) and r.v == pytest.approx(3.0, abs=1e-12)
