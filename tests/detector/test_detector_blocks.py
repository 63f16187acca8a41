"""The noisy chain's frame does not depend on how it is cut into blocks, nor on the thread that
runs it: the block size is a speed setting, never part of the random stream."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from rigsim.detector import DetectorConfig, apply_detector, model


def _spot(h, w, amp=3e5):
    v = np.arange(h)[:, None] - h / 3.0
    u = np.arange(w)[None, :] - w / 2.0
    s = w / 40.0
    return amp * np.exp(-v * v / (2 * s * s)) * np.exp(-u * u / (2 * s * s))


def _frame(ph, seed, **kw):
    f = apply_detector(ph, DetectorConfig(), seed=seed, **kw)
    return f.dn, f.saturated, f.expected_dn


@pytest.mark.parametrize("shape", [(512, 700), (257, 255), (3, 5)])
def test_frame_is_the_same_for_any_block_size(monkeypatch, shape):
    # odd sizes put a short run of read-noise pairs at the end; a bright spot mixes the exact
    # walk (small λ) and the Cornish–Fisher quantile (large λ) inside one block
    ph = _spot(*shape) + 2.0
    added = np.random.default_rng(1).random(shape) * 3.0
    frames = []
    for chunk in (model._PAIR, 4 * model._PAIR, 16 * model._PAIR):
        monkeypatch.setattr(model, "_CHUNK", chunk)
        frames.append(_frame(ph, 7, added_e=added))
    for f in frames[1:]:
        for a, b in zip(frames[0], f):
            np.testing.assert_array_equal(a, b)
    assert frames[0][0].std() > 1.0  # noise present: the comparison is not of two constant frames


def test_frames_are_the_same_from_concurrent_threads():
    ph = _spot(640, 640)
    ref = [_frame(ph, s) for s in range(4)]
    got = {}

    def run(s):
        got[s] = _frame(ph, s)

    threads = [threading.Thread(target=run, args=(s,)) for s in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for s in range(4):
        for a, b in zip(ref[s], got[s]):
            np.testing.assert_array_equal(a, b)
    assert not np.array_equal(ref[0][0], ref[1][0])


def test_expected_dn_is_float64_gain_times_electrons_plus_offset():
    cfg = DetectorConfig()
    ph = _spot(64, 64, amp=2e3)
    f = apply_detector(ph, cfg, seed=3)
    e = apply_detector(ph, cfg, noiseless=True).expected_dn  # no fixed patterns: compare loosely
    assert f.expected_dn.dtype == np.float64
    assert f.expected_dn is f.expected_dn                    # built once
    # PRNU 0.5 % and DSNU 1 e- (0.2 DN) are the only differences from the noiseless mean
    assert np.abs(f.expected_dn - e).max() < 0.006 * e.max() + 6 * cfg.dsnu_e * cfg.gain_dn_per_e
    assert np.abs(f.expected_dn - e).max() > 0.0
