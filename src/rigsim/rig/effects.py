"""The ``[effects]`` table of a star-sensor rig file: what a real sensor shows beyond the ideal
frame, each effect switchable (``enabled``) with its physical parameters. Every effect is off
unless the file (or ``--effects``) switches it on, so an ideal frame stays ideal.

docs/effects.md gives every default value and its source.
"""

from __future__ import annotations

from pydantic import Field, StrictBool

from rigsim.rig.model import RigModel

__all__ = ["STAR_EFFECTS", "CosmicRays", "HotPixels", "StarEffects", "StrayLight"]


class HotPixels(RigModel):
    """Displacement-damage hot pixels: a fixed set of pixels (from the detector's ``sensor_seed``)
    with a dark current of ``threshold + Exp(mean_excess)``."""

    enabled: StrictBool = False
    fraction: float = Field(5e-3, ge=0.0, le=0.2, description="share of the pixels that are hot")
    threshold_e_per_s: float = Field(1000.0, ge=0.0, le=1e7, description="lowest dark current of a hot pixel")
    mean_excess_e_per_s: float = Field(3000.0, ge=0.0, le=1e7, description="mean dark current above the threshold")


class CosmicRays(RigModel):
    """Charged particles crossing the depleted silicon during the exposure."""

    enabled: StrictBool = False
    flux_per_cm2_s: float = Field(1.2, ge=0.0, le=1e5, description="particles per cm² of detector per second")
    depth_um: float = Field(10.0, gt=0.0, le=1000.0, description="depth of the charge-collecting silicon")
    charge_e_per_um: float = Field(60.0, gt=0.0, le=1e4, description="most probable charge per µm of path")
    landau_width: float = Field(0.25, ge=0.0, le=2.0,
                                description="Moyal scale of the deposit's fluctuation, relative to the most probable")


class StrayLight(RigModel):
    """A stray-light gradient: μ = edge + falloff · (angle from the field edge nearest the source)."""

    enabled: StrictBool = False
    edge_mag_per_arcsec2: float = Field(18.0, ge=5.0, le=30.0, description="surface brightness at the bright edge")
    falloff_mag_per_deg: float = Field(0.3, ge=0.0, le=10.0, description="fall-off away from the bright edge")
    direction_deg: float = Field(0.0, ge=-360.0, le=360.0,
                                 description="direction towards the source in the image, from +u towards +v")


class StarEffects(RigModel):
    hot_pixels: HotPixels = Field(default_factory=HotPixels)
    cosmic_rays: CosmicRays = Field(default_factory=CosmicRays)
    stray_light: StrayLight = Field(default_factory=StrayLight)

    @property
    def enabled(self) -> tuple[str, ...]:
        return tuple(n for n in STAR_EFFECTS if getattr(self, n).enabled)

    def only(self, names) -> StarEffects:
        """A copy with exactly ``names`` switched on (values kept)."""
        names = set(names)
        return self.model_copy(update={n: getattr(self, n).model_copy(update={"enabled": n in names})
                                       for n in STAR_EFFECTS})


STAR_EFFECTS = ("hot_pixels", "cosmic_rays", "stray_light")
