"""Detector configuration (EMVA 1288 quantities, units in the field names)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["DetectorConfig"]


class DetectorConfig(BaseModel):
    """An area-scan CCD/CMOS detector in EMVA 1288 terms.

    Signal chain (see :func:`rigsim.detector.apply_detector`): photons x quantum_efficiency x
    (1 + PRNU pattern) -> Poisson photo-electrons; + Poisson dark electrons with mean
    ``dark_current_e_per_s * exposure_s + DSNU pattern``; clip at ``full_well_e``; + Gaussian
    read noise; x ``gain_dn_per_e`` + ``offset_dn``; round to integers; clip to [0, 2^adc_bits-1].

    ``sensor_seed`` identifies the detector *instance*: the DSNU and PRNU fixed patterns are drawn
    from it alone, so they stay the same for every frame; each frame's temporal noise takes its
    own seed.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    quantum_efficiency: float = Field(0.6, gt=0.0, le=1.0,
                                      description="electrons per photon (at the rendered band)")
    exposure_s: float = Field(0.01, gt=0.0, le=3600.0, description="integration time")
    full_well_e: float = Field(20000.0, gt=0.0, le=1.0e7, description="saturation capacity")
    read_noise_e: float = Field(5.0, ge=0.0, le=1.0e4, description="temporal dark noise, rms e-")
    dark_current_e_per_s: float = Field(10.0, ge=0.0, le=1.0e7,
                                        description="mean dark current per pixel")
    dsnu_e: float = Field(1.0, ge=0.0, le=1.0e5,
                          description="dark signal non-uniformity: spatial rms of the dark "
                                      "signal, e- (at this exposure)")
    prnu_frac: float = Field(0.005, ge=0.0, le=0.5,
                             description="photo-response non-uniformity: spatial rms of the gain, "
                                         "fraction")
    gain_dn_per_e: float = Field(0.2, gt=0.0, le=100.0, description="system gain K")
    adc_bits: int = Field(12, ge=8, le=16, description="ADC bit depth (output fits uint16)")
    offset_dn: float = Field(64.0, ge=0.0, le=65535.0, description="black level added by the ADC")
    sensor_seed: int = Field(0, ge=0, le=2**63 - 1,
                             description="seed of the fixed patterns (DSNU, PRNU) of this "
                                         "detector instance")

    @property
    def max_dn(self) -> int:
        return 2 ** self.adc_bits - 1

    @property
    def dark_mean_e(self) -> float:
        return self.dark_current_e_per_s * self.exposure_s
