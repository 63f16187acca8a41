"""The star-sensor rig (seed 004): typed, immutable, loaded from ``scenes/star_sensor.toml``.

One file describes the *true* instrument (what is rendered; estimators never see it), the sky
model, the attitude sequence, and the settings of identification, calibration and the study.
Units are in the field names. Errors in a file become :class:`rigsim.errors.RigError` naming
the file, the field, the value and the allowed range.

Camera conventions are rigsim's (docs/conventions.md): OpenCV pixel origin (pixel (0,0)'s centre
at (0,0)), camera frame x right (+u), y down (+v), z boresight; Brown distortion in OpenCV's
normalised form. Attitudes are ``R_cam_from_icrs``.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import Field, StrictBool, model_validator

from rigsim.detector.config import DetectorConfig
from rigsim.optics.camera import PinholeBrown, brown_undistort, radial_r2_max
from rigsim.rig.effects import StarEffects
from rigsim.rig.model import RigModel

__all__ = [
    "PSF",
    "Calibration",
    "CentroidMapSpec",
    "Identification",
    "Nominal",
    "NominalSensor",
    "NominalStarRig",
    "Sequence",
    "Sky",
    "StarRig",
    "StarSensor",
    "Study",
    "psf_sigma_px",
]



class _Model(RigModel):
    pass


Pair = Annotated[list[float], Field(min_length=2, max_length=2)]


class PSF(_Model):
    """Defocused point-spread function.

    A star sensor is defocused on purpose so that a star covers a few pixels (sub-pixel
    centroiding needs it). Geometrically the defocused image of a point is the aperture's blur
    disk of diameter ``defocus_um / N`` (N = f / D); rigsim uses the circular Gaussian with the
    same second moments (σ = blur radius / 2), combined in quadrature with the Gaussian
    approximation of the Airy core (σ = 0.42 λ N). ``sigma_px`` overrides the computed width.
    """

    model: Literal["gaussian"] = "gaussian"
    defocus_um: float = Field(100.0, ge=0.0, le=5000.0, description="detector distance from best focus")
    wavelength_nm: float = Field(600.0, gt=200.0, le=2000.0, description="effective wavelength of the band")
    sigma_px: float | None = Field(None, gt=0.1, le=10.0, description="override: Gaussian σ in pixels")


def psf_sigma_px(psf: PSF, f_number: float, pixel_pitch_um: float) -> float:
    """σ (px) of the Gaussian PSF: the defocus blur disk's (radius/2) and the Airy core's (0.42 λN),
    in quadrature; ``psf.sigma_px`` overrides."""
    if psf.sigma_px is not None:
        return float(psf.sigma_px)
    s_def = psf.defocus_um / f_number / 2.0 / 2.0
    s_diff = 0.42 * psf.wavelength_nm * 1e-3 * f_number
    return math.hypot(s_def, s_diff) / pixel_pitch_um


class StarSensor(_Model):
    """The true star sensor: pinhole + Brown distortion, optics, PSF, detector."""

    resolution_px: Annotated[list[Annotated[int, Field(ge=16, le=8192)]], Field(min_length=2, max_length=2)] = [1024, 1024]
    pixel_pitch_um: float = Field(15.0, gt=0.5, le=100.0)
    focal_length_mm: float = Field(43.3, gt=1.0, le=5000.0)
    principal_point_px: Pair = [511.5, 511.5]
    k1: float = Field(0.0, ge=-2.0, le=2.0, description="radial, OpenCV normalised")
    k2: float = Field(0.0, ge=-20.0, le=20.0, description="radial, OpenCV normalised")
    p1: float = Field(0.0, ge=-0.1, le=0.1, description="tangential (optional)")
    p2: float = Field(0.0, ge=-0.1, le=0.1, description="tangential (optional)")
    aperture_diameter_mm: float = Field(20.0, gt=0.1, le=1000.0)
    optics_transmission: float = Field(0.7, gt=0.0, le=1.0)
    psf: PSF = Field(default_factory=PSF)
    detector: DetectorConfig = Field(default_factory=DetectorConfig)

    @model_validator(mode="after")
    def _check(self):
        W, H = self.resolution_px
        u0, v0 = self.principal_point_px
        if not (0.0 <= u0 <= W - 1 and 0.0 <= v0 <= H - 1):
            raise ValueError(f"principal_point_px = {self.principal_point_px} must lie on the detector "
                             f"(0..{W - 1}, 0..{H - 1} px)")
        # the whole detector must lie inside the distortion model's monotonic domain
        corners_u = [-0.5 - u0, W - 0.5 - u0]
        corners_v = [-0.5 - v0, H - 0.5 - v0]
        xd = [cu / self.f_px for cu in corners_u for _ in corners_v]
        yd = [cv / self.f_px for _ in corners_u for cv in corners_v]
        r2max = radial_r2_max(self.k1, self.k2, 0.0)
        _x, _y, ok = brown_undistort(xd, yd, self.k1, self.k2, self.p1, self.p2, 0.0, r2max)
        if not ok.all():
            raise ValueError(f"k1 = {self.k1}, k2 = {self.k2}, p1 = {self.p1}, p2 = {self.p2}: the distortion "
                             f"folds back (or cannot be inverted) inside the detector")
        return self

    @property
    def f_px(self) -> float:
        return self.focal_length_mm * 1000.0 / self.pixel_pitch_um

    @property
    def f_number(self) -> float:
        return self.focal_length_mm / self.aperture_diameter_mm

    @property
    def aperture_area_cm2(self) -> float:
        return math.pi * (self.aperture_diameter_mm / 20.0) ** 2

    @property
    def psf_sigma_px(self) -> float:
        return psf_sigma_px(self.psf, self.f_number, self.pixel_pitch_um)

    @property
    def fov_deg(self) -> tuple[float, float]:
        W, H = self.resolution_px
        return (2 * math.degrees(math.atan(W / 2 / self.f_px)), 2 * math.degrees(math.atan(H / 2 / self.f_px)))

    def camera(self, *, f_px: float | None = None, principal_point_px=None, k1=None, k2=None) -> PinholeBrown:
        """The true camera (or a variant with some intrinsics replaced)."""
        f = self.f_px if f_px is None else float(f_px)
        u0, v0 = self.principal_point_px if principal_point_px is None else principal_point_px
        return PinholeBrown(f, f, float(u0), float(v0), self.k1 if k1 is None else float(k1),
                            self.k2 if k2 is None else float(k2), self.p1, self.p2, 0.0,
                            *self.resolution_px)


class Sky(_Model):
    """Star catalogue and radiometry."""

    catalogue: Literal["hipparcos2"] = "hipparcos2"
    epoch_year: float = Field(2025.0, ge=1900.0, le=2100.0, description="observation epoch (Julian year, TT)")
    magnitude_limit: float = Field(6.5, ge=-2.0, le=12.0, description="faintest Hp magnitude rendered")
    zero_point_photons_per_s_cm2: float = Field(1.5e6, gt=0.0, le=1e9,
                                                description="photons per s per cm² from an Hp = 0 star in the sensor band")
    background_mag_per_arcsec2: float = Field(21.0, ge=5.0, le=30.0, description="diffuse sky + stray light surface brightness")


class Sequence(_Model):
    """Attitude sequence of the observation (see rigsim.truth.star)."""

    kind: Literal["inertial", "slew", "random"] = "slew"
    n_frames: int = Field(20, ge=1, le=100000)
    frame_interval_s: float = Field(1.0, gt=0.0, le=86400.0)
    start_ra_deg: float = Field(80.0, ge=0.0, lt=360.0)
    start_dec_deg: float = Field(20.0, ge=-90.0, le=90.0)
    start_roll_deg: float = Field(0.0, ge=-360.0, le=360.0)
    slew_rate_deg_per_s: float = Field(0.5, ge=0.0, le=10.0, description="kind = 'slew'")
    slew_direction_deg: float = Field(30.0, ge=-360.0, le=360.0,
                                      description="direction of the boresight's motion in the image, from +u towards +v")
    roll_rate_deg_per_s: float = Field(0.2, ge=-10.0, le=10.0, description="kind = 'slew': rotation about the boresight")
    jitter_arcsec: float = Field(0.0, ge=0.0, le=3600.0, description="random attitude noise per frame (1σ per axis)")
    smear_substeps: int = Field(1, ge=1, le=64, description="sub-exposures per frame for motion smear (1 = snapshot)")


class Identification(_Model):
    """Matching detected stars against the catalogue near an approximate attitude."""

    attitude_error_deg: float = Field(0.3, ge=0.0, le=20.0,
                                      description="error of the a-priori attitude (rotation angle, random axis)")
    search_radius_px: float = Field(60.0, gt=0.0, le=2000.0, description="largest offset of a star from its predicted position")
    match_tolerance_px: float = Field(2.0, gt=0.0, le=50.0, description="final residual tolerance after the attitude fit")
    min_matches: int = Field(4, ge=3, le=1000)
    focal_length_tolerance: float = Field(0.05, ge=0.0, le=0.3, description="lost in space: the nominal focal length's "
                                          "largest relative error (the true f is searched in f / (1 ± this))")
    pattern_tolerance_px: float = Field(1.0, gt=0.0, le=10.0, description="lost in space: centroid error allowed in "
                                        "a 4-star pattern's edges (noise and distortion the nominal model leaves)")
    false_match_probability: float = Field(1e-9, gt=0.0, le=1e-3, description="lost in space: the largest accepted "
                                           "chance that an identification is a coincidence")

    def lost_in_space_settings(self) -> dict:
        """The keyword arguments of :func:`rigsim.estimation.star_lis.identify_lost_in_space`."""
        return {"focal_length_tolerance": self.focal_length_tolerance, "match_tolerance_px": self.match_tolerance_px,
                "min_matches": self.min_matches, "pattern_tolerance_px": self.pattern_tolerance_px,
                "false_match_probability": self.false_match_probability}


class Nominal(_Model):
    """What the user believes about the sensor before calibration (design and ground calibration)
    and how sure they are: the only intrinsics the estimators see. Without this table the nominal
    sensor is the design: the ``[sensor]`` focal length, the principal point at the detector centre
    and no distortion."""

    focal_length_mm: float = Field(gt=1.0, le=5000.0, description="assumed focal length")
    focal_length_sigma_px: float = Field(10.0, gt=0.0, le=1000.0, description="its 1σ (the joint EKF's prior)")
    principal_point_px: Pair = Field(description="assumed principal point")
    principal_point_sigma_px: float = Field(10.0, gt=0.0, le=1000.0, description="its 1σ (the EKFs' prior)")
    k1: float = Field(0.0, ge=-2.0, le=2.0, description="assumed radial distortion (OpenCV normalised)")
    k2: float = Field(0.0, ge=-20.0, le=20.0)
    p1: float = Field(0.0, ge=-0.1, le=0.1, description="assumed tangential distortion")
    p2: float = Field(0.0, ge=-0.1, le=0.1)
    centroid_map: Literal["none", "traced_lens"] = Field(
        "none", description="ground calibration of the lens's star-image centroid shift: 'traced_lens' = a collimator "
                            "map of the traced lens (rigsim.procedures.star.ground_map) that the pipeline subtracts")
    centroid_map_bv: float = Field(0.65, ge=-0.4, le=2.0, description="B−V of the map's reference star spectrum")
    centroid_map_sigma_px: float = Field(0.01, ge=0.0, le=1.0,
                                         description="the bench's measurement error per map node and axis (1σ)")


class Calibration(_Model):
    """Estimators: AD / ADS EKF over the sequence and batch least squares."""

    max_stars_per_frame: int = Field(20, ge=3, le=200)
    weighting: Literal["propagated", "diagonal"] = "propagated"
    ads_variant: Literal["exact", "improved"] = "exact"
    process_noise_px: float = Field(0.0, ge=0.0, le=100.0, description="EKF process noise per frame (1σ)")
    centroid_method: Literal["gauss", "wcom", "tcom", "model"] = Field(
        "gauss", description="'gauss': a Gaussian fitted with its width; 'wcom' / 'tcom': windowed / thresholded "
                             "centre of mass; 'model': the image the optics predict (the traced lens's PSF with "
                             "[effects.traced_psf] on, else the [sensor.psf] Gaussian) fitted by maximum likelihood, "
                             "positions at the camera model's image point (docs/effects-star.md)")
    distortion_terms: Literal["auto", "none", "k1", "k1,k2"] = Field(
        "auto", description="distortion fitted with the intrinsics and attitudes together (the joint fit): 'auto' "
                            "= k1, and k2 when the data support it (χ² lower by more than 9)")
    background: Literal["model", "map"] = Field(
        "model", description="the sky background the stars are found against: 'model' = one level, the detector "
                             "model's offset and noise; 'map' = a level and noise map measured on each frame (sky "
                             "glow, gradients, vignetting), stars found by a matched filter (Gaussian fit only)")
    single_pixel_filter: StrictBool = Field(True, description="repair single-pixel events (hot pixels, particle "
                                                               "hits) before extracting the stars")
    reject_poor_fits: StrictBool = Field(True, description="leave out of the calibration the stars whose PSF fit is "
                                                            "poor (reduced χ² far above 1: a particle hit, a blend)")
    poor_fit_reference: Literal["model", "frame"] = Field(
        "model", description="what a poor fit is judged against: the noise model alone, or also the frame's "
                             "other stars (a PSF that is not a Gaussian at all: only the stars whose unexplained "
                             "share of signal stands out of their frame are poor)")
    fixed_pattern: Literal["none", "sequence"] = Field(
        "none", description="subtract the detector's fixed pattern (hot pixels, DSNU) estimated from the sequence "
                            "itself (per-pixel median over the frames) before extracting the stars")


    @model_validator(mode="after")
    def _check(self):
        if self.background == "map" and self.centroid_method != "gauss":
            raise ValueError(f"background = 'map' fits every star with a Gaussian: centroid_method must be 'gauss', "
                             f"got {self.centroid_method!r}")
        return self


class Study(_Model):
    """Monte-Carlo comparison of AD and ADS (u0/v0 accuracy over many trials)."""

    trials: int = Field(200, ge=2, le=100000)
    centroid_sigma_px: float | None = Field(None, gt=0.0, le=10.0,
                                            description="per-axis centroid noise; None = measured on rendered frames")
    seed: int = Field(4, ge=0)


class _LensDesign(_Model):
    """The traced lens's design as the pipeline knows it: the ``[sensor]`` optics and the
    ``[effects.traced_psf]`` band and sampling (the design, not a measurement of the instrument)."""

    aperture_diameter_mm: float
    reference_wavelength_nm: float
    defocus_um: float
    band_min_nm: float
    band_max_nm: float
    wavelengths: int
    pupil_rays: int
    oversample: int


class CentroidMapSpec(_LensDesign):
    """The ``[nominal] centroid_map = "traced_lens"`` ground calibration as the pipeline knows it: the lens
    design it was measured on, the reference star colour and the bench's error
    (rigsim.procedures.star.ground_map builds the map)."""

    reference_bv: float
    sigma_px: float
    seed: int


class TracedLensSpec(_LensDesign):
    """The lens design the star images come from when ``[effects.traced_psf]`` is on, as the pipeline's
    forward-model centroider (``centroid_method = "model"``) knows it, with the PSF table's field nodes."""

    field_nodes: int


