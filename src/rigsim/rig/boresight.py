"""Rig description of seed 003: two line-array cameras sharing a central prism (pydantic v2).

Same conventions as :mod:`rigsim.rig.cube_mirror`: frozen models, unknown keys rejected, units in the
field names (``_mm``, ``_um``, ``_px``, ``_deg``, ``_arcsec``, ``_min``). The loader
(:func:`rigsim.rig.load.load_boresight_rig`) turns every validation problem into one
:class:`rigsim.errors.RigError` naming the file, the field, the value and the allowed range.

Geometry (docs/boresight.md has the figure in words):

* ``OTA`` (the paper's O X_OTA Y_OTA Z_OTA): origin O at the camera's (ideal, thin) lens, +Z
  towards object space (the prism), the focal plane at z = −F. The CCD line lies along Y at
  x = F·tan ω (the off-axis field); the CMOS detectors M1, M2 sit at its two ends, centred at
  (F·tan ω, Lc1) and (F·tan ω, Lc2).
* ``HRC`` (camera frame): Z_HRC from the CCD centre through O, Y_HRC = Y_OTA, X_HRC = Y × Z,
  i.e. ``R_ota_from_hrc = Rot_Y(−ω)``.
* ``prism``: fixed to the central prism; ``prism_pitch_deg`` orients each camera's HRC frame in
  it (a rotation about Y: a forward- and a backward-looking camera).
* detector pixels: rigsim's convention (pixel (0, 0)'s centre at (u, v) = (0, 0)); the paper's
  detector coordinates are (x, y) = (u − (W−1)/2, v − (H−1)/2), x along X_OTA and y along
  Y_OTA when the tilt θm is zero.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from rigsim.detector.config import DetectorConfig
from rigsim.rig.effects_boresight import BoresightEffects
from rigsim.rig.model import RigModel

__all__ = ["LineCamera", "Laser", "StudySettings", "OrbitScenario", "BoresightRig"]


class _Model(RigModel):
    pass


Px2 = Annotated[list[Annotated[float, Field(ge=-10000.0, le=10000.0)]], Field(min_length=2, max_length=2)]


class LineCamera(_Model):
    """One line-array camera with its two CMOS detectors and laser transceivers (Table 2)."""

    name: str = Field(min_length=1, max_length=40)
    focal_length_mm: float = Field(6000.0, ge=100.0, le=50000.0, description="F_OTA (Table 2: 6000)")
    off_axis_deg: float = Field(6.0, ge=0.0, le=30.0, description="ω (Table 2: 6°)")
    telecentric_factor: float = Field(0.5, ge=0.05, le=20.0,
                                      description="Kf (Table 2: 0.5); the loop's focal length changes "
                                                  "by Δf/Kf when the camera's changes by Δf")
    pixel_pitch_um: float = Field(10.0, ge=1.0, le=100.0, description="d (Table 2: 10 µm)")
    detector_width_px: int = Field(5120, ge=64, le=20000, description="Table 2: 5120")
    detector_height_px: int = Field(3840, ge=64, le=20000, description="Table 2: 3840")
    m1_center_y_mm: float = Field(500.0, ge=-5000.0, le=5000.0, description="Lc1 (signed position along the line)")
    m2_center_y_mm: float = Field(-500.0, ge=-5000.0, le=5000.0, description="Lc2 (signed position along the line)")
    m1_tilt_deg: float = Field(0.0, ge=-10.0, le=10.0, description="θm1, rotation of M1 in the focal plane")
    m2_tilt_deg: float = Field(0.0, ge=-10.0, le=10.0, description="θm2")
    m1_reference_px: Px2 = Field([0.0, 0.0], description="A1 in the paper's detector coordinates (centred): "
                                                         "where the laser's own return lands at the reference")
    m2_reference_px: Px2 = Field([0.0, 0.0], description="B1")
    prism_pitch_deg: float = Field(0.0, ge=-60.0, le=60.0,
                                   description="orientation of this camera's HRC frame in the prism frame (about Y)")
    facet_distance_mm: float = Field(1000.0, ge=50.0, le=20000.0,
                                     description="rendering: distance from the lens to its prism facet")

    @model_validator(mode="after")
    def _detectors(self):
        if not self.m1_center_y_mm > self.m2_center_y_mm:
            raise ValueError(f"m1_center_y_mm ({self.m1_center_y_mm}) must be greater than m2_center_y_mm "
                             f"({self.m2_center_y_mm}): M1 and M2 sit at the two ends of the line, "
                             "L = Lc1 − Lc2 > 0")
        half_w = 0.5 * self.detector_height_px * self.pixel_pitch_um * 1e-3
        if self.m1_center_y_mm - self.m2_center_y_mm < 2.0 * half_w:
            raise ValueError(f"the detectors overlap: Lc1 − Lc2 = {self.m1_center_y_mm - self.m2_center_y_mm} mm "
                             f"is less than the detector height {2 * half_w} mm")
        for name, ref in (("m1_reference_px", self.m1_reference_px), ("m2_reference_px", self.m2_reference_px)):
            if abs(ref[0]) > 0.5 * self.detector_width_px - 16 or abs(ref[1]) > 0.5 * self.detector_height_px - 16:
                raise ValueError(f"{name} = {ref} px lies within 16 px of the detector's edge or beyond "
                                 f"(allowed |x| ≤ {0.5 * self.detector_width_px - 16}, "
                                 f"|y| ≤ {0.5 * self.detector_height_px - 16})")
        return self


class Laser(_Model):
    """The laser transceivers: an emitter conjugate (through the transceiver's beam splitter) with
    the reference point of its CMOS, emitting along the optical axis (telecentric)."""

    core_radius_um: float = Field(25.0, ge=2.0, le=500.0,
                                  description="radius of the emitting core; the spot is its image (loop magnification −1)")
    photons_per_frame: float = Field(4.0e5, gt=0.0, le=1e12, description="photons reaching the detector per exposure")


class StudySettings(_Model):
    """Defaults of the paper's analyses (section 3)."""

    centroid_sigma_px: float = Field(0.1, gt=0.0, le=10.0, description="centroid error per axis (paper: 0.1 px)")
    monte_carlo_runs: int = Field(1200, ge=10, le=10_000_000, description="Fig 5: 1200 runs")
    reference_measurements: int = Field(100, ge=1, le=100000, description="N of eqs 16–17 (reference averaging)")
    perturbation_arcsec: float = Field(10.0, ge=0.0, le=3600.0,
                                       description="true α = β = γ of the Monte-Carlo state")
    perturbation_delta_f_um: float = Field(10.0, ge=-10000.0, le=10000.0, description="true Δf of the Monte-Carlo state")
    seed: int = Field(2023, ge=0, le=2**63 - 1)


class OrbitScenario(_Model):
    """Thermal-vacuum orbit scenario (section 4): sinusoidal thermal drift, rendered frames."""

    period_min: float = Field(94.6, gt=1.0, le=10000.0, description="orbit period")
    orbits: float = Field(2.0, gt=0.0, le=100.0, description="paper: two cycles")
    measurements: int = Field(19, ge=3, le=10000, description="paper: 19 measurements, equally spaced")
    relative_pitch_pp_arcsec: float = Field(1.0, ge=0.0, le=3600.0,
                                            description="peak-to-peak of camera 2 vs camera 1 about Y (paper: ~1″)")
    relative_roll_pp_arcsec: float = Field(0.3, ge=0.0, le=3600.0, description="peak-to-peak about X")
    camera_drift_pp_arcsec: float = Field(3.0, ge=0.0, le=3600.0,
                                          description="each camera's drift against the prism (common to both, cancels)")
    prism_drift_pp_arcsec: float = Field(2.0, ge=0.0, le=3600.0, description="prism's own drift (cancels)")
    focal_pp_um: float = Field(4.0, ge=0.0, le=10000.0, description="peak-to-peak of each camera's Δf")
    phase_deg: float = Field(30.0, ge=-360.0, le=360.0)
    reference_frames: int = Field(16, ge=1, le=1000, description="frames averaged into the reference spots")
    window_px: int = Field(48, ge=12, le=256, description="fixed ROI read from each CMOS")
    centroider: Literal["tcom", "tcom_peak"] = Field(
        "tcom", description="spot centroider: the thresholded centre of mass of the whole ROI (seed 003), or of "
                            "the brightest blob only (a ghost the threshold separates from the spot is left out)")
    spp: int = Field(256, ge=16, le=65536, description="light paths per ROI pixel")


class BoresightRig(_Model):
    """The dual line-array camera with its central prism (seed 003)."""

    name: str = Field(min_length=1)
    seed_document: str = "003"
    description: str = ""
    cameras: Annotated[list[LineCamera], Field(min_length=1, max_length=2)]
    laser: Laser = Laser()
    detector: DetectorConfig = DetectorConfig()
    study: StudySettings = StudySettings()
    orbit: OrbitScenario = OrbitScenario()
    effects: BoresightEffects = Field(default_factory=BoresightEffects,
                                      description="what a real rig shows beyond the ideal frame (docs/effects.md)")

    @model_validator(mode="after")
    def _names(self):
        names = [c.name for c in self.cameras]
        if len(set(names)) != len(names):
            raise ValueError(f"camera names must be unique, got {names}")
        if self.seed_document != "003":
            raise ValueError(f"seed_document = {self.seed_document!r}: this schema describes seed 003")
        return self

    def camera(self, name: str) -> LineCamera:
        for c in self.cameras:
            if c.name == name:
                return c
        raise KeyError(f"no camera {name!r}; this rig has {[c.name for c in self.cameras]}")
