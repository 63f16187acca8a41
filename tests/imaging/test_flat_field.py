"""The aiming camera's flat field: frames of the screen lit evenly by a lamp divide the returned spot,
so a grain in the screen's albedo no longer pulls the spot's centroid.

The truth is made here without the code under test: a uniform disk of known centre on a screen whose
albedo is a smoothed random field (contrast 5 %), a glowing hole, room light with a gradient, and
Poisson noise; the centroid is the plain value-weighted mean of the pixels above 10 % of the peak."""

import numpy as np
import pytest

from rigsim.imaging.screen import FLAT_MIN_LEVEL, apply_flat, flat_field

H, W = 200, 240
V, U = np.mgrid[0:H, 0:W].astype(float)
HOLE = np.hypot(U - 120.0, V - 100.0) < 12.0
OFFSET = 64.0


def _albedo(seed=1, contrast=0.05):
    import cv2

    z = cv2.GaussianBlur(np.random.default_rng(seed).normal(size=(H, W)).astype(np.float32), (0, 0), 3.0)
    return 1.0 + contrast * (z - z.mean()) / z.std()


def _centroid(img):
    w = np.where(img > 0.1 * img.max(), img, 0.0)
    return np.array([(w * U).sum(), (w * V).sum()]) / w.sum()


def _frames(seed, albedo, centre=(131.3, 94.6), radius=40.0):
    rng = np.random.default_rng(seed)
    room = 300.0 * (1.0 + 0.002 * U) * albedo * ~HOLE
    glow = 2000.0 * HOLE
    spot_e = 8000.0 * (np.hypot(U - centre[0], V - centre[1]) < radius) * albedo * ~HOLE
    lamp = 15000.0 * albedo * ~HOLE
    hole = OFFSET + rng.poisson(room + glow).astype(float)
    spot = OFFSET + rng.poisson(room + glow + spot_e).astype(float)
    flats = [OFFSET + rng.poisson(room + lamp).astype(float) for _ in range(16)]
    return hole, spot, flats, np.asarray(centre)


def test_the_flat_is_the_albedo_and_leaves_the_hole_out():
    """Less the hole frame (its room light), over its median: the albedo to the flat's shot noise
    (1/√(16·15000) = 0.2 %), NaN in the hole, which the lamp leaves dark."""
    a = _albedo()
    hole, _, flats, _ = _frames(3, a)
    f = flat_field(flats, hole)
    assert np.all(np.isnan(f[HOLE])) and np.all(np.isfinite(f[~HOLE]))
    ratio = f[~HOLE] / a[~HOLE]
    assert np.std(ratio / np.median(ratio)) < 0.004
    assert np.nanmin(f) >= FLAT_MIN_LEVEL


def test_the_flat_removes_the_grain_s_pull_on_the_spot():
    """Ten noise seeds: the grain pulls the plain centroid by a few hundredths of a pixel; divided by
    the flat it is within the noise of the centroid on a uniform screen (paired, same seeds)."""
    a, one = _albedo(), np.ones((H, W))
    pull, flat_pull = [], []
    for seed in range(10):
        hole, spot, flats, c = _frames(seed, a)
        hole1, spot1, _, _ = _frames(seed, one)
        ideal = _centroid(spot1 - hole1)
        pull.append(_centroid(spot - hole) - ideal)
        flat_pull.append(_centroid(apply_flat(hole, spot, flat_field(flats, hole)) - hole) - ideal)
    pull, flat_pull = np.array(pull), np.array(flat_pull)
    print("grain pull", np.abs(pull).mean(axis=0), "with the flat", np.abs(flat_pull).mean(axis=0))
    assert np.abs(pull.mean(axis=0)).max() > 0.02
    assert np.abs(flat_pull.mean(axis=0)).max() < 0.2 * np.abs(pull.mean(axis=0)).max()


def test_an_unlit_flat_is_refused():
    hole, _, _, _ = _frames(0, np.ones((H, W)))
    with pytest.raises(ValueError, match="the screen is not lit"):
        flat_field([hole], hole)
