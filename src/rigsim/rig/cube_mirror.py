"""Typed, immutable rig descriptions (pydantic v2).

One rig file (TOML, in ``scenes/``) describes one physical rig instance: nominal geometry,
the *true* errors of this instance (what the simulator renders; estimators never see
them) and the 1σ specifications of the error sources (what Monte-Carlo campaigns draw).
Units are in the field names: ``_mm``, ``_um``, ``_px``, ``_deg``, ``_arcsec``, ``_arcmin``.

Frames (see docs/conventions.md):
- ``rot``   turntable frame: the base frame of the turntable, equal to the mount frame at
            zero pose. Axes X', Y', Z'.
- ``mount`` the innermost frame (where sensor and cube are fixed); moves with the table.
- ``sun``   sensor measurement frame: x along +u (columns), y along +v (rows), z boresight.
- ``cube``  / ``pm`` / ``ref``: mirror-cube frame; face "+Z" is the face whose outward normal
            is +Z (the document's XY face), etc.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from rigsim.detector.config import DetectorConfig
from rigsim.optics.camera import PinholeBrown
from rigsim.rig.effects_cube import CubeMirrorEffects, cube_effect_names
from rigsim.rig.model import RigModel

FaceName = Literal["+X", "-X", "+Y", "-Y", "+Z", "-Z"]
AxisLabel = Literal["X", "Y", "Z"]

Small3 = Annotated[list[Annotated[float, Field(ge=-3600.0, le=3600.0)]], Field(min_length=3, max_length=3)]
"""A small rotation vector in arcseconds (each component within ±1°)."""


class _Model(RigModel):
    pass


class Orientation(_Model):
    """A rotation R_b_from_a given as Euler angles with an explicit scipy sequence.

    Lower-case ``euler_seq`` is extrinsic (rotations about the fixed a-frame axes), upper-case
    intrinsic — scipy's rule. The matrix is ``Rotation.from_euler(seq, angles).as_matrix()``.
    """

    euler_seq: str = "xyz"
    euler_deg: Annotated[list[Annotated[float, Field(ge=-360.0, le=360.0)]], Field(min_length=3, max_length=3)] = [0.0, 0.0, 0.0]

    @field_validator("euler_seq")
    @classmethod
    def _seq(cls, v: str) -> str:
        ok = len(v) == 3 and (set(v) <= set("xyz") or set(v) <= set("XYZ")) and v[0] != v[1] and v[1] != v[2]
        if not ok:
            raise ValueError(f"must be a 3-letter scipy Euler sequence of x/y/z (all lower = extrinsic, all upper = intrinsic), got {v!r}")
        return v

    def matrix(self) -> np.ndarray:
        from scipy.spatial.transform import Rotation  # here: keeps `rigsim --help` fast

        return Rotation.from_euler(self.euler_seq, self.euler_deg, degrees=True).as_matrix()


class TurntableAxis(_Model):
    """One turntable axis. Axes are listed outermost (fixed to the base) first."""

    name: str = Field(min_length=1, description="outer / middle / inner")
    label: AxisLabel = Field(description="nominal direction at zero pose: X', Y' or Z' of the rot frame")
    range_deg: Annotated[list[float], Field(min_length=2, max_length=2)] = [-360.0, 360.0]
    # specifications (1σ), drawn by Monte-Carlo campaigns
    encoder_sigma_arcsec: float = Field(0.0, ge=0.0, le=3600.0, description="angle readout accuracy (1σ)")
    # true errors of this instance
    encoder_bias_arcsec: float = Field(0.0, ge=-3600.0, le=3600.0, description="true readout offset")
    misalignment_arcsec: Small3 = Field([0.0, 0.0, 0.0], description="true small rotation of this axis's direction (rot frame, arcsec)")
    wobble_arcsec: float = Field(0.0, ge=0.0, le=600.0, description="true axis wobble amplitude")
    wobble_phase_deg: float = Field(0.0, ge=-360.0, le=360.0)

    @field_validator("range_deg")
    @classmethod
    def _range(cls, v):
        lo, hi = v
        if not (-720.0 <= lo < hi <= 720.0):
            raise ValueError(f"must be [low, high] with -720 ≤ low < high ≤ 720 degrees, got {v}")
        return v


class Turntable(_Model):
    kind: Literal["2-axis", "3-axis"]
    axes: list[TurntableAxis]
    perpendicularity_sigma_arcsec: float = Field(0.0, ge=0.0, le=600.0, description="spec of axis non-perpendicularity (1σ), drawn by Monte Carlo")
    accuracy_note: str = ""

    @model_validator(mode="after")
    def _axes(self):
        n = {"2-axis": 2, "3-axis": 3}[self.kind]
        if len(self.axes) != n:
            raise ValueError(f"a {self.kind} turntable needs exactly {n} [[turntable.axes]] entries, got {len(self.axes)}")
        labels = [a.label for a in self.axes]
        if len(set(labels)) != len(labels):
            raise ValueError(f"axis labels must differ, got {labels}")
        names = [a.name for a in self.axes]
        if len(set(names)) != len(names):
            raise ValueError(f"axis names must differ, got {names}")
        return self

    def axis(self, label: str) -> TurntableAxis:
        for a in self.axes:
            if a.label == label or a.name == label:
                return a
        raise KeyError(label)


class SunSimulator(_Model):
    aperture_mm: float = Field(gt=0.0, le=2000.0)
    collimation_full_angle_arcmin: float = Field(gt=0.0, le=600.0, description="full angle subtended by the source (sun: 32′)")
    distance_mm: float = Field(1000.0, gt=0.0, le=1e6, description="simulator exit aperture to turntable centre")
    direction_misalignment_arcsec: Small3 = [0.0, 0.0, 0.0]


class CubeMirror(_Model):
    edge_mm: float = Field(gt=0.0, le=200.0)
    R_cube_from_sun: Orientation = Field(description="TRUE orientation of the cube relative to the sensor measurement frame")
    face_tilt_arcsec: dict[FaceName, Small3] = Field(default_factory=dict, description="true per-face normal error (non-orthogonality)")
    face_flatness_note: str = ""
    centre_in_mount_mm: Annotated[list[float], Field(min_length=3, max_length=3)] = [0.0, 0.0, -60.0]


class DiaphragmScreen(_Model):
    hole_diameter_mm: float = Field(gt=0.0, le=100.0)
    width_mm: float = Field(gt=0.0, le=2000.0)
    height_mm: float = Field(gt=0.0, le=2000.0)
    distance_from_simulator_mm: float = Field(gt=0.0, le=10000.0)
    distance_to_cube_mm: float = Field(gt=0.0, le=100000.0, description="hole to cube face (the lever arm of the reflected spot)")

    @model_validator(mode="after")
    def _hole_fits(self):
        if self.hole_diameter_mm >= min(self.width_mm, self.height_mm):
            raise ValueError(
                f"hole_diameter_mm = {self.hole_diameter_mm} must be smaller than the screen "
                f"(min(width_mm, height_mm) = {min(self.width_mm, self.height_mm)})"
            )
        return self


class AimingCamera(_Model):
    resolution_px: Annotated[list[Annotated[int, Field(ge=16, le=20000)]], Field(min_length=2, max_length=2)]
    pixel_pitch_um: float = Field(gt=0.0, le=100.0)
    focal_length_mm: float = Field(gt=0.0, le=5000.0)
    working_distance_mm: float = Field(gt=0.0, le=10000.0)
    view_angle_deg: float = Field(0.0, ge=0.0, lt=80.0, description="angle between the camera axis and the screen normal")
    concentric_threshold_px: float = Field(1.0, gt=0.0, le=1000.0, description="search stops when |offset| is below this (Table 1: 1 px)")
    null_sigma_px: float = Field(1.0, ge=0.0, le=100.0, description="1σ residual hole/spot offset at the end of the search (paper's σ1)")
    mounting_sigma_arcsec: float = Field(0.0, ge=0.0, le=3600.0, description="paper's σ3: equivalent null bias from the camera mounting (1σ)")
    mounting_bias_arcsec: Small3 = Field([0.0, 0.0, 0.0], description="true equivalent null bias of this instance (arcsec)")
    flat_frames: int = Field(
        16, ge=0, le=256, description="pipeline: frames of the screen lit evenly by a lamp (the simulator shuttered), "
        "averaged into a flat field that divides the spot (the screen's grain, the camera's PRNU); 0: no flat "
        "(docs/effects-screen.md)")
    hole_background: Literal["none", "plane"] = Field(
        "plane", description="pipeline: the hole fit's background — plane (the lit screen's level and gradient from "
                             "the frame's border, for room light) or none (the dark offset only, the paper's; docs/effects.md)")
    detector: DetectorConfig = Field(default_factory=DetectorConfig)

    @property
    def object_pixel_mm(self) -> float:
        """Size of one pixel projected onto the screen (on-axis pinhole)."""
        return self.pixel_pitch_um * 1e-3 * self.working_distance_mm / self.focal_length_mm


class Autocollimator(_Model):
    focal_length_mm: float = Field(gt=0.0, le=5000.0)
    aperture_mm: float = Field(gt=0.0, le=1000.0)
    resolution_px: Annotated[list[Annotated[int, Field(ge=16, le=20000)]], Field(min_length=2, max_length=2)]
    pixel_pitch_um: float = Field(gt=0.0, le=100.0)
    resolution_arcsec: float = Field(gt=0.0, le=60.0, description="reading resolution / accuracy (1σ): 0.1″ for CZ-2")
    distance_mm: float = Field(500.0, gt=0.0, le=100000.0, description="objective to the mirror")
    null_threshold_arcsec: float = Field(0.1, gt=0.0, le=600.0, description="rendered campaign: a null search stops when both readings are below this")
    setup_error_arcsec: float = Field(30.0, ge=0.0, le=600.0, description="rendered step A: 1σ per axis of the instrument's pointing before it is adjusted on the plane mirror")
    detector: DetectorConfig = Field(default_factory=DetectorConfig)


class PlaneMirror(_Model):
    perpendicularity_spec_arcsec: float = Field(10.0, ge=0.0, le=3600.0, description="spec: normal vs inner axis (patent: < 10″)")
    normal_tilt_arcsec: Small3 = Field([0.0, 0.0, 0.0], description="true small rotation of the mirror normal from the inner axis")
    diameter_mm: float = Field(50.0, gt=0.0, le=1000.0)


class Distortion(_Model):
    """Brown–Conrady coefficients in OpenCV's order and normalisation."""

    k1: float = Field(0.0, ge=-10.0, le=10.0)
    k2: float = Field(0.0, ge=-10.0, le=10.0)
    p1: float = Field(0.0, ge=-1.0, le=1.0)
    p2: float = Field(0.0, ge=-1.0, le=1.0)
    k3: float = Field(0.0, ge=-10.0, le=10.0)

    def as_array(self) -> np.ndarray:
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])


