"""A camera that writes its ADC's codes MSB-aligned into wider words (``container_bits``: a 12-bit ADC in
16-bit words writes code × 16, a saturated pixel as 65535, as the FLIR Blackfly S does in Mono16):
the rendered DN against closed forms written out here (not the model's own code), and the pipeline's
noise model, saturation level and detection threshold in those units.

Closed forms (EMVA 1288 linear camera, codes c = round(K·n + offset), frame DN y = s·c with s = 2^(16−12)):
    E[y]   = s·(K·(η·μp + μd) + offset)
    Var[y] = s²·(K²·(R² + μd + η·μp) + 1/12)      (1/12: the ADC's quantisation, Sheppard, K·σ ≫ 1)
A variance from N pixels has relative standard error √(2/(N−1)); the tolerances are 5 of them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from rigsim.detector import DetectorConfig, apply_detector
from rigsim.imaging import NoiseModel
from rigsim.imaging.frame_spots import default_threshold_dn

N_SIDE = 384
REL_VAR_SE = math.sqrt(2.0 / (N_SIDE * N_SIDE - 1))
STEP = 16  # 2^(16 − 12)


def _cfg(**kw) -> DetectorConfig:
    base = dict(quantum_efficiency=0.6, exposure_s=0.5, full_well_e=12000.0, read_noise_e=4.0, dark_current_e_per_s=20.0,
                dsnu_e=0.0, prnu_frac=0.0, gain_dn_per_e=0.33, adc_bits=12, offset_dn=60.0, container_bits=16,
                sensor_seed=3)
    base.update(kw)
    return DetectorConfig(**base)


@pytest.mark.parametrize("mu_p", [0.0, 400.0, 6000.0])
def test_frames_of_a_12_bit_adc_in_16_bit_words_have_the_closed_form_mean_variance_and_grid(mu_p):
    cfg = _cfg()
    eta, K, R, mu_d, off = 0.6, 0.33, 4.0, 20.0 * 0.5, 60.0
    y = apply_detector(np.full((N_SIDE, N_SIDE), mu_p), cfg, seed=11).dn.astype(np.int64)
    assert np.all(y % STEP == 0)                                        # the value grid: multiples of 16
    assert len(np.unique(y)) > 10                                       # and many of them (not a constant)
    mean = STEP * (K * (eta * mu_p + mu_d) + off)
    var = STEP ** 2 * (K ** 2 * (R ** 2 + mu_d + eta * mu_p) + 1.0 / 12.0)
    assert y.mean() == pytest.approx(mean, abs=5 * math.sqrt(var / y.size))
    assert y.var(ddof=1) == pytest.approx(var, rel=5 * REL_VAR_SE)
    # the pipeline's noise model says the same, in the same units
    noise = NoiseModel.from_detector(cfg)
    assert noise.variance(mean) == pytest.approx(var, rel=1e-12)
    assert noise.offset_dn == STEP * off and noise.gain_dn_per_e == pytest.approx(STEP * K)


def test_noiseless_frames_hold_the_rounded_code_times_the_step():
    cfg = _cfg()
    mu_p = np.linspace(0.0, 3000.0, 97)[None, :]
    fr = apply_detector(mu_p, cfg, noiseless=True)
    code = np.floor(0.33 * (0.6 * mu_p + 10.0) + 60.0 + 0.5)
    assert np.array_equal(fr.dn, (STEP * code).astype(np.uint16))
    assert np.allclose(fr.expected_dn, STEP * (0.33 * (0.6 * mu_p + 10.0) + 60.0), rtol=1e-12)


def test_a_saturated_pixel_is_written_as_65535_and_the_pipeline_calls_it_saturated():
    cfg = _cfg(full_well_e=1e6)                        # the ADC saturates first: (4095 − 60) / 0.33 = 12227 e⁻
    ph = np.full((64, 64), 500.0)
    ph[30:33, 30:33] = 1e5                             # 6e4 e⁻: far above the ADC's top code
    ph[10, 10] = (4094 - 60 - 0.33 * 10.0) / 0.33 / 0.6  # one code below the top (noiseless: exactly 4094)
    fr = apply_detector(ph, cfg, noiseless=True)
    assert np.all(fr.dn[30:33, 30:33] == 65535) and fr.saturated[30:33, 30:33].all()
    assert fr.dn[10, 10] == 4094 * STEP and not fr.saturated[10, 10]
    assert fr.saturated.sum() == 9
    assert cfg.saturation_dn == 4095 * STEP            # frame DN at and above which a pixel is saturated
    assert not np.any((fr.dn > 4094 * STEP) & (fr.dn < 65535))
    noisy = apply_detector(ph, cfg, seed=5)
    assert set(np.unique(noisy.dn[30:33, 30:33])) == {65535}
    assert np.all((noisy.dn % STEP == 0) | (noisy.dn == 65535))


def test_the_detection_threshold_counts_quantisation_steps_of_the_frame():
    """5σ of the read noise, at least 3 steps of the frame's grid: 3 DN for plain codes, 48 DN in 16-bit words."""
    quiet = _cfg(read_noise_e=1.0, gain_dn_per_e=0.1)  # 5σ = 0.5 codes: the floor decides
    assert default_threshold_dn(NoiseModel.from_detector(quiet)) == 3 * STEP
    assert default_threshold_dn(NoiseModel.from_detector(_cfg(read_noise_e=1.0, gain_dn_per_e=0.1,
                                                                container_bits=None))) == 3
    loud = _cfg(read_noise_e=20.0, gain_dn_per_e=0.5)  # 5σ = 50 codes = 800 frame DN
    assert default_threshold_dn(NoiseModel.from_detector(loud)) == pytest.approx(5 * 20.0 * 0.5 * STEP)


def test_without_container_bits_the_frame_is_the_codes():
    cfg = _cfg(container_bits=None, full_well_e=1e6)
    assert cfg.code_step_dn == 1 and cfg.saturation_dn == 4095
    fr = apply_detector(np.full((32, 32), 1e6), cfg, noiseless=True)
    assert np.all(fr.dn == 4095)
    assert "container_bits" not in fr.meta["config"]   # sidecars of existing rigs stay as they were
    n = NoiseModel.from_detector(cfg)
    assert (n.gain_dn_per_e, n.offset_dn, n.extra_variance_dn2, n.quantum_dn) == (0.33, 60.0, 1.0 / 12.0, 1.0)


@pytest.mark.parametrize("kw,msg", [({"container_bits": 10}, "narrower than adc_bits = 12"),
                                    ({"container_bits": 17}, "less than or equal to 16"),
                                    ({"container_bits": 7, "adc_bits": 8}, "greater than or equal to 8")])
def test_a_container_narrower_than_the_adc_or_wider_than_16_bits_is_refused(kw, msg):
    with pytest.raises(ValidationError, match=msg):
        _cfg(**kw)
