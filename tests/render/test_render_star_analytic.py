"""Analytic renderer: flux conservation and exact centroids (pixel-integrated Gaussian)."""

import numpy as np
import pytest

from rigsim.render.star import render_stars


def test_flux_and_first_moment_exact():
    rng = np.random.default_rng(3)
    uv = np.column_stack([rng.uniform(20, 80, 5), rng.uniform(20, 80, 5)])
    uv = uv[np.argsort(uv[:, 0])]
    uv[:, 0] += np.arange(5) * 60  # keep them apart (≥ 60 px)
    ph = rng.uniform(1e3, 1e5, 5)
    img = render_stars(uv, ph, (120, 400), 0.8)
    assert img.sum() == pytest.approx(ph.sum(), rel=1e-6)  # flux beyond 5σ: 6e-7 of each star
    v, u = np.indices(img.shape)
    for (cu, cv), p in zip(uv, ph):
        m = (np.abs(u - cu) < 6) & (np.abs(v - cv) < 6)
        w = img * m
        # the first moment of a pixel-integrated Gaussian equals its centre exactly (symmetric integrals);
        # truncation at 5σ leaves < 1e-6 px
        assert (w * u).sum() / w.sum() == pytest.approx(cu, abs=1e-5)
        assert (w * v).sum() / w.sum() == pytest.approx(cv, abs=1e-5)


def test_pixel_convention_and_edges():
    img = render_stars(np.array([[0.0, 0.0]]), np.array([1000.0]), (10, 10), 0.5)
    # centred on pixel (0, 0): that pixel holds erf(0.5/(√2·0.5))² = 0.4661 of the flux; 3/4 of the star is off-frame
    assert img[0, 0] == pytest.approx(1000 * 0.682689492 ** 2, rel=1e-6)
    assert img.sum() == pytest.approx(1000 * (0.5 + 0.682689492 / 2) ** 2, rel=1e-6)
    smear = render_stars(np.array([[[5.0, 5.0], [6.0, 5.0]]]), np.array([100.0]), (12, 12), 0.7)
    v, u = np.indices(smear.shape)
    assert (smear * u).sum() / smear.sum() == pytest.approx(5.5, abs=1e-6)
