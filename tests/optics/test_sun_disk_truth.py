"""spot_truth's quadrature is its definition: the flux-weighted moments of disk_directions projected
with PinholeBrown.project_valid, to the last bit (it only lays the points out column by column)."""

import math

import numpy as np
import pytest

from rigsim.optics.camera import PinholeBrown
from rigsim.optics.sun_disk import disk_directions, spot_truth

CAM = PinholeBrown(fx=272.7, fy=272.8, cx=511.2, cy=512.9, width=1024, height=1024,
                   k1=-0.12, k2=0.011, k3=-0.0004, p1=2e-4, p2=-1e-4)
ANGLE = math.radians(32 / 60)


def _by_definition(s, n, response):
    d = disk_directions(s, ANGLE, n)
    uv, valid = CAM.project_valid(d)
    if response == "flux":
        w = d[:, 2].copy()
    else:
        x, y = d[:, 0] / d[:, 2], d[:, 1] / d[:, 2]
        a, b, c, dd = CAM.distort_jacobian(x, y)
        w = (a * dd - b * c) / d[:, 2] ** 3
    return valid.all(), (w[:, None] * uv).sum(axis=0) / w.sum(), (w[:, None] * np.floor(uv + 0.5)).sum(axis=0) / w.sum(), w.sum() / n


@pytest.mark.parametrize("response", ["flux", "radiance"])
def test_spot_truth_is_its_definition_bit_for_bit(response):
    rng = np.random.default_rng(7)
    for k in range(12):
        s = np.array([*rng.uniform(-0.8, 0.8, 2), 1.0])
        n = (200_000, 40_001)[k % 2]
        got = spot_truth(CAM, s, ANGLE, n=n, response=response)
        ok, mean, pix, flux = _by_definition(s, n, response)
        assert got["valid"] and ok
        assert got["mean_uv"] == mean.tolist() and got["pixel_centroid_uv"] == pix.tolist()
        assert got["relative_flux"] == flux


def test_spot_truth_outside_the_model_is_invalid():
    assert spot_truth(CAM, [0.0, 0.0, -1.0], ANGLE, n=1000) == {"valid": False, "center_uv": None}
    far = spot_truth(CAM, [math.sin(1.4), 0.0, math.cos(1.4)], ANGLE, n=1000)  # beyond the model's fold
    assert far["valid"] is False
