"""CRLB: analytic limits, generic-PSF agreement, and Monte-Carlo of an efficient estimator."""

import math

import numpy as np
import pytest

from rigsim.imaging import NoiseModel, centroid_gauss, crlb_gaussian, crlb_psf
from rigsim.imaging.synth import add_noise, flux_for_snr, gaussian_spots


def test_photon_limited_limit_matches_closed_form():
    # no background, no read noise, wide PSF on a large ROI: sigma_u = sqrt(s^2 + 1/12) / sqrt(F)
    # (pixelisation adds the box variance 1/12 px^2), a standard closed form.
    F, s = 1.0e4, 3.0
    b = crlb_gaussian(F, 0.0, 0.0, s, roi_px=41, unknowns=("u", "v"))
    expected = math.sqrt(s * s + 1.0 / 12.0) / math.sqrt(F)
    assert b.sigma_u == pytest.approx(expected, rel=2e-3)
    assert b.sigma_v == pytest.approx(expected, rel=2e-3)


def test_background_limited_scaling():
    # background dominated: sigma ~ sqrt(B) / F, so doubling F halves it, 4x B doubles it
    s = 1.5
    a = crlb_gaussian(1000.0, 1.0e4, 0.0, s).sigma_u
    b = crlb_gaussian(2000.0, 1.0e4, 0.0, s).sigma_u
    c = crlb_gaussian(1000.0, 4.0e4, 0.0, s).sigma_u
    assert b / a == pytest.approx(0.5, rel=0.02)
    assert c / a == pytest.approx(2.0, rel=0.02)
    # read noise enters as background + read^2
    d = crlb_gaussian(1000.0, 1.0e4 + 100.0**2, 0.0, s).sigma_u
    e = crlb_gaussian(1000.0, 1.0e4, 100.0, s).sigma_u
    assert d == pytest.approx(e, rel=1e-12)


def test_generic_psf_agrees_with_analytic():
    psf = lambda shape, u, v: gaussian_spots(shape, u, v, 1.0, 1.3)  # noqa: E731
    for unknowns in (("u", "v"), ("u", "v", "flux", "background")):
        g = crlb_psf(psf, 2500.0, 30.0, 4.0, 5.27, 4.81, (11, 11), unknowns=unknowns)
        a = crlb_gaussian(2500.0, 30.0, 4.0, 1.3, du=0.27, dv=-0.19, roi_px=11, unknowns=unknowns)
        assert g.sigma_u == pytest.approx(float(a.sigma_u), rel=1e-5)
        assert g.sigma_v == pytest.approx(float(a.sigma_v), rel=1e-5)


def test_more_unknowns_never_tighten_the_bound():
    kw = dict(du=np.linspace(-0.5, 0.5, 7), dv=0.3)
    b2 = crlb_gaussian(800.0, 50.0, 5.0, 1.0, unknowns=("u", "v"), **kw).sigma_u
    b4 = crlb_gaussian(800.0, 50.0, 5.0, 1.0, **kw).sigma_u
    b5 = crlb_gaussian(800.0, 50.0, 5.0, 1.0, unknowns=("u", "v", "flux", "background", "sigma"), **kw).sigma_u
    assert np.all(b4 >= b2 * (1 - 1e-12))
    assert np.all(b5 >= b4 * (1 - 1e-12))


def test_broadcasting_shapes():
    b = crlb_gaussian(np.array([1e3, 1e4])[:, None], 20.0, 5.0, 1.0, du=np.linspace(-0.5, 0.5, 5))
    assert b.sigma_u.shape == (2, 5)
    assert np.all(b.sigma_u[1] < b.sigma_u[0])


@pytest.mark.parametrize(
    "kw",
    [dict(flux_e=0.0), dict(flux_e=-1.0), dict(background_e=np.nan), dict(read_noise_e=-1.0)],
)
def test_rejects_bad_input(kw):
    args = dict(flux_e=1e3, background_e=10.0, read_noise_e=2.0, sigma_px=1.0)
    args.update(kw)
    with pytest.raises(ValueError):
        crlb_gaussian(**args)
    with pytest.raises(ValueError):
        crlb_gaussian(1e3, 10.0, 2.0, 1.0, unknowns=("u", "flux"))


def test_monte_carlo_efficient_estimator_attains_bound():
    """The noise-weighted Gaussian fit's scatter equals the CRLB (the bound is attained, so the
    bound is right and so is the estimator). 3000 spots: the RMS is known to ~1.3 %."""
    rng = np.random.default_rng(20240401)
    B, R, s, n = 20.0, 5.0, 1.0, 3000
    F = flux_for_snr(100.0, B, R, s)
    du = rng.uniform(-0.5, 0.5, n)
    dv = rng.uniform(-0.5, 0.5, n)
    img = add_noise(gaussian_spots((9, 9), 4 + du, 4 + dv, F, s, B), NoiseModel(1.0, R), rng)
    r = centroid_gauss(img, sigma_px=s, noise=NoiseModel(1.0, R))
    err = np.concatenate([r.u - 4 - du, r.v - 4 - dv])
    bound = crlb_gaussian(F, B, R, s, du=du, dv=dv)
    bound_rms = math.sqrt(np.mean(np.concatenate([bound.sigma_u, bound.sigma_v]) ** 2))
    ratio = math.sqrt(np.mean(err**2)) / bound_rms
    se = 1.0 / math.sqrt(2 * err.size)  # relative standard error of an RMS
    assert abs(ratio - 1.0) < 4 * se + 0.01, ratio