class SunSensor(_Model):
    resolution_px: Annotated[list[Annotated[int, Field(ge=16, le=20000)]], Field(min_length=2, max_length=2)]
    pixel_pitch_um: float = Field(gt=0.0, le=100.0)
    focal_length_mm: float = Field(gt=0.0, le=1000.0)
    fy_over_fx: float = Field(1.0, gt=0.5, lt=2.0)
    principal_point_px: Annotated[list[float], Field(min_length=2, max_length=2)]
    distortion: Distortion = Field(default_factory=Distortion)
    R_sun_from_mount: Orientation = Field(description="TRUE mounting rotation of the sensor on the turntable's inner frame")
    centroid_sigma_px: float = Field(0.05, ge=0.0, le=10.0, description="1σ centroid noise used by analytic campaigns")
    detector: DetectorConfig = Field(default_factory=DetectorConfig)

    @model_validator(mode="after")
    def _pp_inside(self):
        w, h = self.resolution_px
        u0, v0 = self.principal_point_px
        if not (0 <= u0 <= w - 1 and 0 <= v0 <= h - 1):
            raise ValueError(f"principal_point_px = {self.principal_point_px} must lie on the detector (0..{w - 1}, 0..{h - 1})")
        return self

    @property
    def fx_px(self) -> float:
        return self.focal_length_mm / (self.pixel_pitch_um * 1e-3)

    @property
    def fy_px(self) -> float:
        return self.fx_px * self.fy_over_fx

    def camera_matrix(self) -> np.ndarray:
        u0, v0 = self.principal_point_px
        return np.array([[self.fx_px, 0.0, u0], [0.0, self.fy_px, v0], [0.0, 0.0, 1.0]])

    def camera(self) -> PinholeBrown:
        """The sensor's pinhole + Brown model (OpenCV convention) with these intrinsics."""
        d = self.distortion
        return PinholeBrown(self.fx_px, self.fy_px, *self.principal_point_px, d.k1, d.k2, d.p1, d.p2, d.k3,
                            *self.resolution_px)