class NominalSensor(_Model):
    """The star sensor as the estimators know it: the detector and optics design (resolution, pitch,
    PSF, detector settings) and the ``[nominal]`` intrinsics. :meth:`StarRig.nominal_rig` builds it."""

    resolution_px: tuple[int, int]
    pixel_pitch_um: float
    focal_length_mm: float
    principal_point_px: tuple[float, float]
    k1: float
    k2: float
    p1: float
    p2: float
    focal_length_sigma_px: float
    principal_point_sigma_px: float
    psf_sigma_px: float
    detector: DetectorConfig
    centroid_map: CentroidMapSpec | None = None
    traced_lens: TracedLensSpec | None = None

    @property
    def f_px(self) -> float:
        return self.focal_length_mm * 1000.0 / self.pixel_pitch_um

    @property
    def theta(self) -> tuple[float, float, float, float, float]:
        """(f, u0, v0, k1, k2) in the order of :data:`rigsim.estimation.star_calibration.THETA_NAMES`."""
        return (self.f_px, *self.principal_point_px, self.k1, self.k2)

    def camera(self, *, f_px: float | None = None, principal_point_px=None, k1=None, k2=None) -> PinholeBrown:
        """The nominal camera (or a variant with some intrinsics replaced)."""
        f = self.f_px if f_px is None else float(f_px)
        u0, v0 = self.principal_point_px if principal_point_px is None else principal_point_px
        return PinholeBrown(f, f, float(u0), float(v0), self.k1 if k1 is None else float(k1),
                            self.k2 if k2 is None else float(k2), self.p1, self.p2, 0.0, *self.resolution_px)


