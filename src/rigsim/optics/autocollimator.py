"""Photoelectric autocollimator: exact numpy model (the truth for rendered frames).

Pure numpy, float64, no Mitsuba: this module is the *independent* computation that the
Mitsuba scene (:mod:`rigsim.render.cube_mirror.autocollimator`) is tested against.

Instrument (docs/render_autocollimator.md)
------------------------------------------
A point reticle (a pinhole source) sits near the back focal plane of a plano-convex N-BK7
singlet objective (flat side towards the reticle, convex side towards the mirror: the
best-form orientation for a collimated beam). The beam leaves along the autocollimator axis,
limited by a circular stop of diameter ``aperture_mm`` just in front of the convex vertex,
reflects off the mirror under test (a cube face or the plane mirror on the inner frame), comes
back through the stop and the lens and lands on the detector, a plane
``source_offset_mm`` (5 µm) behind the reticle. The reticle sits at the *best-collimation*
position (the RMS slope of the outgoing rays is minimal; 0.83 mm inside the paraxial focus for
the seed-001 rig), which is how an autocollimator is focused at infinity.

Truth = an exact Snell trace of every ray (vector refraction at the flat face and the sphere,
unpolarised Fresnel transmission at each of the four crossings, reflection off the mirror
plane, clipping by the stop on both passes and by the mirror's outline), with the reticle's
emission uniform in solid angle over a cone that slightly overfills the stop, sampled by a
deterministic golden-angle quadrature. Spherical aberration is large for a singlet at f/11,
so neither ``f·tan(2t)`` nor any single focal length is the truth: the spot centroid is
computed from the rays (``mean_uv``) and binned into pixels (``pixel_centroid_uv``) exactly as
a rendered image would be.

Frames and pixels
-----------------
Autocollimator frame ``A`` (the Mitsuba scene's world frame): origin at the centre of the lens
(mid-thickness, on the axis), ``+z_A`` along the optical axis towards the mirror, ``x_A`` the
rot frame's X' made perpendicular to the axis, ``y_A = z_A × x_A`` (≈ −Y' for an axis along
+Z'). Detector pixel (u, v) (OpenCV convention, pixel (0,0)'s centre at (0,0)) is the point
``x_A = (u − cx)·pitch``, ``y_A = (v − cy)·pitch`` of the detector plane, with (cx, cy) the
detector centre, which is where the optical axis meets it.

Reading
-------
The true tilt of a mirror is the pair of angles of its normal ``n`` (pointing back at the
autocollimator) in the A frame: ``θx = atan2(n_x, −n_z)``, ``θy = atan2(n_y, −n_z)`` — the
normal tilted towards +x_A gives θx > 0 and moves the spot towards +u. The beam is deviated by
twice that (half the beam deviation = mirror tilt). :meth:`AutocollimatorOptics.reading`
converts a spot position into these two angles with the instrument's calibration (fitted on
the exact model with a large flat mirror, radial form ``F·tan(ρ)·(1 + c·ρ²)``);
:meth:`AutocollimatorOptics.tilt_from_spot` inverts the exact model for a given mirror
outline and position (what a perfect calibration in this very geometry would return).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field, replace

import numpy as np

from rigsim.errors import GeometryError
from rigsim.files.cache import cached_json, source_digest
from rigsim.frames import ARCSEC_PER_RAD

__all__ = [
    "SCHOTT_N_BK7",
    "n_bk7",
    "PlanoConvexObjective",
    "MirrorTarget",
    "RayBundle",
    "SpotTruth",
    "AutocollimatorOptics",
    "flat_mirror",
    "retilt",
    "cone_directions",
    "a_frame_basis",
    "SpotExtent",
    "spot_extent_px",
    "centroid_roi_px",
    "render_window_px",
    "diffraction_half_px",
    "peak_over_noise",
    "MIN_ROI_PX",
    "MIN_RENDER_WINDOW_PX",
]

SCHOTT_N_BK7 = ((1.03961212, 0.00600069867), (0.231792344, 0.0200179144), (1.01046945, 103.560653))
"""Schott Sellmeier coefficients (B_i, C_i in µm²) of N-BK7."""

_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))
_CALIBRATIONS: dict = {}  # (instrument key, n_rays) → factory calibration, shared by equal instruments in a process
_CALIBRATION_KEYS = ("F_mm", "c", "fit_rms_px", "ref_uv", "n_rays", "range_rad", "mirror")


def _code_digest() -> str:
    """The digest of the code the factory calibration runs (this module and the beam splitter's)."""
    from rigsim.optics import beam_splitter

    return source_digest([__file__, beam_splitter.__file__])


def _is_calibration(d: dict, need: tuple, n_rays: int) -> bool:
    """A cached factory calibration holds every number it needs, finite, for ``n_rays``."""
    if set(d) != set(need) or d["n_rays"] != n_rays or not isinstance(d["mirror"], str):
        return False
    nums = [d[k] for k in need if k not in ("mirror", "ref_uv")] + list(d["ref_uv"])
    return len(d["ref_uv"]) == 2 and all(isinstance(v, (int, float)) and math.isfinite(v) for v in nums) and d["F_mm"] > 0


def n_bk7(wavelength_nm: float) -> float:
    """Refractive index of N-BK7 (Schott Sellmeier formula); 1.5168 at 587.56 nm."""
    l2 = (float(wavelength_nm) * 1e-3) ** 2
    return math.sqrt(1.0 + sum(b * l2 / (l2 - c) for b, c in SCHOTT_N_BK7))


# ------------------------------------------------------------------------------ objective
@dataclass(frozen=True)
class PlanoConvexObjective:
    """A plano-convex singlet in the A frame: flat face at z = −t/2, convex vertex at +t/2.

    ``focal_length_mm`` is the paraxial EFL at ``wavelength_nm``; for a plano-convex lens it
    does not depend on the thickness: R = f·(n − 1). ``clear_aperture_mm`` is the stop
    diameter; the glass is ``edge_margin_mm`` wider in radius so that the stop, not the rim,
    limits the beam.
    """

    focal_length_mm: float
    clear_aperture_mm: float
    center_thickness_mm: float = 5.0
    wavelength_nm: float = 587.56
    edge_margin_mm: float = 2.0
    stop_gap_mm: float = 0.5
    glass: str = "N-BK7"

    def __post_init__(self):
        if not (self.focal_length_mm > 0 and self.clear_aperture_mm > 0 and self.center_thickness_mm > 0):
            raise ValueError("focal length, aperture and thickness must be > 0")
        sag = self.sag(self.lens_radius_mm)
        if not math.isfinite(sag) or sag >= self.center_thickness_mm - 0.5:
            raise ValueError(
                f"a plano-convex lens of f = {self.focal_length_mm} mm and Ø{2 * self.lens_radius_mm:g} mm "
                f"needs more than {self.center_thickness_mm} mm centre thickness (sag {sag:.2f} mm)")

    @property
    def n(self) -> float:
        return n_bk7(self.wavelength_nm)

    @property
    def radius_mm(self) -> float:
        return self.focal_length_mm * (self.n - 1.0)

    @property
    def lens_radius_mm(self) -> float:
        return 0.5 * self.clear_aperture_mm + self.edge_margin_mm

    @property
    def stop_radius_mm(self) -> float:
        return 0.5 * self.clear_aperture_mm

    @property
    def z_vertex(self) -> float:
        return 0.5 * self.center_thickness_mm

    @property
    def z_flat(self) -> float:
        return -0.5 * self.center_thickness_mm

    @property
    def z_centre(self) -> float:
        """Centre of curvature of the convex face (inside the glass side, on −z)."""
        return self.z_vertex - self.radius_mm

    @property
    def z_stop(self) -> float:
        return self.z_vertex + self.stop_gap_mm

    @property
    def bfd_paraxial_mm(self) -> float:
        """Paraxial back focal distance from the flat face (light entering the convex side)."""
        return self.focal_length_mm - self.center_thickness_mm / self.n

    def sag(self, r) -> np.ndarray:
        R = self.radius_mm
        r = np.asarray(r, float)
        return R - np.sqrt(np.maximum(R * R - r * r, 0.0)) if np.all(r < R) else np.full_like(r, np.nan)

    def as_dict(self) -> dict:
        return {
            "type": "plano-convex singlet", "glass": self.glass, "wavelength_nm": self.wavelength_nm,
            "n": self.n, "focal_length_mm": self.focal_length_mm, "radius_mm": self.radius_mm,
            "center_thickness_mm": self.center_thickness_mm, "clear_aperture_mm": self.clear_aperture_mm,
            "lens_diameter_mm": 2 * self.lens_radius_mm, "stop_gap_mm": self.stop_gap_mm,
            "bfd_paraxial_mm": self.bfd_paraxial_mm,
        }


# ------------------------------------------------------------------------------ mirror
@dataclass(frozen=True)
class MirrorTarget:
    """The mirror under test in the A frame.

    ``normal`` is the unit outward normal (towards the autocollimator). ``shape`` is
    ``"square"`` (a cube face: ``half_size_mm`` = half the edge, ``e1``/``e2`` its in-plane edge
    directions) or ``"disk"`` (``half_size_mm`` = radius).
    """

    centre: np.ndarray
    normal: np.ndarray
    shape: str
    half_size_mm: float
    e1: np.ndarray
    e2: np.ndarray
    reflectance: float = 1.0
    name: str = ""

    def __post_init__(self):
        if self.shape not in ("square", "disk"):
            raise ValueError(f"MirrorTarget.shape = {self.shape!r}: must be 'square' or 'disk'")

    def inside(self, p: np.ndarray) -> np.ndarray:
        d = np.asarray(p, float) - self.centre
        a, b = d @ self.e1, d @ self.e2
        if self.shape == "square":
            return (np.abs(a) <= self.half_size_mm) & (np.abs(b) <= self.half_size_mm)
        return a * a + b * b <= self.half_size_mm ** 2

    def outline(self, n: int = 256) -> np.ndarray:
        """(n, 3) points on the mirror's edge."""
        if self.shape == "disk":
            ph = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
            return self.centre + self.half_size_mm * (np.cos(ph)[:, None] * self.e1 + np.sin(ph)[:, None] * self.e2)
        k = max(n // 4, 1)
        s = np.linspace(-1.0, 1.0, k, endpoint=False)
        h = self.half_size_mm
        pts = [(x, -1.0) for x in s] + [(1.0, y) for y in s] + [(-x, 1.0) for x in s] + [(-1.0, -y) for y in s]
        pts = np.array(pts) * h
        return self.centre + pts[:, :1] * self.e1 + pts[:, 1:] * self.e2

    def area_points(self, n_side: int = 41) -> np.ndarray:
        """Points spread over the mirror's area (for coverage fractions)."""
        s = (np.arange(n_side) + 0.5) / n_side * 2.0 - 1.0
        a, b = np.meshgrid(s, s)
        a, b = a.ravel(), b.ravel()
        if self.shape == "disk":
            keep = a * a + b * b <= 1.0
            a, b = a[keep], b[keep]
        h = self.half_size_mm
        return self.centre + h * (a[:, None] * self.e1 + b[:, None] * self.e2)

    def tilt_rad(self) -> np.ndarray:
        """True reading: (θx, θy) = (atan2(n_x, −n_z), atan2(n_y, −n_z)) in the A frame."""
        n = self.normal
        return np.array([math.atan2(n[0], -n[2]), math.atan2(n[1], -n[2])])


def _refract(d, nh, eta):
    """Vector Snell refraction of unit rows ``d`` at unit normals ``nh`` facing the incident
    side (d·n < 0); ``eta = n_incident / n_transmitted``. Returns (t, T_unpolarised, ok)."""
    ci = -np.einsum("ij,ij->i", d, nh) if nh.ndim == 2 else -(d @ nh)
    k = 1.0 - eta * eta * (1.0 - ci * ci)
    ok = k > 0.0
    ct = np.sqrt(np.maximum(k, 0.0))
    nn = nh if nh.ndim == 2 else nh[None, :]
    t = eta * d + (eta * ci - ct)[:, None] * nn
    rs = (eta * ci - ct) / (eta * ci + ct)
    rp = (ci - eta * ct) / (ci + eta * ct)
    return t, 1.0 - 0.5 * (rs * rs + rp * rp), ok


def cone_directions(n: int, half_angle_rad: float, offset: float = 0.5) -> np.ndarray:
    """``n`` unit directions uniform in solid angle within a cone about +z (golden-angle spiral,
    stratified in cos θ)."""
    i = np.arange(n, dtype=np.float64)
    c = 1.0 - (i + offset) / n * (1.0 - math.cos(half_angle_rad))
    s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
    ph = i * _GOLDEN_ANGLE
    return np.stack([s * np.cos(ph), s * np.sin(ph), c], axis=-1)


@dataclass
class RayBundle:
    """Result of an exact trace: rays that reached the detector plane and the bookkeeping."""

    uv: np.ndarray  # (m, 2) detector pixel coordinates of the rays that land
    weight: np.ndarray  # (m,) photons carried by each
    emitted_photons: float
    n_rays: int
    frac_stop_out: float  # of the emitted rays, fraction through the stop on the way out
    frac_on_mirror: float  # of those, fraction hitting the mirror
    frac_return: float  # of those, fraction back through the stop and the lens
    mirror_fill_fraction: float  # fraction of the mirror's area inside the beam footprint


@dataclass
class SpotTruth:
    """The exact image of the reticle (pixel coordinates, OpenCV convention)."""

    valid: bool
    mean_uv: np.ndarray | None  # continuous centroid of the image (all rays on the detector plane)
    pixel_centroid_uv: np.ndarray | None  # first moment of the pixel-binned image in ``window``
    window: tuple[int, int, int, int] | None  # (u0, v0, w, h) the binned centroid refers to
    flux_photons: float  # photons reaching the detector plane
    flux_on_detector: float  # … and landing on the detector area
    extent_uv: np.ndarray | None  # [[u_min, v_min], [u_max, v_max]] of the landing rays
    rms_radius_px: float
    tilt_rad: np.ndarray  # true reading (θx, θy) of the mirror
    paraxial_uv: np.ndarray  # where f·tan(2t) (paraxial EFL) would put the spot
    flags: dict = field(default_factory=dict)
    bundle: RayBundle | None = None

    def as_dict(self) -> dict:
        d = {
            "valid": self.valid,
            "spot_mean_uv": None if self.mean_uv is None else self.mean_uv.tolist(),
            "spot_pixel_centroid_uv": None if self.pixel_centroid_uv is None else self.pixel_centroid_uv.tolist(),
            "pixel_centroid_window": None if self.window is None else list(self.window),
            "flux_photons": self.flux_photons,
            "flux_on_detector_photons": self.flux_on_detector,
            "spot_extent_uv": None if self.extent_uv is None else self.extent_uv.tolist(),
            "spot_rms_radius_px": self.rms_radius_px,
            "true_tilt_arcsec": (self.tilt_rad * ARCSEC_PER_RAD).tolist(),
            "paraxial_uv": self.paraxial_uv.tolist(),
        }
        if self.bundle is not None:
            b = self.bundle
            d.update(truth_rays=b.n_rays, beam_fraction_on_mirror=b.frac_on_mirror,
                     return_fraction_through_objective=b.frac_return,
                     mirror_fill_fraction=b.mirror_fill_fraction)
        return d


# ------------------------------------------------------------------------------ spot size
MIN_ROI_PX = 15
"""Smallest centroid window (px): a few pixels of background around the smallest spot."""

MIN_RENDER_WINDOW_PX = 32
"""Smallest render window (px). Mitsuba's ``spp`` counts samples per film pixel, so the light paths
of a frame are spp × window²: 1024 spp over 32² px is the 1.05 M paths (0.0046 px rms centroid
noise) the rendering budget is measured at (docs/render_autocollimator.md). A smaller window would
trace fewer paths and give noisier frames at the same spp."""

_AIRY_FIRST_ZERO = 1.2196698912665045  # first zero of 2·J1(πx)/(πx), in units of λf/D


@dataclass(frozen=True)
class SpotExtent:
    """How far the return spot reaches on the detector, from :func:`spot_extent_px` (pixels).

    ``aperture`` is the return beam's limiting aperture: ``"square"`` (a cube face smaller than the
    beam: a sinc² cross) or ``"circle"`` (the stop, or a disk mirror: an Airy pattern);
    ``aperture_mm`` its side or diameter. ``first_zero_px`` is the first zero of the cross, λf/a,
    or the first dark ring, 1.22·λf/D. ``diffraction_px`` is the distance from the centre out to
    which the pattern of a point stays above ``k_sigma`` × the background noise when its peak is
    ``peak_over_noise`` × that noise (never less than the first zero). ``geometric_px`` is the full
    width of the ray-optics image of the reticle (the reticle's image and the objective's
    aberrations). ``radius_px`` = ``geometric_px``/2 + ``diffraction_px``: the pattern spread over
    the geometric image.
    """

    aperture: str
    aperture_mm: float
    first_zero_px: float
    diffraction_px: float
    geometric_px: float
    k_sigma: float
    peak_over_noise: float

    @property
    def radius_px(self) -> float:
        return 0.5 * self.geometric_px + self.diffraction_px

    def as_dict(self) -> dict:
        return {"aperture": self.aperture, "aperture_mm": self.aperture_mm, "first_zero_px": self.first_zero_px,
                "diffraction_px": self.diffraction_px, "geometric_px": self.geometric_px, "radius_px": self.radius_px,
                "k_sigma": self.k_sigma, "peak_over_noise": self.peak_over_noise}


def spot_extent_px(*, wavelength_nm: float, focal_length_mm: float, pixel_pitch_um: float, beam_diameter_mm: float,
                   mirror_shape: str, mirror_size_mm: float, peak_over_noise: float, k_sigma: float = 3.0,
                   geometric_px: float = 0.0) -> SpotExtent:
    """The return spot's extent in pixels, from the instrument's physics (pure, closed form).

    The limiting aperture is the smaller of the beam (a circle of ``beam_diameter_mm``) and the
    mirror (``mirror_shape`` ``"square"``: a cube face of side ``mirror_size_mm``; ``"disk"``: a
    mirror of that diameter). With s = λ·f/(a·pitch) px:

    * square face, side a: I/I0 = sinc²(x/s)·sinc²(y/s); first zero at s; along the cross's arms
      the lobes follow the envelope (s/(π·x))², so the arms stay above k·σ out to
      x = (s/π)·√(P/k), P = ``peak_over_noise`` (peak over the background noise σ);
    * circle, diameter D: I/I0 = (2·J1(v)/v)², v = π·r/s; first dark ring at 1.22·s; the rings
      follow the envelope 8/(π·v³), above k·σ out to r = (s/π)·(8·P/(π·k))^(1/3).

    A face whose side is at least the beam's diameter is limited by the beam (circle). The square
    bound is conservative for a face between D/√2 and D (its pupil is the square clipped by the
    circle, whose straight edges are shorter). ``geometric_px`` (the ray-optics image's width,
    e.g. from :meth:`AutocollimatorOptics.spot_extent`) is carried into ``radius_px``.
    """
    vals = (wavelength_nm, focal_length_mm, pixel_pitch_um, beam_diameter_mm, mirror_size_mm, peak_over_noise, k_sigma)
    if not all(math.isfinite(float(v)) and v > 0 for v in vals):
        raise ValueError("wavelength, focal length, pitch, beam and mirror sizes, peak_over_noise and k_sigma "
                         f"must be finite and > 0, got {vals}")
    if mirror_shape not in ("square", "disk"):
        raise ValueError(f"mirror_shape = {mirror_shape!r}: must be 'square' or 'disk'")
    if not (math.isfinite(geometric_px) and geometric_px >= 0):
        raise ValueError(f"geometric_px = {geometric_px!r}: must be finite and >= 0")
    if mirror_shape == "square" and mirror_size_mm < beam_diameter_mm:
        aperture, size = "square", float(mirror_size_mm)
    else:
        aperture, size = "circle", float(min(mirror_size_mm, beam_diameter_mm))
    s = wavelength_nm * 1e-6 * focal_length_mm / (size * pixel_pitch_um * 1e-3)
    ratio = peak_over_noise / k_sigma  # the peak in units of the threshold
    if aperture == "square":
        zero = s
        reach = s / math.pi * math.sqrt(ratio)
    else:
        zero = _AIRY_FIRST_ZERO * s
        reach = s / math.pi * (8.0 * ratio / math.pi) ** (1.0 / 3.0)
    return SpotExtent(aperture, size, float(zero), float(max(zero, reach)), float(geometric_px), float(k_sigma),
                      float(peak_over_noise))


def centroid_roi_px(extent: SpotExtent, margin_px: float = 0.5, minimum: int = MIN_ROI_PX) -> int:
    """Odd side of the centroid window. The window is centred on the brightest pixel, which may lie
    anywhere on the geometric image (on a cube face the singlet's image is a ring with its peak on
    the rim: 3.9 px off the centre for the default rig), and it must hold every pixel above k·σ,
    ``extent.radius_px`` from the centre: half side = geometric/2 + radius + ``margin_px`` (pixels
    are not points) = geometric + diffraction + margin; side 2·⌈…⌉ + 1, at least ``minimum``."""
    side = 2 * math.ceil(0.5 * extent.geometric_px + extent.radius_px + margin_px) + 1
    return int(max(side, int(minimum) | 1))


def render_window_px(geometric_px: float, margin_px: float = 3.0, growth: float = 0.05,
                     minimum: int = MIN_RENDER_WINDOW_PX) -> int:
    """Even side of the render window (Mitsuba's ray-optics image, before the diffraction blur),
    centred on the spot's rounded mean: half of it holds half the geometric spot grown by
    ``growth`` (the spot's width changes by < 2 % across the measuring range, and it is up to
    0.65 px lopsided about its mean) plus ``margin_px`` (rounding of the centre and the 1 px margin
    of the ``spot_exceeds_window`` flag): 2·⌈(1 + growth)·geometric/2 + margin⌉, at least
    ``minimum`` (:data:`MIN_RENDER_WINDOW_PX`)."""
    if not (math.isfinite(geometric_px) and geometric_px >= 0):
        raise ValueError(f"geometric_px = {geometric_px!r}: must be finite and >= 0")
    side = 2 * math.ceil(0.5 * (1.0 + growth) * geometric_px + margin_px)
    return int(max(side, int(minimum) + int(minimum) % 2))


def diffraction_half_px(extent: SpotExtent, margin_px: float = 0.5) -> int:
    """Half side of the diffraction kernel the render window is convolved with. Give it an extent
    for k = 1: the pattern, spread over the geometric image, is then below the background noise
    beyond ``extent.radius_px``, so the light the kernel leaves out is ≲ 1σ per pixel (measured on
    the exact model: 1.0σ for the default rig's cube face, 0.4σ for its plane mirror). Half side
    ⌈radius + ``margin_px``⌉ (pixel integration)."""
    return math.ceil(extent.radius_px + margin_px)


def peak_over_noise(detector, peak_fraction: float = 0.5) -> float:
    """Brightest pixel over the background noise of a frame whose peak is ``peak_fraction`` of the
    full well (the renderer's brightness setting): ``detector`` has the fields of
    :class:`rigsim.detector.DetectorConfig`. Noise of a dark pixel in electrons: read noise, dark
    shot noise, DSNU and the ADC's quantisation √(1/12) DN."""
    if not (0.0 < peak_fraction <= 1.0):
        raise ValueError(f"peak_fraction = {peak_fraction!r}: must be in (0, 1]")
    k = float(detector.gain_dn_per_e)
    sigma_e = math.sqrt(detector.read_noise_e ** 2 + detector.dark_current_e_per_s * detector.exposure_s
                        + detector.dsnu_e ** 2 + 1.0 / (12.0 * k * k))
    return float(peak_fraction * detector.full_well_e / sigma_e)


class AutocollimatorOptics:
    """Exact model of one autocollimator (numpy, float64). See the module docstring.

    Parameters: ``ac``, the instrument's specification (any object with the fields of the rig file's ``[autocollimator]`` table: focal_length_mm, aperture_mm, resolution_px, pixel_pitch_um, distance_mm); ``wavelength_nm`` of the
    (monochromatic) reticle light; ``center_thickness_mm`` of the singlet; ``focus``:
    ``"collimated"`` (reticle at the best-collimation position, default) or ``"paraxial"``
    (paraxial focal point); ``source_offset_mm``: the detector plane lies this far behind the
    reticle (the reticle is a point source, not a surface: it casts no shadow); ``overfill``:
    the reticle's cone reaches the stop plane at ``overfill`` × the stop radius;
    ``beam_splitter`` (:class:`~rigsim.optics.beam_splitter.BeamSplitter`, default none): the
    reticle is folded in by reflection off the plate's first surface and the return crosses the
    plate; the detector is centred on the plate's displaced axis and refocused for it.
    """

    def __init__(self, ac, *, wavelength_nm: float = 587.56, center_thickness_mm: float | None = None,
                 focus: str = "collimated", source_offset_mm: float = 0.005, overfill: float = 1.01,
                 beam_splitter=None):
        if focus not in ("collimated", "paraxial"):
            raise ValueError(f"focus = {focus!r}: must be 'collimated' or 'paraxial'")
        if not (0.0 < source_offset_mm < 1.0):
            raise ValueError(f"source_offset_mm = {source_offset_mm!r}: must be in (0, 1) mm")
        if not (1.0 <= overfill <= 1.2):
            raise ValueError(f"overfill = {overfill!r}: must be in [1, 1.2]")
        self.ac = ac
        if center_thickness_mm is None:  # 5 mm, or thick enough for the sag of a fast lens (1 mm edge left)
            probe = PlanoConvexObjective(ac.focal_length_mm, ac.aperture_mm, 1e6, wavelength_nm)
            center_thickness_mm = max(5.0, math.ceil(probe.sag(probe.lens_radius_mm) + 1.0))
        self.objective = PlanoConvexObjective(ac.focal_length_mm, ac.aperture_mm, center_thickness_mm, wavelength_nm)
        self.focus = focus
        self.source_offset_mm = float(source_offset_mm)
        self.overfill = float(overfill)
        self.width, self.height = (int(x) for x in ac.resolution_px)
        self.pitch_mm = ac.pixel_pitch_um * 1e-3
        self.cx = (self.width - 1) / 2.0
        self.cy = (self.height - 1) / 2.0
        self.distance_mm = float(ac.distance_mm)
        self.beam_splitter = beam_splitter
        z_par = self.objective.z_flat - self.objective.bfd_paraxial_mm
        self.focus_shift_mm = 0.0 if focus == "paraxial" else self._best_collimation_shift(z_par)
        self.z_source = z_par + self.focus_shift_mm
        self.z_detector = self.z_source - self.source_offset_mm
        self.detector_xy0 = np.zeros(2)  # where the detector's centre (cx, cy) lies in x_A, y_A
        if beam_splitter is not None:
            # the detector follows the plate's displaced, refocused axis (its axial ray exits the
            # plate −d along x_A; the foci move away from the plate)
            self.z_detector -= beam_splitter.focus_shift_mm
            self.detector_xy0 = np.array([-beam_splitter.lateral_shift_mm, 0.0])
        self.cone_half_angle_rad = self._cone_for_stop(self.overfill)
        self._calib = None
        # everything the exact model depends on: instruments built from equal numbers share one calibration
        self._key = (float(ac.focal_length_mm), float(ac.aperture_mm), (self.width, self.height), float(self.pitch_mm),
                     self.distance_mm, float(wavelength_nm), float(center_thickness_mm), focus, self.source_offset_mm,
                     self.overfill, beam_splitter)

    # -- geometry helpers ----------------------------------------------------------------
    @property
    def source_position(self) -> np.ndarray:
        return np.array([0.0, 0.0, self.z_source])

    @property
    def efl_mm(self) -> float:
        return self.objective.focal_length_mm

    def uv_to_xy(self, uv) -> np.ndarray:
        uv = np.asarray(uv, float)
        return np.stack([(uv[..., 0] - self.cx) * self.pitch_mm + self.detector_xy0[0],
                         (uv[..., 1] - self.cy) * self.pitch_mm + self.detector_xy0[1]], -1)

    def xy_to_uv(self, xy) -> np.ndarray:
        xy = np.asarray(xy, float)
        return np.stack([(xy[..., 0] - self.detector_xy0[0]) / self.pitch_mm + self.cx,
                         (xy[..., 1] - self.detector_xy0[1]) / self.pitch_mm + self.cy], -1)

    def on_detector(self, uv, margin_px: float = 0.0) -> np.ndarray:
        uv = np.asarray(uv, float)
        return ((uv[..., 0] >= -0.5 + margin_px) & (uv[..., 0] < self.width - 0.5 - margin_px)
                & (uv[..., 1] >= -0.5 + margin_px) & (uv[..., 1] < self.height - 0.5 - margin_px))

    def measuring_range_rad(self) -> tuple[float, float]:
        """Half range of the mirror tilt (θx, θy) that keeps the spot centre on the detector
        (paraxial estimate: half-width / f / 2)."""
        return (0.5 * math.atan(0.5 * self.width * self.pitch_mm / self.efl_mm),
                0.5 * math.atan(0.5 * self.height * self.pitch_mm / self.efl_mm))

    def calibration_range_rad(self) -> float:
        """Largest tilt (rad) of the calibration: the measuring range along x, or less when the mirror
        at ``distance_mm`` throws the return beam off the objective sooner — the tilt that shifts it
        by a quarter of the clear aperture (2·t·distance = aperture/4, about 70 % of it back)."""
        returning = 0.5 * math.atan(0.25 * self.objective.clear_aperture_mm / self.distance_mm)
        return min(self.measuring_range_rad()[0], returning)

    # -- exact trace ---------------------------------------------------------------------
    def _outgoing(self, d: np.ndarray, z_source: float | None = None):
        """Reticle → flat face → convex face → stop plane. Returns (P_stop, dir, T, ok)."""
        ob = self.objective
        zs = self.z_source if z_source is None else z_source
        t = (ob.z_flat - zs) / d[:, 2]
        P = np.column_stack([t * d[:, 0], t * d[:, 1], np.full(len(d), ob.z_flat)])
        ok = np.hypot(P[:, 0], P[:, 1]) <= ob.lens_radius_mm
        d1, T1, ok1 = _refract(d, np.array([0.0, 0.0, -1.0]), 1.0 / ob.n)
        C = np.array([0.0, 0.0, ob.z_centre])
        R = ob.radius_mm
        oc = P - C
        b = np.einsum("ij,ij->i", oc, d1)
        c = np.einsum("ij,ij->i", oc, oc) - R * R
        t2 = -b + np.sqrt(np.maximum(b * b - c, 0.0))
        P2 = P + t2[:, None] * d1
        ok &= np.hypot(P2[:, 0], P2[:, 1]) <= ob.lens_radius_mm
        nrm = (P2 - C) / R
        d2, T2, ok2 = _refract(d1, -nrm, ob.n)
        t3 = (ob.z_stop - P2[:, 2]) / d2[:, 2]
        P3 = P2 + t3[:, None] * d2
        ok &= ok1 & ok2 & (np.hypot(P3[:, 0], P3[:, 1]) <= ob.stop_radius_mm)
        T = T1 * T2
        if self.beam_splitter is not None:  # the reticle's light comes off S1 (a plane mirror: same rays)
            T = T * self.beam_splitter.weights(d @ self.beam_splitter.normal, 1)[0]
        return P3, d2, T, ok

    def _return(self, H: np.ndarray, r: np.ndarray):
        """Mirror → stop plane → convex face → flat face → detector plane. Returns (xy, T, ok)."""
        ob = self.objective
        ok = r[:, 2] < 0.0
        t = (ob.z_stop - H[:, 2]) / np.where(ok, r[:, 2], -1.0)
        P = H + t[:, None] * r
        ok &= (t > 0) & (np.hypot(P[:, 0], P[:, 1]) <= ob.stop_radius_mm)
        C = np.array([0.0, 0.0, ob.z_centre])
        R = ob.radius_mm
        oc = P - C
        b = np.einsum("ij,ij->i", oc, r)
        c = np.einsum("ij,ij->i", oc, oc) - R * R
        disc = b * b - c
        ok &= disc >= 0
        t2 = -b - np.sqrt(np.maximum(disc, 0.0))
        P2 = P + t2[:, None] * r
        ok &= np.hypot(P2[:, 0], P2[:, 1]) <= ob.lens_radius_mm
        nrm = (P2 - C) / R
        d1, T1, ok1 = _refract(r, nrm, 1.0 / ob.n)
        t3 = (ob.z_flat - P2[:, 2]) / d1[:, 2]
        P3 = P2 + t3[:, None] * d1
        ok &= np.hypot(P3[:, 0], P3[:, 1]) <= ob.lens_radius_mm
        d2, T2, ok2 = _refract(d1, np.array([0.0, 0.0, 1.0]), ob.n)
        if self.beam_splitter is not None:
            from rigsim.optics.beam_splitter import trace_plate

            bs = self.beam_splitter
            P3, d2, ci, okp = trace_plate(P3, d2, bs.placement)
            T2 = T2 * bs.weights(ci, 1)[1] * bs.weights(ci, 2)[1]
            ok2 = ok2 & okp
        t4 = (self.z_detector - P3[:, 2]) / d2[:, 2]
        P4 = P3 + t4[:, None] * d2
        return P4[:, :2], T1 * T2, ok & ok1 & ok2

    def _best_collimation_shift(self, z_par: float, n: int = 20000) -> float:
        from scipy.optimize import minimize_scalar

        def rms_slope(dz):
            zs = z_par + dz
            th = self._cone_for_stop(1.0, zs)
            _, d2, _, ok = self._outgoing(cone_directions(n, th), zs)
            s = d2[ok, :2] / d2[ok, 2:3]
            return float(np.sqrt(np.mean(np.sum(s * s, axis=1))))

        res = minimize_scalar(rms_slope, bounds=(-0.02 * self.efl_mm, 0.02 * self.efl_mm), method="bounded",
                              options={"xatol": 1e-7})
        return float(res.x)

    def _cone_for_stop(self, overfill: float, z_source: float | None = None) -> float:
        """Half angle of the reticle's cone whose marginal ray meets the stop plane at
        ``overfill`` × the stop radius."""
        target = overfill * self.objective.stop_radius_mm
        lo, hi = 0.0, 0.3
        for _ in range(80):
            m = 0.5 * (lo + hi)
            P3, _, _, _ = self._outgoing(np.array([[math.sin(m), 0.0, math.cos(m)]]), z_source)
            if P3[0, 0] < target:
                lo = m
            else:
                hi = m
        return lo

    def trace(self, mirror: MirrorTarget, n_rays: int = 1_000_000, emitted_photons: float = 1.0,
              chunk: int = 500_000) -> RayBundle:
        """Exact trace of ``n_rays`` reticle rays off ``mirror`` onto the detector plane."""
        if n_rays < 1000:
            raise ValueError(f"n_rays = {n_rays!r}: need at least 1000 rays")
        w0 = emitted_photons / n_rays
        uv_parts, w_parts = [], []
        n_stop = n_mirror = n_back = 0
        for start in range(0, n_rays, chunk):
            i = np.arange(start, min(n_rays, start + chunk), dtype=np.float64)
            c = 1.0 - (i + 0.5) / n_rays * (1.0 - math.cos(self.cone_half_angle_rad))
            s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
            ph = i * _GOLDEN_ANGLE
            d = np.stack([s * np.cos(ph), s * np.sin(ph), c], axis=-1)
            P, d2, T, ok = self._outgoing(d)
            P, d2, T = P[ok], d2[ok], T[ok]
            n_stop += len(P)
            nm = mirror.normal
            den = d2 @ nm
            hit_ok = den < 0
            t = ((mirror.centre - P) @ nm) / np.where(hit_ok, den, -1.0)
            H = P + t[:, None] * d2
            hit_ok &= (t > 0) & mirror.inside(H)
            H, d2, T = H[hit_ok], d2[hit_ok], T[hit_ok]
            n_mirror += len(H)
            r = d2 - 2.0 * (d2 @ nm)[:, None] * nm
            xy, T2, ok2 = self._return(H, r)
            n_back += int(ok2.sum())
            uv_parts.append(self.xy_to_uv(xy[ok2]))
            w_parts.append(w0 * mirror.reflectance * T[ok2] * T2[ok2])
        uv = np.concatenate(uv_parts) if uv_parts else np.zeros((0, 2))
        w = np.concatenate(w_parts) if w_parts else np.zeros(0)
        return RayBundle(uv, w, float(emitted_photons), int(n_rays), n_stop / n_rays,
                         n_mirror / max(n_stop, 1), n_back / max(n_mirror, 1), self.mirror_fill_fraction(mirror))

    def beam_radius_at(self, z: float) -> float:
        """Radius of the outgoing beam footprint (marginal ray) at the plane z (A frame)."""
        P3, d2, _, _ = self._outgoing(np.array([[math.sin(self.cone_half_angle_rad), 0.0,
                                                 math.cos(self.cone_half_angle_rad)]]))
        P3, d2 = P3[0], d2[0]
        r_stop_edge = self.objective.stop_radius_mm
        # the beam is limited by the stop: the marginal ray that passes the stop edge
        slope = d2[0] / d2[2]
        return float(r_stop_edge + slope * (z - self.objective.z_stop))

    def mirror_fill_fraction(self, mirror: MirrorTarget) -> float:
        """Fraction of the mirror's area that lies inside the outgoing beam (stop-limited)."""
        pts = mirror.area_points()
        # project each mirror point back along the axis: the beam is a near-cylinder about z_A
        rb = np.array([self.beam_radius_at(z) for z in (pts[:, 2].min(), pts[:, 2].max())]).min()
        return float(np.mean(np.hypot(pts[:, 0], pts[:, 1]) <= rb))

    # -- spot truth ----------------------------------------------------------------------
    def paraxial_uv(self, mirror: MirrorTarget) -> np.ndarray:
        """Where the paraxial model (EFL · tan of the return beam's angle) puts the spot."""
        nm = mirror.normal
        d = np.array([0.0, 0.0, 1.0])
        r = d - 2.0 * (d @ nm) * nm
        return self.xy_to_uv(self.efl_mm * np.array([r[0], r[1]]) / (-r[2]) + self.detector_xy0)

    def spot(self, mirror: MirrorTarget, *, n_rays: int = 1_000_000, emitted_photons: float = 1.0,
             window: tuple[int, int, int, int] | None = None, window_px: int | None = None,
             window_margin_px: float = 1.0) -> SpotTruth:
        """Exact spot image of ``mirror``: centroids, extent, flux and geometry flags.

        ``window`` (u0, v0, w, h) is the region whose pixel-binned centroid is returned (the
        render window); with ``window_px`` instead it is placed as the renderer places it
        (:meth:`window_for`). Flags: ``beam_misses_face``, ``beam_partly_misses_face``
        (the mirror is off-centre: neither is ≥ 99 % of the mirror's area inside the beam nor
        ≥ 99 % of the beam on the mirror; a cube face smaller than the beam and centred in it is
        fine), ``return_vignetted`` (> 1 % of the light
        reflected by the mirror misses the objective on the way back), ``spot_off_detector``,
        ``spot_cut_by_edge`` (some light lands beyond the detector's edge),
        ``spot_exceeds_window`` (light beyond the window, less ``window_margin_px``);
        ``spot_outside_model`` is always False (the exact trace has no domain limit; the key is
        kept for the common sidecar format). A return beam that misses the objective entirely is
        ``return_vignetted`` and ``spot_off_detector``.
        """
        b = self.trace(mirror, n_rays, emitted_photons)
        flags = {
            "beam_misses_face": bool(b.frac_on_mirror == 0.0),
            "beam_partly_misses_face": bool(b.frac_on_mirror > 0 and max(b.mirror_fill_fraction, b.frac_on_mirror) < 0.99),
            "return_vignetted": bool(b.frac_on_mirror > 0 and b.frac_return < 0.99),  # > 1 % lost
            "spot_outside_model": False,
            "spot_off_detector": False,
            "spot_cut_by_edge": False,
            "spot_exceeds_window": False,
        }
        tilt = mirror.tilt_rad()
        par = self.paraxial_uv(mirror)
        flux = float(b.weight.sum())
        if flux <= 0:
            flags["spot_off_detector"] = True
            return SpotTruth(False, None, None, None, 0.0, 0.0, None, float("nan"), tilt, par, flags, b)
        w = b.weight
        uv = b.uv
        mean = (w[:, None] * uv).sum(0) / flux
        rms = float(np.sqrt((w * ((uv - mean) ** 2).sum(1)).sum() / flux))
        on = self.on_detector(uv)
        flux_on = float(w[on].sum())
        flags["spot_off_detector"] = bool(flux_on == 0.0)
        flags["spot_cut_by_edge"] = bool(0.0 < flux_on < flux)
        ext = np.array([uv.min(0), uv.max(0)])
        if window is None and window_px is not None:
            window = self.window_for(mean, window_px)
        pix = None
        if window is not None:
            u0, v0, ww, wh = window
            flags["spot_exceeds_window"] = bool(
                ext[0, 0] < u0 - 0.5 + window_margin_px or ext[1, 0] > u0 + ww - 0.5 - window_margin_px
                or ext[0, 1] < v0 - 0.5 + window_margin_px or ext[1, 1] > v0 + wh - 0.5 - window_margin_px)
            pix = self.binned_centroid(b, window)
        return SpotTruth(True, mean, pix, window, flux, flux_on, ext, rms, tilt, par, flags, b)

    def binned_centroid(self, bundle: RayBundle, window: tuple[int, int, int, int]) -> np.ndarray | None:
        """First moment of the pixel-binned exact image over the pixels of ``window`` that lie on
        the detector — what a perfect renderer followed by a plain first moment returns."""
        u0, v0, ww, wh = window
        ij = np.floor(bundle.uv + 0.5)
        keep = ((ij[:, 0] >= max(u0, 0)) & (ij[:, 0] < min(u0 + ww, self.width))
                & (ij[:, 1] >= max(v0, 0)) & (ij[:, 1] < min(v0 + wh, self.height)))
        s = bundle.weight[keep].sum()
        if not s > 0:
            return None
        return (bundle.weight[keep, None] * ij[keep]).sum(0) / s

    def binned_image(self, bundle: RayBundle, window: tuple[int, int, int, int]) -> np.ndarray:
        """The exact image (photons per pixel) of ``window``: rays binned into pixels."""
        u0, v0, ww, wh = window
        ij = np.floor(bundle.uv + 0.5).astype(np.int64)
        i, j = ij[:, 0] - u0, ij[:, 1] - v0
        keep = ((i >= 0) & (i < ww) & (j >= 0) & (j < wh) & (ij[:, 0] >= 0) & (ij[:, 0] < self.width)
                & (ij[:, 1] >= 0) & (ij[:, 1] < self.height))
        img = np.zeros((wh, ww))
        np.add.at(img, (j[keep], i[keep]), bundle.weight[keep])
        return img

    # -- spot size ---------------------------------------------------------------------------
    def centred_mirror(self, shape: str, size_mm: float) -> MirrorTarget:
        """A mirror of outline ``shape`` (``"square"``: a cube face of side ``size_mm``; ``"disk"``:
        diameter ``size_mm``) at ``distance_mm`` from the convex vertex, centred on the axis and
        square to it (at its null): the nominal target of the instrument."""
        if shape not in ("square", "disk"):
            raise ValueError(f"shape = {shape!r}: must be 'square' or 'disk'")
        if not (size_mm > 0 and math.isfinite(size_mm)):
            raise ValueError(f"size_mm = {size_mm!r}: must be finite and > 0")
        m = flat_mirror(self.distance_mm + self.objective.z_vertex, (0.0, 0.0), 0.5 * float(size_mm))
        if shape == "square":
            m = replace(m, shape="square", e1=np.array([1.0, 0.0, 0.0]), e2=np.array([0.0, -1.0, 0.0]), name="face")
        return m

    def geometric_spot_px(self, mirror: MirrorTarget, n_rays: int = 20_000) -> float:
        """Width (px, the larger of u and v) of the ray-optics image of the reticle off ``mirror`` as
        it is placed and tilted: the exact trace of ``n_rays`` rays. The reticle is a point, so this
        is the objective's aberration and focus blur over the part of the pupil the mirror returns
        (8.94 px on the default rig's 25 mm face, 14.3 px on its Ø50 mm plane mirror). 0 when no
        light comes back."""
        sp = self.spot(mirror, n_rays=n_rays)
        return float(np.max(np.ptp(sp.extent_uv, axis=0))) if sp.valid and sp.extent_uv is not None else 0.0

    def spot_extent(self, mirror: MirrorTarget, *, peak_over_noise: float, k_sigma: float = 3.0,
                    n_rays: int = 20_000) -> SpotExtent:
        """:func:`spot_extent_px` for ``mirror`` (as it is placed and tilted) seen by this
        instrument: the geometric width from :meth:`geometric_spot_px`, the diffraction of the
        smaller of the stop and the mirror's outline."""
        geo = self.geometric_spot_px(mirror, n_rays)
        return spot_extent_px(wavelength_nm=self.objective.wavelength_nm, focal_length_mm=self.efl_mm,
                              pixel_pitch_um=self.pitch_mm * 1e3, beam_diameter_mm=self.objective.clear_aperture_mm,
                              mirror_shape=mirror.shape, mirror_size_mm=2.0 * mirror.half_size_mm,
                              peak_over_noise=peak_over_noise, k_sigma=k_sigma, geometric_px=geo)

    @staticmethod
    def window_for(center_uv, window_px: int) -> tuple[int, int, int, int]:
        """Window (u0, v0, w, h) of ``window_px`` square centred on the rounded ``center_uv``."""
        half = int(window_px) // 2
        return (int(math.floor(center_uv[0] + 0.5)) - half, int(math.floor(center_uv[1] + 0.5)) - half,
                int(window_px), int(window_px))

    # -- diffraction -------------------------------------------------------------------------
    def return_pupil(self, mirror: MirrorTarget, dp_mm: float, half_extent_mm: float | None = None):
        """Mask of the returning beam's cross-section at the stop plane on a square grid of pitch
        ``dp_mm`` centred on the axis: a point q is lit if it is inside the stop, the return ray
        through it (direction of the mirror-reflected axial beam) meets the mirror inside its
        outline at m, and the outgoing axial ray to m passed the stop. Returns (mask, coords)."""
        ob = self.objective
        h = ob.stop_radius_mm + 0.5 if half_extent_mm is None else half_extent_mm
        m = int(math.ceil(h / dp_mm))
        c = np.arange(-m, m + 1) * dp_mm
        X, Y = np.meshgrid(c, c)
        q = np.stack([X.ravel(), Y.ravel(), np.full(X.size, ob.z_stop)], -1)
        n = mirror.normal
        r = np.array([0.0, 0.0, 1.0]) - 2.0 * n[2] * n
        t = ((q - mirror.centre) @ n) / (r @ n)
        mp = q - t[:, None] * r
        lit = (np.hypot(q[:, 0], q[:, 1]) <= ob.stop_radius_mm) & mirror.inside(mp) \
            & (np.hypot(mp[:, 0], mp[:, 1]) <= ob.stop_radius_mm)
        return lit.reshape(X.shape), c

    def kernel_sampling(self, half_px: int) -> tuple[int, int]:
        """(samples_per_px, n_fft) of :meth:`diffraction_kernel`: the pupil grid (stop + 0.5 mm)
        fills at most half the FFT (|FT|² without aliasing), so the PSF is sampled at
        ``samples_per_px`` ≥ 2·(pupil width)·pitch/(λ·f) per pixel, at least 2; the FFT spans
        at least 3·half_px + 1 px (the periodic copies of the PSF stay two kernel radii away, where
        the pattern is ≤ 1/4 of its level at the kernel's edge), in at least 512 samples (the pupil
        then spans ≥ 128 of them) and a length with factors 2, 3 and 5 only (fast FFT). The
        default rig gets (2, 512)."""
        lam = self.objective.wavelength_nm * 1e-6
        width = 2.0 * (self.objective.stop_radius_mm + 0.5)
        s = max(2, math.ceil(2.0 * width * self.pitch_mm / (lam * self.efl_mm)))
        return s, _fast_len(max(512, s * (3 * int(half_px) + 1)))

    def diffraction_kernel(self, mirror: MirrorTarget, half_px: int = 32, samples_per_px: int | None = None,
                           n_fft: int | None = None) -> np.ndarray:
        """Pixel-integrated Fraunhofer PSF of the return pupil (uniform amplitude, no aberration),
        ``(2·half_px + 1)²`` kernel normalised to 1, ``K[j, i]`` = offset (i − half_px,
        j − half_px) px. Centrosymmetric (|FT|² of a real pupil), so convolving with it keeps
        an image's centroid. Scale: λ at ``wavelength_nm``, angles → detector with the EFL.
        ``samples_per_px`` and ``n_fft`` default to :meth:`kernel_sampling` (2 and 512 for the
        default rig)."""
        s0, n0 = self.kernel_sampling(half_px)
        samples_per_px = s0 if samples_per_px is None else int(samples_per_px)
        n_fft = n0 if n_fft is None else int(n_fft)
        lam = self.objective.wavelength_nm * 1e-6
        dp = lam * self.efl_mm * samples_per_px / (n_fft * self.pitch_mm)
        mask, c = self.return_pupil(mirror, dp)
        if len(c) > n_fft:
            raise ValueError("n_fft too small for the pupil at this sampling")
        P = np.zeros((n_fft, n_fft))
        k0 = n_fft // 2 - len(c) // 2
        P[k0:k0 + len(c), k0:k0 + len(c)] = mask
        psf = np.abs(np.fft.fft2(P)) ** 2  # index 0 = on axis; spacing 1/samples_per_px px
        nu = np.fft.fftfreq(n_fft, d=1.0 / samples_per_px)  # cycles per pixel
        otf = np.fft.fft2(psf) * np.sinc(nu)[:, None] * np.sinc(nu)[None, :]  # × pixel aperture
        psf_pix = np.real(np.fft.ifft2(otf))
        idx = (np.arange(-half_px, half_px + 1) * samples_per_px) % n_fft
        K = np.clip(psf_pix[np.ix_(idx, idx)], 0.0, None)
        K = 0.5 * (K + K[::-1, ::-1])  # exact centrosymmetry (removes float round-off)
        return K / K.sum()

    # -- reading ---------------------------------------------------------------------------
    def calibration(self, n_rays: int = 400_000) -> dict:
        """The instrument's factory calibration, fitted on the exact model: a flat mirror larger
        than the beam at ``distance_mm``, tilted along x_A; the spot's radial offset s (mm) is
        fitted as ``F·tan(ρ)·(1 + c·ρ²)`` with ρ the return beam's angle (= 2·tilt), over six
        tilts up to :meth:`calibration_range_rad`. With a beam splitter the plate breaks the
        symmetry: the zero (``ref_uv``) is the spot of the untilted mirror and the y axis gets its
        own scale (``y_scale``, from six tilts along y_A)."""
        if self._calib is None and (self._key, n_rays) in _CALIBRATIONS:
            self._calib = copy.deepcopy(_CALIBRATIONS[self._key, n_rays])
        if self._calib is None:
            # other processes (dataset workers, later runs) share it through the cache folder
            key = {"instrument": repr(self._key), "n_rays": int(n_rays), "numpy": np.__version__, "code": _code_digest()}
            need = _CALIBRATION_KEYS + (("y_scale",) if self.beam_splitter is not None else ())
            self._calib = cached_json("autocollimator-calibration", key, lambda: self._factory_calibration(n_rays),
                                      lambda d: _is_calibration(d, need, n_rays))
            if len(_CALIBRATIONS) >= 64:
                _CALIBRATIONS.pop(next(iter(_CALIBRATIONS)))
            _CALIBRATIONS[self._key, n_rays] = copy.deepcopy(self._calib)
        return self._calib

    def _factory_calibration(self, n_rays: int) -> dict:
        """:meth:`calibration` computed: the six (or twelve) traced tilts and the fit."""
        half = self.calibration_range_rad()
        ref = np.array([self.cx, self.cy])

        def cal_spot(tilt):
            m = flat_mirror(self.distance_mm + self.objective.z_vertex, tilt,
                            radius_mm=2.0 * self.objective.clear_aperture_mm)
            return self.spot(m, n_rays=n_rays).mean_uv

        if self.beam_splitter is not None:
            ref = cal_spot((0.0, 0.0))
        s, rho = [], []
        for t in np.linspace(0.1, 1.0, 6) * half:
            uv = cal_spot((t, 0.0))
            if uv is None:  # no light back at this tilt: not a calibration point
                continue
            s.append((uv[0] - ref[0]) * self.pitch_mm)
            rho.append(2.0 * t)
        if len(s) < 3:
            raise ValueError(f"autocollimator calibration: light returned at {len(s)} of 6 tilts up to "
                             f"{math.degrees(half) * 60:.2f} arcmin (need 3)")
        s, rho = np.array(s), np.array(rho)
        A = np.column_stack([np.tan(rho), np.tan(rho) * rho ** 2])
        (F, Fc), *_ = np.linalg.lstsq(A, s, rcond=None)
        resid = s - A @ np.array([F, Fc])
        cal = {"F_mm": float(F), "c": float(Fc / F), "fit_rms_px": float(np.sqrt(np.mean(resid ** 2)) / self.pitch_mm),
               "ref_uv": [float(ref[0]), float(ref[1])], "n_rays": n_rays, "range_rad": float(half),
               "mirror": "flat, Ø2×aperture, at distance_mm"}
        if self.beam_splitter is not None:
            half_y = min(half, self.measuring_range_rad()[1])
            sy, ay = [], []
            for t in np.linspace(0.1, 1.0, 6) * half_y:
                uv = cal_spot((0.0, t))
                if uv is not None:
                    sy.append((uv[1] - ref[1]) * self.pitch_mm)
                    ay.append(F * np.tan(2.0 * t) * (1.0 + Fc / F * 4.0 * t * t))
            cal["y_scale"] = float(np.dot(ay, ay) / np.dot(ay, sy))
        return cal

    def reading(self, uv) -> np.ndarray:
        """Calibrated reading (θx, θy) in radians of a spot at ``uv`` (arrays of (…, 2) welcome)."""
        cal = self.calibration()
        xy = self.uv_to_xy(uv) - self.uv_to_xy(np.array(cal["ref_uv"]))
        if "y_scale" in cal:
            xy = xy * np.array([1.0, cal["y_scale"]])
        s = np.hypot(xy[..., 0], xy[..., 1])
        F, c = cal["F_mm"], cal["c"]
        rho = np.arctan(s / F)
        for _ in range(30):
            g = F * np.tan(rho) * (1 + c * rho * rho) - s
            dg = F * ((1 + np.tan(rho) ** 2) * (1 + c * rho * rho) + np.tan(rho) * 2 * c * rho)
            rho = rho - g / dg
        phi = np.arctan2(xy[..., 1], xy[..., 0])
        th = np.tan(0.5 * rho)
        return np.stack([np.arctan(th * np.cos(phi)), np.arctan(th * np.sin(phi))], -1)

    def reading_paraxial(self, uv) -> np.ndarray:
        """Reading with the paraxial focal length and no calibration: ½·atan(Δ·pitch/EFL)."""
        xy = self.uv_to_xy(uv)
        return 0.5 * np.arctan(xy / self.efl_mm)

    def tilt_from_spot(self, uv, mirror: MirrorTarget, *, n_rays: int = 400_000, iterations: int = 6,
                       tol_rad: float = 1e-10) -> np.ndarray:
        """Invert the exact model: the tilt (θx, θy) of ``mirror`` (same outline and position,
        normal re-tilted) whose exact spot centroid (``mean_uv``) is at ``uv``."""
        uv = np.asarray(uv, float)
        t = self.reading(uv)
        cal = self.calibration()
        J = 2.0 * cal["F_mm"] / self.pitch_mm  # px per rad (small angles)
        for _ in range(iterations):
            sp = self.spot(retilt(mirror, t), n_rays=n_rays)
            if not sp.valid:
                raise GeometryError("the mirror returns no light at this tilt")
            step = (uv - sp.mean_uv) / J
            t = t + step
            if np.max(np.abs(step)) < tol_rad:
                break
        return t


def _fast_len(n: int) -> int:
    """Smallest 2^a·3^b·5^c ≥ n."""
    best = 1 << max(int(n) - 1, 0).bit_length()
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            m = p35
            while m < n:
                m *= 2
            best = min(best, m)
            p35 *= 3
        p5 *= 5
    return best


def flat_mirror(z_mm: float, tilt_rad, radius_mm: float, centre_xy=(0.0, 0.0), reflectance: float = 1.0) -> MirrorTarget:
    """A disk mirror at z (A frame) whose true reading is ``tilt_rad`` = (θx, θy)."""
    n = _normal_from_tilt(tilt_rad)
    e1, e2 = _plane_axes(n)
    return MirrorTarget(np.array([centre_xy[0], centre_xy[1], float(z_mm)]), n, "disk", float(radius_mm), e1, e2,
                        reflectance, "flat")


def retilt(mirror: MirrorTarget, tilt_rad) -> MirrorTarget:
    """The same mirror (centre, outline size) with the normal set to reading ``tilt_rad``."""
    n = _normal_from_tilt(tilt_rad)
    # rotate the in-plane axes with the minimal rotation taking the old normal to the new one
    Rm = _min_rotation(mirror.normal, n)
    return replace(mirror, normal=n, e1=Rm @ mirror.e1, e2=Rm @ mirror.e2)


def _normal_from_tilt(tilt_rad) -> np.ndarray:
    tx, ty = (float(x) for x in tilt_rad)
    n = np.array([math.tan(tx), math.tan(ty), -1.0])
    return n / np.linalg.norm(n)


def _plane_axes(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = a - (a @ n) * n
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def _min_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation taking unit vector a to unit vector b."""
    v = np.cross(a, b)
    c = float(a @ b)
    if np.linalg.norm(v) < 1e-15:
        return np.eye(3)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1.0 + c)


def a_frame_basis(axis_rot) -> np.ndarray:
    """R_rot_from_A of an autocollimator whose axis (unit, from the mirror towards the instrument)
    is ``axis_rot``: z_A = −axis, x_A = X′ made perpendicular to it (Y′ if the axis is near X′),
    y_A = z_A × x_A."""
    d = np.asarray(axis_rot, float)
    z = -d / np.linalg.norm(d)
    x0 = np.array([1.0, 0.0, 0.0])
    if abs(x0 @ z) > 0.9:
        x0 = np.array([0.0, 1.0, 0.0])
    x = x0 - (x0 @ z) * z
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


# ------------------------------------------------------------------------------ geometry
def exact_reading_rad(R_rot_from_A: np.ndarray, normal_rot) -> np.ndarray:
    """The instrument's ideal reading of a mirror with outward normal ``normal_rot``:
    (θx, θy) = (atan2(n_x, −n_z), atan2(n_y, −n_z)) with n in the A frame
    (:meth:`rigsim.optics.autocollimator.MirrorTarget.tilt_rad`)."""
    n = np.asarray(normal_rot, float) @ R_rot_from_A
    return np.array([math.atan2(n[0], -n[2]), math.atan2(n[1], -n[2])])


def normal_from_reading(R_rot_from_A: np.ndarray, reading_rad) -> np.ndarray:
    """Inverse of :func:`exact_reading_rad`: the unit normal (rot frame) that reads ``reading_rad``
    — n_A ∝ (tan θx, tan θy, −1)."""
    tx, ty = (float(x) for x in reading_rad)
    n = R_rot_from_A @ np.array([math.tan(tx), math.tan(ty), -1.0])
    return n / np.linalg.norm(n)
