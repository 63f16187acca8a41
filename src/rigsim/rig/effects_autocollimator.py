"""The ``[effects]`` of the photoelectric autocollimator (the 3-axis cube-mirror rig).

docs/effects.md gives every default value and its source.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from rigsim.rig.effects import Effect, EffectsTable

__all__ = ["AutocollimatorEffects", "BeamSplitterPlate", "FaceReflectance", "LensGhosts", "Reticle", "beam_splitter_of"]


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


class BeamSplitterPlate(Effect):
    """The beam splitter as a real glass plate at an angle: the reticle reaches the objective by
    reflection off its first surface, the return crosses both surfaces to the detector (displaced,
    refocused, astigmatic) and the second surface adds a ghost."""

    thickness_mm: float = Field(2.0, gt=0.0, le=10.0, description="plate thickness")
    glass_index: float | None = Field(
        None, gt=1.0, le=2.5, description="refractive index of the plate; unset = N-BK7 at the objective's wavelength")
    tilt_deg: float = Field(45.0, ge=20.0, le=60.0, description="angle between the plate's normal and the optical axis")
    first_surface_reflectance: float | None = Field(
        0.5, gt=0.0, lt=1.0, description="reflectance of the reticle-side surface at tilt_deg; unset = bare glass (Fresnel)")
    second_surface_reflectance: float | None = Field(
        None, ge=0.0, lt=1.0, description="reflectance of the detector-side surface at tilt_deg; unset = bare glass (Fresnel)")


def beam_splitter_of(rig, lens_n: float | None = None):
    """The :class:`~rigsim.optics.beam_splitter.BeamSplitter` of ``rig``'s enabled
    ``[effects.beam_splitter]`` (None when off or absent). The plate is part of the instrument:
    its factory calibration (``AutocollimatorOptics.calibration``) is made with it."""
    eff = getattr(rig, "effects", None)
    b = getattr(eff, "beam_splitter", None)
    if b is None or not b.enabled:
        return None
    from rigsim.optics.autocollimator import n_bk7
    from rigsim.optics.beam_splitter import BeamSplitter

    n = b.glass_index if b.glass_index is not None else (lens_n if lens_n is not None else n_bk7(587.56))
    return BeamSplitter(float(b.thickness_mm), float(n), float(b.tilt_deg), b.first_surface_reflectance,
                        b.second_surface_reflectance)


class AutocollimatorEffects(EffectsTable):
    """Effects of the photoelectric autocollimator (the 3-axis cube-mirror rig)."""

    reticle: Reticle = Field(default_factory=Reticle)
    face_reflectance: FaceReflectance = Field(default_factory=FaceReflectance)
    ghosts: LensGhosts = Field(default_factory=LensGhosts)
    beam_splitter: BeamSplitterPlate = Field(default_factory=BeamSplitterPlate)
