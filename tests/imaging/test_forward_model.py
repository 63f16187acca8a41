"""The forward-model fit (rigsim.imaging.forward_model) against closed forms: a pixel-integrated
Gaussian spot (erf), its Cramér–Rao bound from rigsim.imaging.crlb's separate Gaussian code, and the
noise of many frames drawn from the detector's model (Poisson electrons + Gaussian read noise)."""

import math

import numpy as np
import pytest
from scipy.special import erf

from rigsim.imaging import NoiseModel
from rigsim.imaging.crlb import crlb_gaussian
from rigsim.imaging.forward_model import fit_spot_model, model_crlb

H = W = 15
SIG = 1.1
GAIN = 1.0
READ_E = 5.0
FLUX_E = 4000.0
BG_E = 20.0
NOISE = NoiseModel(gain_dn_per_e=GAIN, read_noise_e=READ_E)


class Gauss:
    """Unit-flux pixel-integrated Gaussian of width ``sig`` on the window's pixels (closed form)."""

    def __init__(self, sig=SIG, shift=(0.0, 0.0)):
        self.sig, self.shift = sig, shift

    def __call__(self, u, v):
        def axis(n, c):
            e = (np.arange(n + 1) - 0.5 - c) / (math.sqrt(2) * self.sig)
            return 0.5 * np.diff(erf(e))
        return np.outer(axis(H, v + self.shift[1]), axis(W, u + self.shift[0]))


def frames(u, v, n, seed):
    rng = np.random.default_rng(seed)
    mu = FLUX_E * Gauss()(u, v) + BG_E
    return rng.poisson(mu, size=(n, H, W)) + rng.normal(0.0, READ_E, size=(n, H, W))


def test_fit_attains_the_crlb_of_a_gaussian_spot():
    """400 frames of a spot at a sub-pixel position: the fitted positions scatter as the CRLB says
    (rigsim.imaging.crlb's Gaussian bound, separate code), within ±10 % (the sampling error of an
    rms over 400 frames is 3.5 %), with no bias beyond 3 standard errors; the fit's own σ equals the
    bound to 5 %; χ²/dof averages 1."""
    u0, v0 = 7.3, 6.8
    bound = crlb_gaussian(FLUX_E, BG_E, READ_E, SIG, du=u0 - 7, dv=v0 - 7, roi_px=H)
    cov = model_crlb(Gauss(), u0, v0, FLUX_E, BG_E, NOISE)
    assert math.sqrt(cov[0, 0]) == pytest.approx(float(bound.sigma_u), rel=1e-3)
    assert math.sqrt(cov[1, 1]) == pytest.approx(float(bound.sigma_v), rel=1e-3)
    fits = [fit_spot_model(d, Gauss(), NOISE, 7.0, 7.0) for d in frames(u0, v0, 400, 1)]
    assert all(f.ok for f in fits)
    e = np.array([[f.u - u0, f.v - v0] for f in fits])
    ratio = np.sqrt(np.mean(e**2, axis=0)) / np.array([bound.sigma_u, bound.sigma_v])
    assert np.all((ratio > 0.9) & (ratio < 1.1)), ratio
    assert np.all(np.abs(e.mean(axis=0)) < 3 * e.std(axis=0) / math.sqrt(len(e)))
    assert np.median([f.sigma_u for f in fits]) == pytest.approx(float(bound.sigma_u), rel=0.05)
    assert np.mean([f.chi2_dof for f in fits]) == pytest.approx(1.0, abs=0.05)
    assert np.mean([f.flux_dn for f in fits]) == pytest.approx(FLUX_E, rel=0.01)
    assert np.mean([f.background_dn for f in fits]) == pytest.approx(BG_E, abs=0.5)


def test_a_model_whose_reference_point_is_elsewhere_is_seen_as_a_bias():
    """The fit returns the model's reference point: a model drawn 0.2 px off moves every fit by
    0.2 px (the fit cannot tell; its χ² cannot either). What it can tell: the wrong shape."""
    d = frames(7.3, 6.8, 50, 2)
    e = np.array([[f.u - 7.3, f.v - 6.8] for f in (fit_spot_model(x, Gauss(shift=(0.2, 0.0)), NOISE, 7, 7) for x in d)])
    assert e.mean(axis=0) == pytest.approx([-0.2, 0.0], abs=0.01)


def test_the_fit_says_when_the_model_does_not_fit():
    """A spot twice as wide as the model: χ²/dof far above 1 (the result carries it; the caller
    judges). Saturated pixels masked out do not count."""
    rng = np.random.default_rng(3)
    mu = FLUX_E * Gauss(sig=2.2)(7.3, 6.8) + BG_E
    d = rng.poisson(mu) + rng.normal(0, READ_E, mu.shape)
    f = fit_spot_model(d, Gauss(), NOISE, 7, 7)
    assert f.chi2_dof > 3
    good = fit_spot_model(frames(7.3, 6.8, 1, 4)[0], Gauss(), NOISE, 7, 7)
    assert good.chi2_dof < 1.5
    mask = np.ones((H, W), bool)
    mask[:, :3] = False
    g = fit_spot_model(frames(7.3, 6.8, 1, 4)[0], Gauss(), NOISE, 7, 7, mask=mask)
    assert g.dof == mask.sum() - 4


def test_too_few_pixels_or_no_spot_is_refused_not_guessed():
    f = fit_spot_model(np.zeros((2, 2)), Gauss(), NOISE, 1, 1)
    assert not f.ok and "too few" in f.problem
    flat = np.random.default_rng(5).normal(BG_E, READ_E, (H, W))
    f = fit_spot_model(flat, Gauss(), NOISE, 7, 7)
    assert not f.ok or f.flux_dn < 5 * math.sqrt(f.cov[2, 2])