class CubeProcedure(_Model):
    """How the cube is measured: which two faces, in which nominal poses (readings of the seeds)."""

    method: Literal["diaphragm", "autocollimator"]
    faces: Annotated[list[FaceName], Field(min_length=2, max_length=2)] = ["+Z", "+Y"]
    nominal_poses_deg: Annotated[list[dict[str, float]], Field(min_length=2, max_length=2)]
    sweep_range_deg: float = Field(60.0, gt=0.0, le=90.0)
    sweep_step_deg: float = Field(5.0, gt=0.0, le=45.0)
    sweep_axes: Annotated[list[AxisLabel], Field(min_length=2, max_length=2)] = ["X", "Y"]
    search_start_deg: Annotated[list[dict[str, float]], Field(min_length=2, max_length=2)] | None = Field(
        None, description="rendered campaign: turntable readings where the fine null search of each face starts "
                          "(coarse acquisition by eye is not modelled); default nominal_poses_deg")
    command_resolution_deg: float = Field(0.0, ge=0.0, le=1.0, description="rendered campaign: turntable commands are "
                                          "rounded to this step (Table 1: 0.001°); 0 = continuous")
    max_search_iterations: int = Field(15, ge=1, le=200, description="rendered campaign: give up a null search after this many frames")
    sweep_centroider: Literal["model", "scurve", "tcom", "wcom", "gauss"] = Field(
        "model", description="sweep frames: 'model' fits the spot the rig's optics predict by maximum likelihood "
        "(docs/forward-model.md); 'scurve' is the first moment with the uniform disk's pixel-phase correction")
    sweep_fit_weights: Literal["centroid_sigma", "equal"] = Field(
        "centroid_sigma", description="sweep fit: 'centroid_sigma' weights each frame by its centroid's 1σ in quadrature "
        "with the floor the residuals show beyond it (docs/forward-model.md); 'equal' weighs every frame alike")
    sweep_outlier_sigma: float = Field(
        8.0, ge=0.0, le=1000.0, description="sweep fit: leave out a frame whose residual, over its centroid's 1σ, "
        "exceeds this many times the robust (MAD) scale of all frames, and refit; 0 keeps every frame (docs/campaign.md)")
    sweep_max_field_deg: float = Field(
        90.0, gt=0.0, le=90.0, description="sweep fit: leave out a frame whose centroid is farther than this from the "
        "axis (the nominal camera: design focal length, principal point at the detector's centre); 90 keeps every frame")

    @model_validator(mode="after")
    def _faces(self):
        if self.faces[0] == self.faces[1] or self.faces[0][1] == self.faces[1][1]:
            raise ValueError(f"faces must be two non-parallel faces, got {self.faces}")
        return self

    @property
    def search_start(self) -> list[dict[str, float]]:
        return self.search_start_deg if self.search_start_deg is not None else self.nominal_poses_deg


