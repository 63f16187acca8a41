"""The ``[effects]`` of the sun sensor (both cube-mirror rigs): the sun and its simulator, the cover glass, the pinhole.

docs/effects.md gives every default value and its source.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator

from rigsim.optics.pinhole_diffraction import DEFAULT_BAND_NM
from rigsim.rig.effects import Effect, EffectsTable

__all__ = ["CoverGlassGhost", "LimbDarkening", "PinholeDiffraction", "SimulatorNonuniformity", "SunSensorEffects",
           "Vignetting"]


class LimbDarkening(Effect):
    """The sun disk's radiance falls towards the limb: I(μ)/I(1) = 1 − u(1 − μ), μ the cosine of the
    emission angle on the solar surface; the disk's mean radiance (its flux) is kept."""

    u: float = Field(0.6, ge=0.0, le=1.0, description="linear limb-darkening coefficient")


class SimulatorNonuniformity(Effect):
    """The simulator's non-uniformity as a linear gradient of ±``nonuniformity`` across its beam:
    ``angular`` (across the 32′ disk: the field stop's non-uniformity, imaged to infinity by the
    collimator; it moves the spot's centroid) or ``spatial`` (across the exit aperture: it scales
    the spot's brightness with where the pinhole sits in the beam)."""

    kind: Literal["angular", "spatial"] = "angular"
    nonuniformity: float = Field(0.02, ge=0.0, le=0.5,
                                 description="(max − min)/(max + min) of the radiance (angular) or irradiance (spatial)")
    direction_deg: float = Field(0.0, ge=-360.0, le=360.0,
                                 description="direction of the gradient across the beam, from the rot frame's "
                                             "axis nearest to perpendicular to the beam towards beam × that axis")
    pinhole_in_mount_mm: list[float] = Field([0.0, 0.0, 20.0], min_length=3, max_length=3,
                                             description="spatial: the pinhole's place in the mount frame")


class CoverGlassGhost(Effect):
    """The detector's cover glass, a plane-parallel window between the pinhole and the detector: the
    light reflected at its inner then its outer surface makes a fainter second spot, displaced
    outwards by 2 t tan θ′ (θ′ the angle in the glass)."""

    thickness_mm: float = Field(0.5, gt=0.0, le=5.0, description="window thickness")
    refractive_index: float = Field(1.458, ge=1.0, le=4.0, description="index of the window (fused silica: 1.458)")
    coating_reflectance: float | None = Field(None, ge=0.0, le=0.5,
                                              description="reflectance per surface of an AR coating (angle-independent); "
                                                          "omit for the bare surface's Fresnel reflectance")


class Vignetting(Effect):
    """The pinhole's mask has a thickness: oblique light passes the overlap of its entrance and exit
    circles, V(θ) = (2/π)(acos k − k√(1 − k²)), k = t tan θ / D, on top of the thin pinhole's cos⁴."""

    pinhole_diameter_mm: float = Field(0.1, gt=0.0, le=5.0, description="pinhole diameter D")
    mask_thickness_mm: float = Field(0.025, ge=0.0, le=5.0, description="mask thickness t")


class PinholeDiffraction(Effect):
    """The pinhole's diffraction: each point of the sun's geometric image (through a point pinhole)
    spreads into the Fresnel pattern of the opening seen along its chief ray (the pinhole projected,
    the entrance and exit circles' overlap in a thick mask), summed over the band: a
    ``source_temperature_k`` blackbody's photons times a silicon detector's quantum efficiency."""

    pinhole_diameter_mm: float = Field(0.1, gt=0.0, le=5.0, description="pinhole diameter D (as vignetting's)")
    mask_thickness_mm: float = Field(0.025, ge=0.0, le=5.0, description="mask thickness t (as vignetting's)")
    propagation: Literal["fresnel", "fraunhofer"] = "fresnel"
    wavelengths_nm: list[float] = Field(list(DEFAULT_BAND_NM), min_length=1, max_length=16,
                                        description="wavelengths summed over (each 300–1100 nm)")
    source_temperature_k: float = Field(5800.0, ge=2000.0, le=10000.0,
                                        description="the simulator's spectrum as a blackbody (AM0 ≈ 5800 K)")
    supersampling: Literal[1, 2, 4] = Field(4, description="sub-pixels per pixel side of the geometric image "
                                                           "before the convolution")

    @field_validator("wavelengths_nm")
    @classmethod
    def _band(cls, v):
        for x in v:
            if not 300.0 <= x <= 1100.0:
                raise ValueError(f"wavelength {x} nm: must be in [300, 1100] nm (a silicon detector's band)")
        return v


class SunSensorEffects(EffectsTable):
    """Effects of the sun sensor (both cube-mirror rigs): the sun and its simulator, the cover glass, the pinhole."""

    limb_darkening: LimbDarkening = Field(default_factory=LimbDarkening)
    simulator_nonuniformity: SimulatorNonuniformity = Field(default_factory=SimulatorNonuniformity)
    cover_glass_ghost: CoverGlassGhost = Field(default_factory=CoverGlassGhost)
    vignetting: Vignetting = Field(default_factory=Vignetting)
    pinhole_diffraction: PinholeDiffraction = Field(default_factory=PinholeDiffraction)

    def disk_radiance(self, with_gradient: bool = True):
        """The disk's radiance these effects give (:class:`rigsim.optics.sun_radiance.DiskRadiance`):
        limb darkening, and the angular non-uniformity's gradient when ``with_gradient``."""
        from rigsim.optics.sun_radiance import DiskRadiance

        nu = self.simulator_nonuniformity
        return DiskRadiance(u=self.limb_darkening.u if self.limb_darkening.enabled else 0.0,
                            g=nu.nonuniformity if with_gradient and nu.enabled and nu.kind == "angular" else 0.0)

    def thick_pinhole(self):
        """The thick pinhole's vignetting (:class:`rigsim.optics.pinhole.ThickPinhole`), None when off."""
        from rigsim.optics.pinhole import ThickPinhole

        v = self.vignetting
        return ThickPinhole(v.pinhole_diameter_mm, v.mask_thickness_mm) if v.enabled else None

    def pinhole_psf(self, focal_length_mm: float):
        """The pinhole's diffraction PSF (:class:`rigsim.optics.pinhole_diffraction.PinholePSF`) for a
        detector ``focal_length_mm`` behind it, None when off."""
        from rigsim.optics.pinhole_diffraction import PinholePSF, band_weights

        pd = self.pinhole_diffraction
        if not pd.enabled:
            return None
        return PinholePSF(pd.pinhole_diameter_mm, pd.mask_thickness_mm, focal_length_mm, tuple(pd.wavelengths_nm),
                          tuple(band_weights(pd.wavelengths_nm, pd.source_temperature_k).tolist()), pd.propagation)
