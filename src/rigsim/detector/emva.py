"""EMVA 1288 predictions for a :class:`~rigsim.detector.DetectorConfig` (closed forms).

Notation as in EMVA 1288 (release 3.1/4.0 linear model): mu_p photons per pixel, eta quantum
efficiency, K system gain (DN/e-), mu_d mean dark electrons, sigma_d^2 temporal dark variance
(read noise^2 + dark shot noise mu_d), sigma_q^2 = 1/12 DN^2 quantisation noise. DN here are the ADC's codes
(a camera that writes them MSB-aligned, ``container_bits``, holds code × ``code_step_dn`` in its frames).
"""

from __future__ import annotations

import numpy as np

from rigsim.detector.config import DetectorConfig

__all__ = [
    "absolute_sensitivity_threshold_photons",
    "dynamic_range_db",
    "mean_dn",
    "saturation_photons",
    "snr",
    "temporal_variance_dn2",
    "total_snr",
]

SIGMA_Q2_DN2 = 1.0 / 12.0


def _sigma_d2(cfg: DetectorConfig) -> float:
    return cfg.read_noise_e ** 2 + cfg.dark_mean_e


def mean_dn(cfg: DetectorConfig, mu_p):
    """mu_y = offset + K (eta mu_p + mu_d)  (below saturation)."""
    return cfg.offset_dn + cfg.gain_dn_per_e * (cfg.quantum_efficiency * np.asarray(mu_p)
                                                + cfg.dark_mean_e)


def temporal_variance_dn2(cfg: DetectorConfig, mu_p):
    """sigma_y^2 = K^2 (sigma_d^2 + eta mu_p) + sigma_q^2: the photon-transfer line, slope K."""
    K = cfg.gain_dn_per_e
    return K * K * (_sigma_d2(cfg) + cfg.quantum_efficiency * np.asarray(mu_p)) + SIGMA_Q2_DN2


def snr(cfg: DetectorConfig, mu_p):
    """Temporal SNR = eta mu_p / sqrt(sigma_d^2 + sigma_q^2/K^2 + eta mu_p)."""
    K = cfg.gain_dn_per_e
    s = cfg.quantum_efficiency * np.asarray(mu_p, dtype=np.float64)
    return s / np.sqrt(_sigma_d2(cfg) + SIGMA_Q2_DN2 / K ** 2 + s)


def total_snr(cfg: DetectorConfig, mu_p):
    """SNR including the spatial non-uniformities (DSNU, PRNU), EMVA 1288 4.0 eq. for SNR_total."""
    K = cfg.gain_dn_per_e
    s = cfg.quantum_efficiency * np.asarray(mu_p, dtype=np.float64)
    var = (_sigma_d2(cfg) + cfg.dsnu_e ** 2 + SIGMA_Q2_DN2 / K ** 2 + s
           + (cfg.prnu_frac * s) ** 2)
    return s / np.sqrt(var)


def saturation_photons(cfg: DetectorConfig) -> float:
    """Photons per pixel at which the pixel saturates (full well or ADC top, whichever first)."""
    e_adc = (cfg.max_dn - cfg.offset_dn) / cfg.gain_dn_per_e
    e_sat = min(cfg.full_well_e, e_adc)
    return max(e_sat - cfg.dark_mean_e, 0.0) / cfg.quantum_efficiency


def absolute_sensitivity_threshold_photons(cfg: DetectorConfig) -> float:
    """mu_p at SNR = 1 (EMVA 1288: (sqrt(sigma_d^2 + sigma_q^2/K^2 + 1/4) + 1/2) / eta)."""
    K = cfg.gain_dn_per_e
    return (np.sqrt(_sigma_d2(cfg) + SIGMA_Q2_DN2 / K ** 2 + 0.25) + 0.5) / cfg.quantum_efficiency


def dynamic_range_db(cfg: DetectorConfig) -> float:
    return 20.0 * np.log10(saturation_photons(cfg) / absolute_sensitivity_threshold_photons(cfg))
