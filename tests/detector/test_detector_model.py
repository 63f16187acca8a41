"""EMVA 1288 detector model: photon transfer, SNR, saturation, seeds, fixed patterns, validation.

Statistical tolerances: a variance estimated from N independent pixels has relative standard
error sqrt(2/(N-1)); tests use >= 4 of those standard errors.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from rigsim.detector import DetectorConfig, apply_detector, emva, fixed_pattern

N_SIDE = 256  # 65,536 pixels per flat field
REL_VAR_SE = math.sqrt(2.0 / (N_SIDE * N_SIDE - 1))


def _cfg(**kw) -> DetectorConfig:
    base = dict(quantum_efficiency=0.55, exposure_s=0.02, full_well_e=30000.0, read_noise_e=6.0,
                dark_current_e_per_s=150.0, dsnu_e=4.0, prnu_frac=0.01, gain_dn_per_e=0.12,
                adc_bits=14, offset_dn=100.0, sensor_seed=1234)
    base.update(kw)
    return DetectorConfig(**base)


def _pair_stats(cfg, mu_p, seed):
    """Mean DN and temporal variance from two frames (difference method removes fixed patterns)."""
    ph = np.full((N_SIDE, N_SIDE), float(mu_p))
    a = apply_detector(ph, cfg, seed=seed).dn.astype(np.float64)
    b = apply_detector(ph, cfg, seed=seed + 1).dn.astype(np.float64)
    return 0.5 * (a.mean() + b.mean()), np.var(a - b, ddof=1) / 2.0


def test_photon_transfer_slope_is_the_gain():
    cfg = _cfg()
    mu_dark, var_dark = _pair_stats(cfg, 0.0, seed=10)
    levels = [2000.0, 8000.0, 16000.0, 30000.0, 45000.0]   # up to ~80 % of the full well
    means, vars_ = [], []
    for i, mu_p in enumerate(levels):
        m, v = _pair_stats(cfg, mu_p, seed=100 + 2 * i)
        means.append(m - mu_dark)
        vars_.append(v - var_dark)
    slope, _ = np.polyfit(means, vars_, 1)
    # slope error: each variance point has ~REL_VAR_SE relative error; the fit averages 5 points
    assert slope == pytest.approx(cfg.gain_dn_per_e, rel=4 * REL_VAR_SE * 1.5)
    # dark temporal variance: K^2 (read^2 + mu_d) + 1/12
    pred_dark = emva.temporal_variance_dn2(cfg, 0.0)
    assert var_dark == pytest.approx(pred_dark, rel=5 * REL_VAR_SE)
    # responsivity: mean DN above dark = K * eta * mu_p (PRNU averages out: 1 % / sqrt(65536))
    for m, mu_p in zip(means, levels):
        assert m == pytest.approx(cfg.gain_dn_per_e * cfg.quantum_efficiency * mu_p, rel=1e-3)


@pytest.mark.parametrize("mu_p", [50.0, 500.0, 5000.0, 40000.0])
def test_temporal_snr_matches_emva_formula(mu_p):
    cfg = _cfg()
    mu_dark, _ = _pair_stats(cfg, 0.0, seed=7)
    m, v = _pair_stats(cfg, mu_p, seed=20)
    snr_meas = (m - mu_dark) / math.sqrt(v)
    snr_pred = float(emva.snr(cfg, mu_p))
    # relative error of SNR = half the variance's, plus the dark-mean error at low signal
    tol = 4 * 0.5 * REL_VAR_SE + 4 * math.sqrt(v / (N_SIDE * N_SIDE)) / max(m - mu_dark, 1e-9)
    assert snr_meas == pytest.approx(snr_pred, rel=tol)


def test_total_snr_includes_fixed_pattern():
    cfg = _cfg(prnu_frac=0.03, dsnu_e=20.0)
    mu_p = 20000.0
    img = apply_detector(np.full((N_SIDE, N_SIDE), mu_p), cfg, seed=3).dn.astype(np.float64)
    dark = apply_detector(np.zeros((N_SIDE, N_SIDE)), cfg, seed=4).dn.astype(np.float64)
    snr_meas = (img.mean() - dark.mean()) / img.std(ddof=1)
    assert snr_meas == pytest.approx(float(emva.total_snr(cfg, mu_p)), rel=4 * 0.5 * REL_VAR_SE + 0.01)
    # and PRNU makes it clearly worse than the temporal SNR
    assert snr_meas < 0.8 * float(emva.snr(cfg, mu_p))


def test_same_seed_same_frame_different_seed_different_frame():
    cfg = _cfg()
    rng = np.random.default_rng(42)
    ph = rng.uniform(0.0, 5000.0, size=(64, 80))
    a = apply_detector(ph, cfg, seed=5)
    b = apply_detector(ph, cfg, seed=5)
    c = apply_detector(ph, cfg, seed=6)
    assert a.dn.dtype == np.uint16 and a.dn.shape == (64, 80)
    np.testing.assert_array_equal(a.dn, b.dn)
    assert np.mean(a.dn != c.dn) > 0.5


def test_seed_is_required_unless_noiseless():
    with pytest.raises(ValueError, match="seed"):
        apply_detector(np.zeros((4, 4)), _cfg())
    apply_detector(np.zeros((4, 4)), _cfg(), noiseless=True)


def test_fixed_pattern_stays_fixed_across_frames_and_windows():
    cfg = _cfg(prnu_frac=0.05, dsnu_e=10.0)
    g1, d1 = fixed_pattern(cfg, (128, 160))
    g2, d2 = fixed_pattern(cfg, (128, 160))
    np.testing.assert_array_equal(g1, g2)
    np.testing.assert_array_equal(d1, d2)
    assert np.std(g1) == pytest.approx(0.05, rel=0.05)    # 20,480 px: rel SE 0.5 %
    assert np.std(d1) == pytest.approx(10.0, rel=0.05)
    # a crop window sees the same pixels' pattern as the full frame, including off-detector parts
    gw, dw = fixed_pattern(cfg, (128, 160), origin_uv=(150, -3), shape=(16, 16))
    np.testing.assert_array_equal(gw[3:, :10], g1[0:13, 150:160])
    assert np.all(gw[:3] == 1.0) and np.all(dw[:, 10:] == 0.0)
    # another detector instance has another pattern
    g3, _ = fixed_pattern(_cfg(prnu_frac=0.05, sensor_seed=99), (128, 160))
    assert abs(np.corrcoef(g1.ravel(), g3.ravel())[0, 1]) < 0.05
    # the mean over many frames converges to the fixed pattern, not to a flat field
    ph = np.full((128, 160), 20000.0)
    mean = np.mean([apply_detector(ph, cfg, seed=s).dn.astype(np.float64) for s in range(8)],
                   axis=0)
    expected = apply_detector(ph, cfg, seed=0).expected_dn
    assert np.corrcoef(mean.ravel(), expected.ravel())[0, 1] > 0.95


def test_noiseless_is_the_deterministic_chain():
    cfg = _cfg()
    ph = np.array([[0.0, 10.0, 1234.5], [20000.0, 5e4, 1e9]])
    f = apply_detector(ph, cfg, noiseless=True)
    e = np.minimum(cfg.quantum_efficiency * ph + cfg.dark_mean_e, cfg.full_well_e)
    y = cfg.gain_dn_per_e * e + cfg.offset_dn
    np.testing.assert_allclose(f.expected_dn, y, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(f.dn, np.clip(np.floor(y + 0.5), 0, cfg.max_dn).astype(np.uint16))
    np.testing.assert_array_equal(f.saturated, [[False, False, False], [False, False, True]])


def test_full_well_saturation_is_flagged():
    cfg = _cfg(full_well_e=10000.0, gain_dn_per_e=0.5, adc_bits=16)
    ph = np.zeros((32, 32))
    ph[10:14, 10:14] = 1e6                      # 550,000 e- expected: deep saturation
    f = apply_detector(ph, cfg, seed=1)
    top = cfg.gain_dn_per_e * cfg.full_well_e + cfg.offset_dn
    # saturated pixels sit at full well plus read noise only (6 e- rms -> 3 DN rms)
    assert np.all(np.abs(f.dn[10:14, 10:14].astype(float) - top) < 6 * 0.5 * cfg.read_noise_e + 1)
    assert f.saturated[10:14, 10:14].all() and f.saturated_pixels == 16
    assert f.meta["full_well_pixels"] == 16 and f.meta["adc_clipped_pixels"] == 0


def test_adc_clips_at_top_code():
    cfg = _cfg(full_well_e=1e6, gain_dn_per_e=1.0, adc_bits=10, offset_dn=10.0)
    ph = np.full((8, 8), 1e5)                   # 55,000 e- -> 55,010 DN >> 1023
    f = apply_detector(ph, cfg, seed=2)
    assert np.all(f.dn == 1023) and f.saturated.all()
    assert f.meta["adc_clipped_pixels"] == 64 and f.meta["full_well_pixels"] == 0


def test_dark_frame_statistics():
    cfg = _cfg(dsnu_e=0.0, prnu_frac=0.0)
    f = apply_detector(np.zeros((N_SIDE, N_SIDE)), cfg, seed=11)
    d = f.dn.astype(np.float64)
    assert d.mean() == pytest.approx(float(emva.mean_dn(cfg, 0.0)), abs=4 * d.std() / N_SIDE + 0.01)
    assert d.var() == pytest.approx(float(emva.temporal_variance_dn2(cfg, 0.0)), rel=5 * REL_VAR_SE)


@pytest.mark.parametrize("field,value,msg", [
    ("quantum_efficiency", 1.5, "quantum_efficiency"),
    ("quantum_efficiency", 0.0, "quantum_efficiency"),
    ("adc_bits", 17, "adc_bits"),
    ("gain_dn_per_e", -0.1, "gain_dn_per_e"),
    ("read_noise_e", -1.0, "read_noise_e"),
    ("qe", 0.5, "qe"),                       # unknown field: extra='forbid'
])
def test_config_rejects_bad_values_naming_the_field(field, value, msg):
    with pytest.raises(ValidationError) as exc:
        _cfg(**{field: value})
    assert msg in str(exc.value)
    assert str(value) in str(exc.value)


def test_input_validation():
    cfg = _cfg()
    with pytest.raises(ValueError, match="2-D"):
        apply_detector(np.zeros(5), cfg, seed=0)
    with pytest.raises(ValueError, match="finite"):
        apply_detector(np.array([[1.0, -2.0]]), cfg, seed=0)
    with pytest.raises(ValueError, match="finite"):
        apply_detector(np.array([[np.nan]]), cfg, seed=0)


def test_emva_derived_quantities_consistent():
    cfg = _cfg()
    mu_sat = emva.saturation_photons(cfg)
    # the ADC top (16383 DN) is reached at (16383-100)/0.12 = 135,692 e- > full well 30,000 e-
    assert mu_sat == pytest.approx((30000.0 - cfg.dark_mean_e) / cfg.quantum_efficiency)
    mu_min = emva.absolute_sensitivity_threshold_photons(cfg)
    # at mu_min the SNR is 1 by definition (EMVA approximation: exact within a few %)
    assert float(emva.snr(cfg, mu_min)) == pytest.approx(1.0, rel=0.05)
    assert emva.dynamic_range_db(cfg) == pytest.approx(20 * math.log10(mu_sat / mu_min))
