"""Fixed patterns drawn per pixel from (sensor_seed, pixel index): windows, statistics, determinism.

Statistical tolerances: a mean of N unit normals has standard error 1/sqrt(N), a standard deviation
sqrt(1/(2N)), a correlation coefficient 1/sqrt(N); tests use 5 of those standard errors.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from scipy import stats

from rigsim.detector import DetectorConfig, apply_detector, fixed_pattern
from rigsim.detector.pattern import pattern_normals

H, W = 480, 640


def _cfg(**kw) -> DetectorConfig:
    base = {"prnu_frac": 0.02, "dsnu_e": 3.0, "dark_current_e_per_s": 400.0, "exposure_s": 0.01, "sensor_seed": 77}
    base.update(kw)
    return DetectorConfig(**base)


@pytest.mark.parametrize("origin,shape", [((0, 0), (H, W)), ((100, 37), (64, 96)), ((-5, -7), (20, 30)),
                                          ((W - 10, H - 4), (16, 16)), ((3, 200), (1, 1)), ((W + 2, 0), (8, 8))])
def test_window_sees_the_full_frame_pattern(origin, shape):
    cfg = _cfg()
    g_full, d_full = fixed_pattern(cfg, (H, W))
    g, d = fixed_pattern(cfg, (H, W), origin_uv=origin, shape=shape)
    u0, v0 = origin
    vv, uu = np.mgrid[v0:v0 + shape[0], u0:u0 + shape[1]]
    on = (uu >= 0) & (uu < W) & (vv >= 0) & (vv < H)
    np.testing.assert_array_equal(g[on], g_full[vv[on], uu[on]])
    np.testing.assert_array_equal(d[on], d_full[vv[on], uu[on]])
    assert np.all(g[~on] == 1.0) and np.all(d[~on] == 0.0)


def test_window_frame_expected_dn_equals_the_full_frames():
    """Through apply_detector: the noise-free mean of a window (fixed patterns included) is the full frame's."""
    cfg = _cfg()
    ph = np.random.default_rng(3).uniform(0, 2000, (H, W))
    full = apply_detector(ph, cfg, seed=1)
    u0, v0, h, w = 211, 95, 70, 50
    win = apply_detector(ph[v0:v0 + h, u0:u0 + w], cfg, seed=2, origin_uv=(u0, v0), detector_shape=(H, W))
    np.testing.assert_array_equal(win.expected_dn, full.expected_dn[v0:v0 + h, u0:u0 + w])


def test_pattern_statistics():
    z1, z2 = (z.astype(np.float64) for z in pattern_normals(5, 1024, (0, 512), (0, 1024)))
    n = z1.size
    for z in (z1, z2):
        assert abs(z.mean()) < 5 / math.sqrt(n)
        assert z.std() == pytest.approx(1.0, abs=5 * math.sqrt(1 / (2 * n)))
        assert stats.kstest(z.ravel()[::7], "norm").pvalue > 1e-3
        # no row/column structure: neighbours uncorrelated, row and column means scatter as 1/sqrt(N)
        for a, b in ((z[:, 1:], z[:, :-1]), (z[1:, :], z[:-1, :])):
            assert abs(np.corrcoef(a.ravel(), b.ravel())[0, 1]) < 5 / math.sqrt(a.size)
        rows, cols = z.mean(axis=1), z.mean(axis=0)
        assert rows.std() * math.sqrt(z.shape[1]) == pytest.approx(1.0, abs=5 * math.sqrt(1 / (2 * rows.size)))
        assert cols.std() * math.sqrt(z.shape[0]) == pytest.approx(1.0, abs=5 * math.sqrt(1 / (2 * cols.size)))
    # PRNU and DSNU independent of each other
    assert abs(np.corrcoef(z1.ravel(), z2.ravel())[0, 1]) < 5 / math.sqrt(n)
    assert abs(np.corrcoef(z1.ravel() ** 2, z2.ravel() ** 2)[0, 1]) < 5 * math.sqrt(2) / math.sqrt(n)


def test_configured_rms_and_seed_dependence():
    cfg = _cfg()
    g, d = fixed_pattern(cfg, (H, W))
    n = g.size
    assert np.std(g) == pytest.approx(cfg.prnu_frac, rel=5 * math.sqrt(1 / (2 * n)))
    assert np.std(d) == pytest.approx(cfg.dsnu_e, rel=5 * math.sqrt(1 / (2 * n)))
    assert abs(np.mean(g) - 1) < 5 * cfg.prnu_frac / math.sqrt(n)
    g2, _ = fixed_pattern(_cfg(sensor_seed=78), (H, W))
    assert abs(np.corrcoef(g.ravel(), g2.ravel())[0, 1]) < 5 / math.sqrt(n)
    # a detector of another width numbers its pixels differently: another pattern
    g3, _ = fixed_pattern(cfg, (H, W + 1))
    assert abs(np.corrcoef(g[:, :W].ravel(), g3[:, :W].ravel())[0, 1]) < 5 / math.sqrt(n)


def test_same_seed_same_frame_in_threads():
    cfg = _cfg()
    ph = np.random.default_rng(0).uniform(0, 5e4, (300, 200))
    ph[::3] = 0.3
    ref = apply_detector(ph, cfg, seed=12)
    with ThreadPoolExecutor(4) as ex:
        outs = list(ex.map(lambda s: apply_detector(ph, cfg, seed=s), [12] * 6))
    for f in outs:
        np.testing.assert_array_equal(f.dn, ref.dn)
        np.testing.assert_array_equal(f.saturated, ref.saturated)
        np.testing.assert_array_equal(f.expected_dn, ref.expected_dn)
