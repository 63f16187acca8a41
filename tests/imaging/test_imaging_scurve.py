"""S-curve correction of the first moment of an undersampled uniform disk (rigsim.imaging.scurve)."""

import numpy as np
import pytest

from rigsim.imaging.scurve import binned_moment_bias, centroid_disk_scurve


def _disk_image(cu, cv, radius, n=15, ss=64, axes=(1.0, 1.0), angle=0.0):
    """Pixel-integrated uniform (elliptical) disk by ss×ss supersampling: an independent raster."""
    off = (np.arange(ss) + 0.5) / ss - 0.5
    v, u = np.mgrid[0:n, 0:n].astype(float)
    U = (u[:, :, None, None] + off[None, None, None, :]) - cu
    V = (v[:, :, None, None] + off[None, None, :, None]) - cv
    c, s = np.cos(angle), np.sin(angle)
    x, y = (c * U + s * V) / axes[0], (-s * U + c * V) / axes[1]
    return (x * x + y * y < radius * radius).mean(axis=(2, 3))


def test_bias_model_is_the_binned_semicircle_moment():
    # a disk centred on a pixel centre or a pixel edge is symmetric: no bias
    assert binned_moment_bias(7.0, 1.27) == pytest.approx(0.0, abs=1e-12)
    assert binned_moment_bias(7.5, 1.27) == pytest.approx(0.0, abs=1e-12)
    # in between it is not, and it is odd about the pixel centre
    b = binned_moment_bias(7.2, 1.27)
    assert abs(b) > 1e-3
    assert binned_moment_bias(6.8, 1.27) == pytest.approx(-b, abs=1e-12)


@pytest.mark.parametrize("axes,angle,max_px,rms_px", [
    ((1.0, 1.0), 0.0, 0.002, 0.0008),   # on axis: a round 2.5 px disk
    ((1.0, 0.6), 0.7, 0.02, 0.004),     # off axis: elongated and turned (partial correction)
])
def test_correction_removes_the_pixel_phase_bias_of_a_2_5_px_disk(axes, angle, max_px, rms_px):
    """The sun as the default sensor sees it: a 2.5 px disk (an ellipse off axis). The plain first
    moment is biased by up to ~0.02 px (0.011–0.014 px rms). Corrected (60 random phases,
    measured): round 0.0009 px max / 0.0003 rms; elongated 0.013 max / 0.0015 rms — an elongated
    disk straddling a pixel edge leaves its half-width barely constrained by the two moments.
    Tolerances ≈ 2× the measurement (the 64² reference raster is itself good to ~7e-4 px)."""
    rng = np.random.default_rng(1)
    raw, cor = [], []
    for _ in range(60):
        cu, cv = 7.0 + rng.uniform(-0.5, 0.5, 2)
        img = _disk_image(cu, cv, 1.27, axes=axes, angle=angle)
        v, u = np.indices(img.shape)
        raw.append([(u * img).sum() / img.sum() - cu, (v * img).sum() / img.sum() - cv])
        c, _ = centroid_disk_scurve(img * 1000.0)
        cor.append(c - [cu, cv])
    raw, cor = np.abs(raw), np.abs(cor)
    assert raw.max() > 0.015  # the bias being corrected is real
    assert cor.max() < max_px, cor.max()
    assert np.sqrt(np.mean(cor**2)) < rms_px
    assert np.sqrt(np.mean(cor**2)) < 0.3 * np.sqrt(np.mean(raw**2))


def test_solver_recovers_centre_and_half_width_of_exact_moments():
    """The closed-form-Jacobian solver (scalar and vectorised) inverts the binned moments of the
    sun's disks (half-width 1.2–2.5 px, every pixel phase) to 1e-9 px; both give the same answer."""
    from rigsim.imaging.scurve import binned_moments, solve_axes, solve_axis

    rng = np.random.default_rng(3)
    c = rng.uniform(200.0, 201.0, 400)
    w = rng.uniform(1.2, 2.5, 400)
    mv = np.array([binned_moments(a, b) for a, b in zip(c, w)])
    cv, wv = solve_axes(mv[:, 0], mv[:, 1])
    np.testing.assert_allclose(cv, c, atol=1e-9)
    np.testing.assert_allclose(wv, w, atol=1e-8)
    cs = np.array([solve_axis(a, b) for a, b in mv])
    np.testing.assert_allclose(cs[:, 0], cv, atol=1e-10)
    np.testing.assert_allclose(cs[:, 1], wv, atol=1e-9)
