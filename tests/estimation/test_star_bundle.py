"""Intrinsics and attitudes from identified stars alone (rigsim.estimation.star_bundle).

The stars' pixels are made here by OpenCV's cv2.projectPoints (not rigsim's camera model) from
Hipparcos directions and random attitudes, with centroid noise of a known σ and a hidden extra
scatter (the "floor" the fit must find from the residuals)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rigsim.estimation.star_bundle import bundle_adjust, held_out_check
from rigsim.estimation.star_calibration import FrameObs
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.sky import SkyCatalogue

W, H = 1024, 768
TRUE = dict(f=5114.3, u0=518.2, v0=390.4, k1=0.10, k2=0.0)
NOMINAL = PinholeBrown(5072.5, 5072.5, (W - 1) / 2, (H - 1) / 2, width=W, height=H)
PRIOR = {"f": 250.0, "u0": 50.0, "v0": 50.0}


@pytest.fixture(scope="module")
def sky():
    return SkyCatalogue.load(8.5, 2019.6)


def _frames(sky, rng, n_frames=6, sigma=0.05, floor=0.07):
    K = np.array([[TRUE["f"], 0, TRUE["u0"]], [0, TRUE["f"], TRUE["v0"]], [0, 0, 1.0]])
    dist = np.array([TRUE["k1"], TRUE["k2"], 0, 0, 0], float)
    frames, R_true, R_start = [], [], []
    while len(frames) < n_frames:
        R = Rotation.random(random_state=rng).as_matrix()
        d = sky.vectors @ R.T
        front = d[:, 2] > 0.99
        uv, _ = cv2.projectPoints(d[front], np.zeros(3), np.zeros(3), K, dist)
        uv = uv.reshape(-1, 2)
        on = (uv[:, 0] > 5) & (uv[:, 0] < W - 6) & (uv[:, 1] > 5) & (uv[:, 1] < H - 6)
        if on.sum() < 25:
            continue
        s = np.full((on.sum(), 2), sigma) * rng.uniform(0.5, 2.0, (on.sum(), 1))
        meas = uv[on] + rng.normal(0, 1, s.shape) * np.sqrt(s**2 + floor**2)
        frames.append(FrameObs(meas, s, sky.vectors[front][on]))
        R_true.append(R)
        R_start.append(Rotation.from_rotvec(rng.normal(0, 2e-3, 3)).as_matrix() @ R)  # a coarse identification
    return frames, R_true, R_start


def test_intrinsics_attitudes_and_the_noise_floor_come_back_within_their_sigma(sky):
    pulls, floors = [], []
    for seed in range(5):
        rng = np.random.default_rng(seed)
        frames, R_true, R_start = _frames(sky, rng)
        b = bundle_adjust(frames, NOMINAL, R_start, estimate=("f", "u0", "v0", "k1"), prior_sigma=PRIOR)
        assert b.success
        truth = np.array([TRUE[n] for n in b.names])
        pulls.append((b.x - truth) / b.sigma)
        floors.append(b.sigma_floor_px)
        assert 0.85 < b.chi2_reduced < 1.15
        assert b.chi2_reduced_model > 1.5  # the centroider's σ alone do not explain the scatter
        for R, Rt, C in zip(b.R, R_true, b.R_cov):
            err = Rotation.from_matrix(R @ Rt.T).as_rotvec()
            assert np.all(np.abs(err) < 5 * np.sqrt(np.diag(C)) + 1e-9)
    pulls = np.array(pulls)
    assert np.all(np.abs(pulls) < 4), pulls
    assert np.sqrt(np.mean(pulls**2)) < 1.6, pulls
    assert abs(np.mean(floors) - 0.07) < 0.01, floors


def test_the_floor_is_zero_when_the_centroid_sigma_explain_the_data(sky):
    rng = np.random.default_rng(7)
    frames, _, R_start = _frames(sky, rng, floor=0.0)
    b = bundle_adjust(frames, NOMINAL, R_start, estimate=("f", "u0", "v0", "k1"), prior_sigma=PRIOR)
    assert b.sigma_floor_px == 0.0
    assert abs(b.chi2_reduced - 1) < 0.2


def test_a_wrong_match_is_rejected(sky):
    rng = np.random.default_rng(3)
    frames, _, R_start = _frames(sky, rng)
    fo = frames[0]
    dirs = fo.dirs_icrs.copy()
    dirs[[0, 1]] = dirs[[1, 0]]  # two stars swapped: both residuals far beyond 5σ
    frames[0] = FrameObs(fo.uv, fo.sigma_uv, dirs)
    b = bundle_adjust(frames, NOMINAL, R_start, estimate=("f", "u0", "v0", "k1"), prior_sigma=PRIOR)
    assert not b.used[0][0] and not b.used[0][1]
    assert b.n_rejected == 2
    assert abs(b.theta[0] - TRUE["f"]) < 4 * b.sigma[0]


def test_held_out_frames_are_predicted_to_their_sigma(sky):
    rng = np.random.default_rng(5)
    frames, _, R_start = _frames(sky, rng, n_frames=5)
    ho = held_out_check(frames, NOMINAL, R_start, estimate=("f", "u0", "v0", "k1"), prior_sigma=PRIOR)
    assert len(ho) == 5
    z = np.array([h.z_rms for h in ho])
    assert np.all((z > 0.75) & (z < 1.3)), z
    rms = np.array([h.rms_px for h in ho])
    assert np.all(rms < 0.2)


def test_nothing_to_fit_is_said_not_raised():
    b = bundle_adjust([FrameObs(np.zeros((2, 2)), np.ones((2, 2)), np.eye(3)[:2])], NOMINAL, [np.eye(3)])
    assert not b.success and "3 identified stars" in b.message
    with pytest.raises(ValueError, match="estimate"):
        bundle_adjust([], NOMINAL, [], estimate=("fx",))
