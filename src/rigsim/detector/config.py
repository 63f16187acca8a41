"""Detector configuration (EMVA 1288 quantities, units in the field names)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["DetectorConfig"]


class DetectorConfig(BaseModel):
    """An area-scan CCD/CMOS detector in EMVA 1288 terms.

    Signal chain (see :func:`rigsim.detector.apply_detector`): photons x quantum_efficiency x
    (1 + PRNU pattern) -> Poisson photo-electrons; + Poisson dark electrons with mean
    ``dark_current_e_per_s * exposure_s + DSNU pattern``; clip at ``full_well_e``; + Gaussian
    read noise; x ``gain_dn_per_e`` + ``offset_dn``; round to integers; clip to [0, 2^adc_bits-1].

    ``gain_dn_per_e``, ``offset_dn`` and :attr:`max_dn` are in the ADC's codes. A camera that writes
    its codes MSB-aligned into wider words (``container_bits``: a 12-bit ADC in 16-bit words writes
    code × 16) has frames in *frame DN*: :attr:`code_step_dn` frame DN per code, saturation at
    :attr:`saturation_dn`; without it the two are the same.

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
    container_bits: int | None = Field(None, ge=8, le=16,
                                       description="bits of the words the codes are written into, MSB-aligned "
                                                   "(shifted left by container_bits - adc_bits; the top code is "
                                                   "written as 2^container_bits - 1); None: the codes as they are")
    sensor_seed: int = Field(0, ge=0, le=2**63 - 1,
                             description="seed of the fixed patterns (DSNU, PRNU) of this "
                                         "detector instance")

    @model_validator(mode="after")
    def _container_holds_codes(self):
        if self.container_bits is not None and self.container_bits < self.adc_bits:
            raise ValueError(f"container_bits = {self.container_bits} is narrower than adc_bits = {self.adc_bits}: "
                             "allowed adc_bits to 16")
        return self

    @property
    def max_dn(self) -> int:
        """The ADC's top code (in codes, as ``offset_dn``)."""
        return 2 ** self.adc_bits - 1

    @property
    def code_step_dn(self) -> int:
        """Frame DN per ADC code: 2^(container_bits - adc_bits), 1 without ``container_bits``."""
        return 1 << (self.container_bits - self.adc_bits) if self.container_bits is not None else 1

    @property
    def saturation_dn(self) -> int:
        """The frame DN at and above which a pixel is saturated (the ADC's top code in frame DN; a
        camera with ``container_bits`` writes it as 2^container_bits - 1, which is above it)."""
        return self.max_dn * self.code_step_dn

    @property
    def dark_mean_e(self) -> float:
        return self.dark_current_e_per_s * self.exposure_s