class NominalStarRig(_Model):
    """What the star-calibration pipeline may see: the nominal sensor and the procedure's settings
    (sky, commanded sequence, identification, calibration). No truth."""

    name: str
    sensor: NominalSensor
    sky: Sky
    sequence: Sequence
    identification: Identification
    calibration: Calibration


class StarRig(_Model):
    name: str = Field(min_length=1)
    seed_document: Literal["004"] = "004"
    description: str = ""
    sensor: StarSensor = Field(default_factory=StarSensor)
    nominal: Nominal | None = None
    sky: Sky = Field(default_factory=Sky)
    sequence: Sequence = Field(default_factory=Sequence)
    identification: Identification = Field(default_factory=Identification)
    calibration: Calibration = Field(default_factory=Calibration)
    study: Study = Field(default_factory=Study)
    effects: StarEffects = Field(default_factory=StarEffects)

    @property
    def nominal_intrinsics(self) -> Nominal:
        """The ``[nominal]`` table, or the design when the file has none (see :class:`Nominal`)."""
        if self.nominal is not None:
            return self.nominal
        W, H = self.sensor.resolution_px
        return Nominal(focal_length_mm=self.sensor.focal_length_mm, principal_point_px=[(W - 1) / 2.0, (H - 1) / 2.0])

    def centroid_map_spec(self) -> CentroidMapSpec | None:
        """The ``[nominal] centroid_map``: None, or what the pipeline needs to rebuild the ground map (the
        bench's error drawn from ``[sensor.detector] sensor_seed``: one instrument, one ground calibration)."""
        s, n, tp = self.sensor, self.nominal_intrinsics, self.effects.traced_psf
        if n.centroid_map == "none":
            return None
        return CentroidMapSpec(reference_bv=n.centroid_map_bv, sigma_px=n.centroid_map_sigma_px, seed=s.detector.sensor_seed,
                               aperture_diameter_mm=s.aperture_diameter_mm, reference_wavelength_nm=s.psf.wavelength_nm,
                               defocus_um=s.psf.defocus_um, band_min_nm=tp.band_min_nm, band_max_nm=tp.band_max_nm,
                               wavelengths=tp.wavelengths, pupil_rays=tp.pupil_rays, oversample=tp.oversample)

    def traced_lens_spec(self) -> TracedLensSpec | None:
        """The lens design of ``[effects.traced_psf]`` when it is on (None: the ``[sensor.psf]`` Gaussian)."""
        s, tp = self.sensor, self.effects.traced_psf
        if not tp.enabled:
            return None
        return TracedLensSpec(aperture_diameter_mm=s.aperture_diameter_mm, reference_wavelength_nm=s.psf.wavelength_nm,
                              defocus_um=s.psf.defocus_um, band_min_nm=tp.band_min_nm, band_max_nm=tp.band_max_nm,
                              wavelengths=tp.wavelengths, field_nodes=tp.field_nodes, pupil_rays=tp.pupil_rays,
                              oversample=tp.oversample)

    def nominal_rig(self) -> NominalStarRig:
        """The rig as the estimators may see it (:class:`NominalStarRig`)."""
        s, n = self.sensor, self.nominal_intrinsics
        sensor = NominalSensor(resolution_px=tuple(s.resolution_px), pixel_pitch_um=s.pixel_pitch_um,
                               focal_length_mm=n.focal_length_mm, principal_point_px=tuple(n.principal_point_px),
                               k1=n.k1, k2=n.k2, p1=n.p1, p2=n.p2, focal_length_sigma_px=n.focal_length_sigma_px,
                               principal_point_sigma_px=n.principal_point_sigma_px,
                               psf_sigma_px=psf_sigma_px(s.psf, n.focal_length_mm / s.aperture_diameter_mm,
                                                         s.pixel_pitch_um),
                               detector=s.detector, centroid_map=self.centroid_map_spec(),
                               traced_lens=self.traced_lens_spec())
        return NominalStarRig(name=self.name, sensor=sensor, sky=self.sky, sequence=self.sequence,
                              identification=self.identification, calibration=self.calibration)
