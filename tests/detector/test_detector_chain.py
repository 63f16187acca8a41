"""The detector chain's edges against hand calculations: added charge, the full-well and top-code flags at
their exact values, the zero clip, MSB-aligned codes, crop windows and their metadata, input checks."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from rigsim.detector import DetectorConfig, apply_detector
from rigsim.detector.model import DetectorFrame


def _cfg(**kw) -> DetectorConfig:
    base = dict(quantum_efficiency=0.5, exposure_s=0.01, full_well_e=10000.0, read_noise_e=0.0,
                dark_current_e_per_s=0.0, dsnu_e=0.0, prnu_frac=0.0, gain_dn_per_e=0.25,
                adc_bits=12, offset_dn=40.0, sensor_seed=7)
    base.update(kw)
    return DetectorConfig(**base)


def test_noiseless_added_charge_adds_electrons():
    cfg = _cfg(dark_current_e_per_s=300.0)   # 3 e- of dark signal
    ph = np.array([[100.0, 2000.0]])
    added = np.array([[50.0, 0.0]])
    f = apply_detector(ph, cfg, noiseless=True, added_e=added)
    # K·(η·ph + dark + added) + offset = 0.25·(50 + 3 + 50) + 40, 0.25·(1000 + 3) + 40
    np.testing.assert_allclose(f.expected_dn, [[65.75, 290.75]], atol=1e-12)


def test_a_pixel_exactly_at_the_full_well_or_the_top_code_is_flagged():
    # full well: η·ph = 0.5·20000 = 10000 e- exactly (the noisy chain flags n >= full well likewise)
    cfg = _cfg()
    f = apply_detector(np.array([[20000.0, 19990.0]]), cfg, noiseless=True)
    assert f.saturated.tolist() == [[True, False]] and f.meta["full_well_pixels"] == 1
    # top code: K·e + offset = 4095 exactly (gain 1, offset 95, 4000 e-), under the well
    cfg = _cfg(gain_dn_per_e=1.0, offset_dn=95.0)
    f = apply_detector(np.array([[8000.0]]), cfg, noiseless=True)
    assert f.dn[0, 0] == 4095 and f.saturated[0, 0] and f.meta["adc_clipped_pixels"] == 1


def test_noiseless_zero_signal_and_zero_offset_reads_zero():
    f = apply_detector(np.zeros((2, 2)), _cfg(offset_dn=0.0), noiseless=True)
    assert np.all(f.dn == 0) and not f.saturated.any()


def test_read_noise_around_a_zero_offset_is_clipped_at_code_zero():
    """No light, no dark, offset 0, gain 1, read noise σ = 2 e-: dn = floor(max(x + 0.5, 0)), x ~ N(0, σ²):
    P(dn = 0) = Φ(0.5/σ) = 0.5987 and no code beyond a few σ."""
    f = apply_detector(np.zeros((256, 256)), _cfg(offset_dn=0.0, gain_dn_per_e=1.0, read_noise_e=2.0), seed=3)
    assert f.dn.max() <= 14
    assert np.mean(f.dn == 0) == pytest.approx(stats.norm.cdf(0.25), abs=0.01)  # SE 0.002


@pytest.mark.parametrize("noiseless", [True, False])
def test_msb_aligned_codes_and_their_expected_dn(noiseless):
    """12-bit codes in 14-bit words: frame DN = code × 4, the top code as all ones (16383); expected_dn in frame DN."""
    cfg = _cfg(container_bits=14, gain_dn_per_e=1.0, offset_dn=10.0)
    ph = np.array([[0.0, 200.0, 1e6]])  # 0, 100 e-, far beyond the top code (the well is 10000 e-)
    f = apply_detector(ph, cfg, noiseless=noiseless, seed=4)
    np.testing.assert_allclose(f.expected_dn, [[40.0, 440.0, 4 * (10000 + 10.0)]], atol=1e-3)
    assert f.dn[0, 2] == 16383 and f.saturated[0, 2]
    if noiseless:
        assert f.dn[0, 0] == 40 and f.dn[0, 1] == 440
    assert np.all(f.dn[0, :2] % 4 == 0)
    assert f.meta["config"]["container_bits"] == 14 and DetectorConfig(**f.meta["config"]) == cfg


def test_meta_config_leaves_out_an_unset_container():
    cfg = _cfg()
    f = apply_detector(np.zeros((2, 2)), cfg, noiseless=True)
    assert "container_bits" not in f.meta["config"] and DetectorConfig(**f.meta["config"]) == cfg


@pytest.mark.parametrize("noiseless", [True, False])
def test_a_crop_window_sees_the_full_frames_fixed_pattern_and_says_where_it_is(noiseless):
    cfg = _cfg(prnu_frac=0.05, dsnu_e=20.0, dark_current_e_per_s=1000.0)
    full = apply_detector(np.full((40, 64), 500.0), cfg, seed=5, noiseless=noiseless)
    u0, v0 = 9, 5  # (u, v): column 9, row 5
    crop = apply_detector(np.full((12, 20), 500.0), cfg, seed=5, noiseless=noiseless, origin_uv=(u0, v0),
                          detector_shape=(40, 64))
    np.testing.assert_array_equal(crop.expected_dn, full.expected_dn[v0:v0 + 12, u0:u0 + 20])
    assert crop.meta["origin_uv"] == [9, 5] and crop.meta["detector_shape"] == [40, 64]
    assert full.meta["origin_uv"] == [0, 0] and full.meta["detector_shape"] == [40, 64]
    # the default window is the detector's corner
    corner = apply_detector(np.full((12, 20), 500.0), cfg, seed=5, noiseless=noiseless, detector_shape=(40, 64))
    np.testing.assert_array_equal(corner.expected_dn, full.expected_dn[:12, :20])


def test_input_checks():
    cfg = _cfg()
    with pytest.raises(ValueError, match="2-D"):
        apply_detector(np.zeros((2, 2, 2)), cfg, seed=0)
    with pytest.raises(ValueError, match=r"finite and >= 0 \(1 pixels"):
        apply_detector(np.array([[1.0, 2.0, 3.0, -0.5]]), cfg, seed=0)
    with pytest.raises(ValueError, match=r"\(1 pixels are not\)"):
        apply_detector(np.array([[np.inf, 1.0]]), cfg, seed=0)
    with pytest.raises(ValueError, match=r"\(2 pixels are not\)"):
        apply_detector(np.array([[np.inf, 0.0, 0.5], [-2.0, 5.0, 1.0]]), cfg, seed=0)
    with pytest.raises(ValueError, match="added_e has shape"):
        apply_detector(np.zeros((3, 3)), cfg, seed=0, added_e=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="added_e has shape"):
        apply_detector(np.zeros((3, 3)), cfg, seed=0, added_e=np.zeros((4, 3)))


def test_an_image_of_another_numeric_kind_is_read_as_float():
    cfg = _cfg()
    a = apply_detector(np.array([[0.0, 100.0, 2000.0]]), cfg, noiseless=True)
    b = apply_detector(np.array([[0, 100, 2000]], dtype=object), cfg, noiseless=True)
    np.testing.assert_array_equal(a.dn, b.dn)
    c = apply_detector(np.array([[0, 100, 2000]], dtype=object), cfg, seed=2)
    np.testing.assert_array_equal(c.dn, apply_detector(np.array([[0.0, 100.0, 2000.0]]), cfg, seed=2).dn)


def test_a_frame_without_an_offset_and_its_repr():
    e = np.array([[1.5, 2.5]], np.float32)
    f = DetectorFrame(np.zeros((1, 2), np.uint16), np.zeros((1, 2), bool), e)
    np.testing.assert_array_equal(f.expected_dn, [[1.5, 2.5]])  # no offset unless given
    assert "_expected" not in repr(f) and "_offset_dn" not in repr(f)  # no image printed
