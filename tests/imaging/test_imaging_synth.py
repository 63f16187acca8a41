"""The synthetic spot generator that all accuracy tests rely on."""

import math

import numpy as np
import pytest
from scipy import integrate

from rigsim.imaging import NoiseModel
from rigsim.imaging.synth import (
    add_noise,
    disk_image,
    flux_for_snr,
    gaussian_frame,
    gaussian_spots,
    pixel_fractions,
    snr_gaussian,
)


def test_pixel_fraction_is_the_integral_over_the_pixel():
    c, s = 3.3, 0.8
    f = pixel_fractions(7, c, s)
    g = lambda x: math.exp(-0.5 * ((x - c) / s) ** 2) / (s * math.sqrt(2 * math.pi))  # noqa: E731
    for i in range(7):
        assert f[i] == pytest.approx(integrate.quad(g, i - 0.5, i + 0.5)[0], abs=1e-12)


def test_gaussian_spot_flux_and_centre():
    img = gaussian_spots((31, 41), 20.37, 14.81, 1000.0, 1.7, background=5.0)
    d = img - 5.0
    assert d.sum() == pytest.approx(1000.0, rel=1e-9)
    vv, uu = np.mgrid[0:31, 0:41]
    assert (d * uu).sum() / d.sum() == pytest.approx(20.37, abs=1e-9)
    assert (d * vv).sum() / d.sum() == pytest.approx(14.81, abs=1e-9)
    stack = gaussian_spots((9, 9), np.array([4.0, 4.5]), 4.0, np.array([1.0, 2.0]), 1.0)
    assert stack.shape == (2, 9, 9)


def test_gaussian_frame_places_spots():
    img = gaussian_frame((50, 60), [10.0, 45.2], [20.0, 30.7], [100.0, 200.0], 1.0)
    assert img.sum() == pytest.approx(300.0, rel=1e-6)
    assert np.unravel_index(np.argmax(img), img.shape) == (31, 45)


def test_disk_area_and_centre():
    img = disk_image((60, 60), 29.3, 30.6, 15.0, 1.0, 0.0, supersample=16)
    assert img.sum() == pytest.approx(math.pi * 15.0**2, rel=2e-3)
    vv, uu = np.mgrid[0:60, 0:60]
    assert (img * uu).sum() / img.sum() == pytest.approx(29.3, abs=2e-3)


def test_snr_definition_round_trip():
    for snr in (5.0, 30.0, 300.0):
        f = flux_for_snr(snr, 20.0, 5.0, 1.0)
        assert snr_gaussian(f, 20.0, 5.0, 1.0) == pytest.approx(snr, rel=1e-12)


def test_noise_statistics_and_seeding():
    nm = NoiseModel(gain_dn_per_e=0.5, read_noise_e=4.0, offset_dn=64.0)
    exp = np.full((200, 200), 114.0)  # DN: 50 DN of signal above the 64 DN offset
    a = add_noise(exp, nm, np.random.default_rng(1))
    b = add_noise(exp, nm, np.random.default_rng(1))
    assert np.array_equal(a, b)
    var = float(nm.variance(np.array(114.0)))
    assert var == pytest.approx(0.5 * 50.0 + (0.5 * 4.0) ** 2)
    assert a.mean() == pytest.approx(114.0, abs=5 * math.sqrt(var / a.size))
    assert a.var() == pytest.approx(var, rel=0.03)
    with pytest.raises(TypeError):
        add_noise(exp, nm, 1)
    s = add_noise(exp * 100, nm, np.random.default_rng(2), saturation_dn=5000.0)
    assert s.max() == 5000.0