class CubeMirrorRig(_Model):
    name: str
    seed_document: Literal["000", "001"]
    description: str = ""
    turntable: Turntable
    sun_simulator: SunSimulator
    sun_sensor: SunSensor
    cube: CubeMirror
    procedure: CubeProcedure
    diaphragm_screen: DiaphragmScreen | None = None
    aiming_camera: AimingCamera | None = None
    autocollimator: Autocollimator | None = None
    plane_mirror: PlaneMirror | None = None
    effects: CubeMirrorEffects = Field(default_factory=CubeMirrorEffects,
                                       description="what a real rig shows beyond the ideal frame (docs/effects.md)")

    @model_validator(mode="after")
    def _devices(self):
        if self.procedure.method == "diaphragm":
            missing = [k for k in ("diaphragm_screen", "aiming_camera") if getattr(self, k) is None]
        else:
            missing = [k for k in ("autocollimator", "plane_mirror") if getattr(self, k) is None]
        if missing:
            raise ValueError(f"procedure.method = {self.procedure.method!r} needs the table(s) {missing}")
        labels = {a.label for a in self.turntable.axes}
        for i, pose in enumerate(self.procedure.nominal_poses_deg):
            bad = set(pose) - labels
            if bad:
                raise ValueError(f"procedure.nominal_poses_deg[{i}] names axes {sorted(bad)}; this turntable has {sorted(labels)}")
        foreign = set(self.effects.enabled) - set(cube_effect_names(self.procedure.method))
        if foreign:
            raise ValueError(f"effects {sorted(foreign)} do not apply to procedure.method = {self.procedure.method!r}; "
                             f"its effects are {', '.join(cube_effect_names(self.procedure.method)) or 'none'}")
        bad = set(self.procedure.sweep_axes) - labels
        if bad:
            raise ValueError(f"procedure.sweep_axes names {sorted(bad)}; this turntable has {sorted(labels)}")
        return self

    @property
    def null_sigma_rad(self) -> float:
        """1σ of a face normal's direction at the end of a null (per axis): the aiming camera's
        residual offset on the screen (the reflection doubles the angle) or the autocollimator's
        reading accuracy."""
        if self.procedure.method == "diaphragm":
            ac = self.aiming_camera
            return ac.null_sigma_px * ac.object_pixel_mm / (2.0 * self.diaphragm_screen.distance_to_cube_mm)
        return self.autocollimator.resolution_arcsec * math.pi / (180.0 * 3600.0)

    # -- derived truth ------------------------------------------------------------------
    def R_sun_from_mount(self) -> np.ndarray:
        return self.sun_sensor.R_sun_from_mount.matrix()

    def R_cube_from_sun(self) -> np.ndarray:
        return self.cube.R_cube_from_sun.matrix()

    def R_cube_from_mount(self) -> np.ndarray:
        return self.R_cube_from_sun() @ self.R_sun_from_mount()
