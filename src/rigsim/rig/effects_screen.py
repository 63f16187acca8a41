"""The ``[effects]`` of the diaphragm screen and the aiming camera (the 2-axis cube-mirror rig).

docs/effects.md gives every default value and its source.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from rigsim.rig.effects import Effect, EffectsTable

__all__ = ["AmbientLight", "CubeGhosts", "ScreenEffects", "ScreenMaterial", "SurfaceFigure"]

_Face = Literal["+X", "-X", "+Y", "-Y", "+Z", "-Z"]
_Tilt3 = Annotated[list[Annotated[float, Field(ge=-3600.0, le=3600.0)]], Field(min_length=3, max_length=3)]


class CubeGhosts(Effect):
    """The cube is a glass cube prism with bare faces: the measured face's Fresnel reflection is the
    spot, the light reflected inside by the opposite face comes back through the measured face as a
    ghost spot, deviated by 2·n·(wedge between the two faces)."""

    refractive_index: float = Field(1.5168, ge=1.0, le=4.0, description="the cube glass's index")
    back_face_tilt_arcsec: dict[_Face, _Tilt3] = Field(
        default_factory=lambda: {"-Z": [3.0, 0.0, 0.0], "-Y": [0.0, 0.0, 3.0]},
        description="true tilt (rotation vector, cube frame) of a face opposite a measured face")
    internal_reflections: int = Field(1, ge=1, le=4, description="internal reflections rendered (ghost orders)")


class ScreenMaterial(Effect):
    """A granular screen: its diffuse albedo varies from point to point (a fixed pattern of the
    screen, drawn from ``seed``)."""

    grain_um: float = Field(40.0, ge=1.0, le=5000.0, description="correlation length (Gaussian σ) of the albedo grain")
    contrast: float = Field(0.05, ge=0.0, le=0.5, description="relative rms of the albedo")
    seed: int = Field(7, ge=0, le=2**32 - 1, description="the screen's pattern")


class AmbientLight(Effect):
    """Room light on the screen: an illuminance with a linear gradient across the screen."""

    illuminance_lux: float = Field(500.0, ge=0.0, le=1e5, description="room illuminance on the screen at the hole")
    gradient_per_100mm: float = Field(0.2, ge=0.0, le=1.0, description="relative change of the illuminance per 100 mm")
    direction_deg: float = Field(0.0, ge=-360.0, le=360.0, description="direction of increase on the screen, from +X' to +Y'")
    beam_illuminance_lux: float = Field(133800.0, gt=0.0, le=1e7,
                                        description="the sun simulator beam's illuminance (normal to the beam)")


class SurfaceFigure(Effect):
    """The measured faces' flatness error: a power term and an astigmatism term, each given as its
    peak-to-valley over the face's inscribed circle (the clear aperture of diameter D = the edge).
    Power PV s is a sphere of radius D²/(8s) (positive: convex, the face's centre stands out)."""

    power_pv_waves: float = Field(0.1, ge=-1000.0, le=1000.0, description="power term, PV (signed: + convex)")
    astigmatism_pv_waves: float = Field(0.05, ge=0.0, le=1000.0, description="astigmatism term, PV")
    astigmatism_angle_deg: float = Field(0.0, ge=-360.0, le=360.0,
                                         description="axis of the astigmatism from the face's first in-plane cube axis")
    wavelength_nm: float = Field(632.8, gt=100.0, le=20000.0, description="the wavelength the PV values count in")
    grid: int = Field(32, ge=2, le=512, description="the figured face's mesh: grid × grid cells")


class ScreenEffects(EffectsTable):
    """Effects of the diaphragm screen and the aiming camera (the 2-axis cube-mirror rig)."""

    cube_ghosts: CubeGhosts = Field(default_factory=CubeGhosts)
    screen_material: ScreenMaterial = Field(default_factory=ScreenMaterial)
    ambient_light: AmbientLight = Field(default_factory=AmbientLight)
    surface_figure: SurfaceFigure = Field(default_factory=SurfaceFigure)
