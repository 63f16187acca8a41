"""The ``[effects]`` of the photoelectric autocollimator (the 3-axis cube-mirror rig).

docs/effects.md gives every default value and its source.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from rigsim.rig.effects import Effect, EffectsTable

__all__ = ["AutocollimatorEffects", "FaceReflectance", "LensGhosts", "Reticle"]


class Reticle(Effect):
    """The instrument projects an illuminated reticle (a cross-hair, optionally with a ring)
    instead of a point: the detector sees the reticle's image and the reading is its centre."""

    pattern: Literal["cross", "cross_ring"] = Field("cross", description="the reticle's drawing")
    line_width_um: float = Field(20.0, gt=0.0, le=500.0, description="width of every line of the reticle")
    arm_length_mm: float = Field(0.5, gt=0.0, le=5.0, description="full length of each bar of the cross")
    ring_radius_mm: float = Field(0.15, gt=0.0, le=2.5, description="mid-line radius of the ring (cross_ring)")


class FaceReflectance(Effect):
    """The cube face is not a perfect mirror: uncoated glass (Fresnel at both the front and the
    opposite face) or a metal coating of reflectance < 1."""

    coating: Literal["uncoated", "protected_al", "enhanced_al"] = Field(
        "uncoated", description="the face: bare glass, or aluminium with a protective / enhancing overcoat")
    glass_index: float = Field(1.5168, gt=1.0, le=2.5, description="refractive index of the cube's glass (N-BK7, d line)")
    protected_al_reflectance: float = Field(0.90, gt=0.0, le=1.0, description="protected aluminium, mean visible")
    enhanced_al_reflectance: float = Field(0.95, gt=0.0, le=1.0, description="enhanced aluminium, mean visible")


class LensGhosts(Effect):
    """Fresnel reflections at both surfaces of the objective (ghost images on the detector)."""

    surface_reflectance: float | None = Field(
        None, ge=0.0, le=0.2, description="reflectance per surface at normal incidence; unset = uncoated (Fresnel)")


class AutocollimatorEffects(EffectsTable):
    """Effects of the photoelectric autocollimator (the 3-axis cube-mirror rig)."""

    reticle: Reticle = Field(default_factory=Reticle)
    face_reflectance: FaceReflectance = Field(default_factory=FaceReflectance)
    ghosts: LensGhosts = Field(default_factory=LensGhosts)
