"""The ``[effects]`` of the boresight rig: the lasers, the central prism, the camera objectives.

docs/effects-boresight.md gives every default value and its source.
"""

from __future__ import annotations

from pydantic import Field

from rigsim.rig.effects import Effect, EffectsTable

__all__ = ["BORESIGHT_EFFECTS", "BoresightEffects", "GaussianBeam", "ObjectiveAberrations", "PrismGlass"]


class GaussianBeam(Effect):
    """The laser's Gaussian profile (embedded-Gaussian M² model) instead of the uniform emitting core:
    the spot is the image of the beam's irradiance in the plane conjugate to the CMOS, which lies
    ``waist_offset_mm`` from the beam's waist."""

    wavelength_nm: float = Field(632.8, ge=200.0, le=2000.0, description="laser wavelength")
    waist_radius_um: float = Field(25.0, ge=2.0, le=200.0, description="1/e² irradiance radius at the waist, w0")
    m_squared: float = Field(1.1, ge=1.0, le=50.0, description="beam-quality factor M²")
    waist_offset_mm: float = Field(2.0, ge=-100.0, le=100.0,
                                   description="waist to the plane conjugate to the CMOS (the transceiver's focus error)")
    truncation: float = Field(3.0, ge=1.5, le=5.0, description="emitting patch half-width in units of w(z)")


class PrismGlass(Effect):
    """Each prism facet as the coated back face of a glass element whose uncoated entrance face
    has a residual wedge: refraction in and out, the Fresnel ghosts of the entrance face."""

    refractive_index: float = Field(1.51509, ge=1.3, le=2.5, description="glass index at the laser wavelength")
    thickness_mm: float = Field(10.0, ge=0.5, le=200.0, description="entrance face to the coated face")
    wedge_arcsec: float = Field(3.0, ge=0.0, le=600.0, description="residual wedge between the two faces")
    wedge_azimuth_deg: float = Field(0.0, ge=-360.0, le=360.0,
                                     description="direction of the wedge's tilt about the beam (0: ghost along u)")


class ObjectiveAberrations(Effect):
    """The camera objective's Seidel coma and astigmatism at the CMOS's field point (a wavefront
    model, not a mirror trace), doubled by the loop's two passes: an asymmetric spot."""

    coma_waves: float = Field(0.25, ge=-5.0, le=5.0, description="W131 at the CMOS field point, waves")
    astigmatism_waves: float = Field(0.25, ge=-5.0, le=5.0, description="W222 at the CMOS field point, waves")
    wavelength_nm: float = Field(632.8, ge=200.0, le=2000.0, description="wavelength the coefficients are given at")
    aperture_diameter_mm: float = Field(600.0, ge=10.0, le=5000.0, description="objective's entrance pupil diameter")
    beam_fill: float = Field(1.0, gt=0.0, le=1.0, description="relative radius of the pupil the laser fills")


class BoresightEffects(EffectsTable):
    """Effects of the boresight rig: the lasers, the central prism, the camera objectives."""

    gaussian_beam: GaussianBeam = Field(default_factory=GaussianBeam)
    prism_glass: PrismGlass = Field(default_factory=PrismGlass)
    objective_aberrations: ObjectiveAberrations = Field(default_factory=ObjectiveAberrations)


BORESIGHT_EFFECTS = BoresightEffects.names()
