"""The ``[effects]`` table of a rig file: what a real rig shows beyond the ideal frame, each effect
switchable (``enabled``) with its physical parameters. Every effect is off unless the file (or
``--effects``) switches it on, so an ideal frame stays ideal.

:class:`EffectsTable` is the family-neutral base; each family's table lists its effects as fields
(``rigsim.rig.effects_*``). docs/effects.md gives every default value and its source.
"""

from __future__ import annotations

from pydantic import Field, StrictBool, model_validator

from rigsim.rig.model import RigModel

__all__ = ["STAR_EFFECTS", "CosmicRays", "Effect", "EffectsTable", "FaintStars", "HotPixels", "SkyGlow", "StarEffects",
           "StrayLight", "TracedPSF", "Vignetting"]


class Effect(RigModel):
    """One effect: off unless switched on."""

    enabled: StrictBool = False


class EffectsTable(RigModel):
    """A family's ``[effects]`` table: every field is an :class:`Effect`."""

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """Every effect of the table, in the rig file's order."""
        return tuple(cls.model_fields)

    @property
    def enabled(self) -> tuple[str, ...]:
        return tuple(n for n in self.names() if getattr(self, n).enabled)

    def only(self, names) -> EffectsTable:
        """A copy with exactly ``names`` switched on (values kept)."""
        names = set(names)
        unknown = names - set(self.names())
        if unknown:
            raise ValueError(f"unknown effects {sorted(unknown)}; this table has {', '.join(self.names())}")
        return self.model_copy(update={n: getattr(self, n).model_copy(update={"enabled": n in names})
                                       for n in self.names()})


class HotPixels(Effect):
    """Displacement-damage hot pixels: a fixed set of pixels (from the detector's ``sensor_seed``)
    with a dark current of ``threshold + Exp(mean_excess)``."""

    fraction: float = Field(5e-3, ge=0.0, le=0.2, description="share of the pixels that are hot")
    threshold_e_per_s: float = Field(1000.0, ge=0.0, le=1e7, description="lowest dark current of a hot pixel")
    mean_excess_e_per_s: float = Field(3000.0, ge=0.0, le=1e7, description="mean dark current above the threshold")


class CosmicRays(Effect):
    """Charged particles crossing the depleted silicon during the exposure."""

    flux_per_cm2_s: float = Field(1.2, ge=0.0, le=1e5, description="particles per cm² of detector per second")
    depth_um: float = Field(10.0, gt=0.0, le=1000.0, description="depth of the charge-collecting silicon")
    charge_e_per_um: float = Field(60.0, gt=0.0, le=1e4, description="most probable charge per µm of path")
    landau_width: float = Field(0.25, ge=0.0, le=2.0,
                                description="Moyal scale of the deposit's fluctuation, relative to the most probable")


class StrayLight(Effect):
    """A stray-light gradient: μ = edge + falloff · (angle from the field edge nearest the source)."""

    edge_mag_per_arcsec2: float = Field(18.0, ge=5.0, le=30.0, description="surface brightness at the bright edge")
    falloff_mag_per_deg: float = Field(0.3, ge=0.0, le=10.0, description="fall-off away from the bright edge")
    direction_deg: float = Field(0.0, ge=-360.0, le=360.0,
                                 description="direction towards the source in the image, from +u towards +v")


class Vignetting(Effect):
    """The lens's relative illumination: the share of the on-axis light that reaches each point of the
    detector, V(ρ) = 1 − rho2 · ρ² − rho4 · ρ⁴, with ρ the distance from the principal point over the
    detector's half-diagonal. It dims the stars and the sky alike."""

    rho2: float = Field(0.3, ge=-1.0, le=1.0, description="fall-off in ρ² (ρ = 1 at the detector's corner)")
    rho4: float = Field(0.0, ge=-1.0, le=1.0, description="fall-off in ρ⁴")

    @model_validator(mode="after")
    def _positive(self):
        corner = 1.0 - self.rho2 - self.rho4
        if not 0.02 <= corner <= 1.5:
            raise ValueError(f"rho2 = {self.rho2}, rho4 = {self.rho4}: the corner would get {corner:.3g} of the "
                             "on-axis light; allowed 0.02 to 1.5")
        return self


class SkyGlow(Effect):
    """A night sky's glow across the field (airglow and light pollution brighten towards the horizon):
    the sky's surface brightness times 1 + slope · d, d the angle (deg) from the field's centre along
    ``direction_deg``."""

    slope_per_deg: float = Field(0.05, ge=-0.2, le=0.2, description="relative change of the sky per degree")
    direction_deg: float = Field(90.0, ge=-360.0, le=360.0,
                                 description="direction of increase in the image, from +u towards +v")


class FaintStars(Effect):
    """Stars fainter than the catalogue: at random places on the detector, with the sky's counts per
    magnitude, dN/dm ∝ 10^(slope · m), from the catalogue's magnitude limit down to ``faint_limit_mag``.
    They add the light and the unidentified detections a real sky has beyond any catalogue."""

    density_per_deg2_per_mag: float = Field(1.0, ge=0.0, le=1e5,
                                            description="stars per square degree per magnitude at the catalogue's limit")
    slope_per_mag: float = Field(0.35, ge=0.0, le=1.0, description="log10 of the counts' growth per magnitude")
    faint_limit_mag: float = Field(13.0, ge=-2.0, le=25.0, description="the faintest star drawn")


class TracedPSF(Effect):
    """The PSF of the traced lens (``rigsim.optics.star_lens``) instead of the Gaussian: field-dependent,
    and the spectrum-weighted sum over the band for each star's colour (B−V). Focal length and entrance
    pupil come from ``[sensor]``; the detector sits ``[sensor.psf] defocus_um`` before the best focus (towards
    the lens) at ``[sensor.psf] wavelength_nm``."""

    band_min_nm: float = Field(450.0, ge=300.0, le=1100.0, description="shortest wavelength of the sensor's band")
    band_max_nm: float = Field(850.0, ge=300.0, le=1100.0, description="longest wavelength of the sensor's band")
    wavelengths: int = Field(7, ge=1, le=41, description="wavelengths traced across the band")
    field_nodes: int = Field(13, ge=2, le=33, description="field directions traced per axis (bilinear between them)")
    pupil_rays: int = Field(48, ge=8, le=512, description="rays across the entrance pupil")
    oversample: int = Field(4, ge=1, le=16, description="PSF bins per pixel")

    @model_validator(mode="after")
    def _band(self):
        if self.band_max_nm < self.band_min_nm:
            raise ValueError(f"band_max_nm = {self.band_max_nm} must be ≥ band_min_nm = {self.band_min_nm}")
        return self


class StarEffects(EffectsTable):
    hot_pixels: HotPixels = Field(default_factory=HotPixels)
    cosmic_rays: CosmicRays = Field(default_factory=CosmicRays)
    stray_light: StrayLight = Field(default_factory=StrayLight)
    traced_psf: TracedPSF = Field(default_factory=TracedPSF)
    sky_glow: SkyGlow = Field(default_factory=SkyGlow)
    vignetting: Vignetting = Field(default_factory=Vignetting)
    faint_stars: FaintStars = Field(default_factory=FaintStars)


STAR_EFFECTS = StarEffects.names()
