"""The star image models of the forward-model centroider (rigsim.optics.star_image_model) against the
renderer's own star images: the Gaussian is render_stars' pixel-integrated Gaussian, the traced model
render_stars_psf's drawing of the same PSF bins, and their derivatives are the images' slopes."""

from __future__ import annotations

import numpy as np
import pytest

from rigsim.optics.star_image_model import GaussianStarImage, TracedStarImage
from rigsim.optics.star_lens import StarLens
from rigsim.optics.star_psf import psf_table
from rigsim.render.star import render_stars, render_stars_psf

W = H = 64


@pytest.fixture(scope="module")
def small_table():
    """The default rig's lens traced at 3 × 3 field directions (the axis, the edges' middles, the corners) and
    two wavelengths: cheap, and the corners hold the largest centroid shift."""
    lens = StarLens(focal_length_mm=43.3, epd_mm=20.0, ref_nm=600.0, defocus_mm=-0.1)
    return psf_table(lens, tan_max_x=0.18, tan_max_y=0.18, wavelengths_nm=[550.0, 700.0], pixel_pitch_um=15.0,
                     nodes=3, pupil_rays=32, oversample=4)


class _Axis:
    """A camera whose ray through (u, v) has tan θ = ((u, v) − 32) · scale (a stand-in for the nominal camera)."""

    def __init__(self, scale):
        self.scale = scale

    def unproject(self, uv):
        t = (np.asarray(uv, float) - 32.0) * self.scale
        d = np.concatenate([t, np.ones((len(t), 1))], axis=1)
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def _window(img, o, h=15, w=15):
    return img[int(o[1]):int(o[1]) + h, int(o[0]):int(o[0]) + w]


def test_the_gaussian_model_is_the_renderers_gaussian_and_its_slopes():
    """On the renderer's own box (±5σ, 9 × 9 px for σ = 0.77 px): equal to 1e-12; the slopes are the
    image's central differences."""
    uv = np.array([[30.3, 31.7], [33.05, 29.5]])
    o = np.floor(uv + 0.5) - 4
    m = GaussianStarImage(0.77).bind(uv)
    p, pu, pv = m.pixels(uv[:, 0], uv[:, 1], o, (9, 9))
    for i in range(2):
        ref = _window(render_stars(uv[i:i + 1], np.array([1.0]), (H, W), 0.77), o[i], 9, 9)
        np.testing.assert_allclose(p[i], ref, atol=1e-12)
    h = 1e-6
    np.testing.assert_allclose(pu, (m.pixels(uv[:, 0] + h, uv[:, 1], o, (9, 9))[0]
                                    - m.pixels(uv[:, 0] - h, uv[:, 1], o, (9, 9))[0]) / (2 * h), atol=1e-7)
    np.testing.assert_allclose(pv, (m.pixels(uv[:, 0], uv[:, 1] + h, o, (9, 9))[0]
                                    - m.pixels(uv[:, 0], uv[:, 1] - h, o, (9, 9))[0]) / (2 * h), atol=1e-7)


def test_the_traced_model_is_the_renderers_drawing_of_the_same_psf(small_table):
    """At the corner (tan θ = 0.18 per axis, the table's node) and on the axis: the model's window equals
    render_stars_psf's window of the same bins to 2 % of the peak (the model smooths each ¼-px bin by
    ⅛ px), keeps every photon, and its first moment is the renderer's to 0.003 px."""
    cam = _Axis(0.18 / 20.0)
    uv = np.array([[52.3, 51.85], [32.0, 32.0], [41.6, 22.2]])
    model = TracedStarImage(small_table, cam, 0.65)
    b = model.bind(uv)
    o = np.floor(uv + 0.5) - 7
    p, pu, pv = b.pixels(uv[:, 0], uv[:, 1], o, (15, 15))
    c = np.arange(15)
    for i in range(len(uv)):
        ref = _window(render_stars_psf(uv[i:i + 1], np.array([1.0]), (H, W), b.bins[i:i + 1], small_table.radius_px,
                                       small_table.oversample), o[i])
        assert float(p[i].sum()) == pytest.approx(float(ref.sum()), abs=1e-9)
        assert np.abs(p[i] - ref).max() < 0.02 * ref.max()
        m_model = np.array([p[i].sum(axis=0) @ c, p[i].sum(axis=1) @ c]) / p[i].sum()
        m_ref = np.array([ref.sum(axis=0) @ c, ref.sum(axis=1) @ c]) / ref.sum()
        np.testing.assert_allclose(m_model, m_ref, atol=3e-3)
    h = 1e-5
    pp = b.pixels(uv[:, 0] + h, uv[:, 1], o, (15, 15))[0]
    pm = b.pixels(uv[:, 0] - h, uv[:, 1], o, (15, 15))[0]
    np.testing.assert_allclose(pu, (pp - pm) / (2 * h), atol=1e-6)
    pp = b.pixels(uv[:, 0], uv[:, 1] + h, o, (15, 15))[0]
    pm = b.pixels(uv[:, 0], uv[:, 1] - h, o, (15, 15))[0]
    np.testing.assert_allclose(pv, (pp - pm) / (2 * h), atol=1e-6)


def test_the_traced_model_follows_the_field_and_the_colour(small_table):
    """The bound PSF is the table's star PSF at the camera's ray through the position: the corner's differs
    from the axis's, and a red star's from a blue one's."""
    cam = _Axis(0.18 / 20.0)
    model = TracedStarImage(small_table, cam, 0.65)
    b = model.bind(np.array([[52.0, 52.0], [32.0, 32.0]]))
    assert np.abs(b.bins[0] - b.bins[1]).max() > 0.1 * b.bins[1].max()
    d = cam.unproject(np.array([[52.0, 52.0]]))
    want, _ = small_table.star_psfs(d, model.spectral_weights())
    np.testing.assert_allclose(b.bins[0], want[0], atol=1e-15)
    red, blue = model.bind(np.array([[52.0, 52.0]]), np.array([1.6])), model.bind(np.array([[52.0, 52.0]]), np.array([-0.2]))
    assert np.abs(red.bins - blue.bins).max() > 1e-4
    assert any("B−V 0.65" in s for s in model.includes) and any("Gaussian" in s for s in GaussianStarImage(0.77).includes)
