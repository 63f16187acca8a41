"""The visible divergent return on the diaphragm screen (rigsim.optics.screen_return) against closed forms."""

import math

import numpy as np
import pytest

from rigsim.optics.screen_return import disk_overlap_area, hole_pull_gain, visible_return_centre_mm


def test_disk_overlap_area_limits_and_a_monte_carlo_value():
    assert disk_overlap_area(0.0, 1.0, 3.0) == pytest.approx(math.pi)
    assert disk_overlap_area(4.0, 1.0, 3.0) == 0.0
    # two unit disks one radius apart: 2π/3 − √3/2 (the classic lens)
    assert disk_overlap_area(1.0, 1.0, 1.0) == pytest.approx(2 * math.pi / 3 - math.sqrt(3) / 2, rel=1e-12)
    rng = np.random.default_rng(1)
    p = rng.uniform(-2, 2, (2_000_000, 2))
    inside = (np.hypot(*p.T) < 1.5) & (np.hypot(p[:, 0] - 1.2, p[:, 1]) < 0.8)
    assert disk_overlap_area(1.2, 1.5, 0.8) == pytest.approx(16 * inside.mean(), rel=5e-3)


def test_a_blur_much_wider_than_the_hole_gives_the_uniform_disk_pull():
    """A uniform disk of radius R with a hole of radius r cut at a distance d from its centre: the rest's
    centroid is at d / (1 − (r/R)²) (the lens profile's plateau is flat out to R − r)."""
    for r, R in ((1.0, 10.0), (1.25, 6.0)):
        assert hole_pull_gain(r, R) == pytest.approx(1 / (1 - (r / R) ** 2), rel=2e-3 if R / r > 8 else 0.02)


def test_the_pull_grows_as_the_blur_shrinks_to_the_hole_and_vanishes_at_the_null():
    gains = [hole_pull_gain(1.0, R) for R in (8.0, 4.0, 2.0, 1.2, 1.0)]
    assert all(a < b for a, b in zip(gains, gains[1:])) and gains[-1] > 1.8
    assert np.allclose(visible_return_centre_mm([0.0, 0.0], 1.0, 1.2), 0.0, atol=1e-9)
    c = visible_return_centre_mm([0.0, -0.03], 1.762, 1.840)  # a random rig's: measured on its rendered frame
    assert c[0] == pytest.approx(0.0, abs=1e-9) and c[1] / -0.03 == pytest.approx(1.92, abs=0.02)
