"""The ground calibration of the star sensor's lens (``[nominal] centroid_map = "traced_lens"``): a
collimator bench shows the sensor a star of the reference colour at a grid of field directions and
measures its centroid with the pipeline's own extraction. The map of (measured − chief ray) is what
the pipeline subtracts from every centroid before identification and calibration.

The bench uses the lens design (``rigsim.optics.star_lens``) and the nominal rig only: no rendered
frame and no truth. docs/effects-star.md ("A ground calibration of the centroid shift") gives the
model and its numbers.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from rigsim.files.cache import cached_json, source_digest
from rigsim.imaging.stars import extract_stars
from rigsim.optics.star_centroid_map import CentroidMap
from rigsim.optics.star_lens import StarLens
from rigsim.optics.star_psf import bv_temperature_k, field_tangents, photon_spectrum_weights, psf_table
from rigsim.rig.star import NominalStarRig

__all__ = ["BENCH_SIGNAL_E", "MAP_NODES", "bench_centroids", "corrected_centroids", "fill_missing", "ground_centroid_map"]

MAP_NODES = 13
"""Field directions per axis (as ``[effects.traced_psf] field_nodes``' default: bilinear between them)."""

BENCH_SIGNAL_E = 1500.0
"""(chosen) Electrons of the bench's star: an Hp ≈ 5.3 star on the default rig, inside the range the calibration
uses (500 e⁻ at the magnitude limit; the bright stars fail the Gaussian fit test). A fitted centroid of a
non-Gaussian spot depends on its signal through the noise weights: docs/effects-star.md."""

_PAD_PX = 4      # empty pixels around each bench star
_CACHE: dict = {}


def bench_centroids(psfs, oversample: int, radius_px: int, nominal: NominalStarRig) -> np.ndarray:
    """(..., 2) centroid (px) of each PSF in ``psfs`` (..., n, n bins, a :class:`rigsim.optics.star_psf.PSFTable`'s
    layout) measured as the pipeline measures a star, less its chief ray: each PSF is laid noise-free into
    a bench frame at two pixel phases per axis (0 and ½ px), the frame goes through the pipeline's
    extraction, and the four results are averaged."""
    s, c = nominal.sensor, nominal.calibration
    psfs = np.asarray(psfs, dtype=float)
    lead, n = psfs.shape[:-2], psfs.shape[-1]
    flat = psfs.reshape(-1, n, n)
    os_ = int(oversample)
    cell = 2 * int(radius_px) + 2 * _PAD_PX + 1                     # px
    phases = [(pu, pv) for pv in (0, os_ // 2) for pu in (0, os_ // 2)]
    k = len(flat) * len(phases)
    per_row = int(np.ceil(np.sqrt(k)))
    rows = int(np.ceil(k / per_row))
    img = np.zeros((rows * cell * os_, per_row * cell * os_))
    chief = np.zeros((k, 2))
    for m in range(k):
        p, (pu, pv) = divmod(m, len(phases))[0], phases[m % len(phases)]
        r, q = divmod(m, per_row)
        bu, bv = q * cell * os_ + _PAD_PX * os_ + pu, r * cell * os_ + _PAD_PX * os_ + pv   # the PSF's first bin
        img[bv:bv + n, bu:bu + n] += flat[p]
        chief[m] = (bu / os_ + radius_px - 0.5, bv / os_ + radius_px - 0.5)              # bin b's centre: (b + ½)/os − ½
    px = img.reshape(rows * cell, os_, per_row * cell, os_).sum(axis=(1, 3))
    d = s.detector
    dn = (d.offset_dn + d.gain_dn_per_e * BENCH_SIGNAL_E * px) * d.code_step_dn  # frame DN
    psf_model = None
    if c.centroid_method == "model":
        from rigsim.procedures.star.psf_model import star_image_model

        psf_model = star_image_model(nominal)
        if s.traced_lens is not None:
            # the forward model looks a star's PSF up at its field direction; on the bench that is the collimator's
            # known angle, i.e. the node's own PSF (the bench frame's pixel positions are not field positions)
            psf_model = _BenchStars(flat[np.arange(k) // len(phases)], chief, radius_px, os_, psf_model.support_px)
    found = extract_stars(dn, d, s.psf_sigma_px, method=c.centroid_method, repair_single_pixels=c.single_pixel_filter,
                          psf_model=psf_model)
    out = np.full((k, 2), np.nan)
    if len(found):
        dist = np.linalg.norm(found.uv[None, :, :] - chief[:, None, :], axis=2)
        dist[:, ~found.usable] = np.inf                         # blended (a ring split in two), edge, saturated
        one = np.sum(dist < 1.5 + radius_px, axis=1) == 1       # a star split into several detections is no measurement
        dist[~one] = np.inf
        j = np.argmin(dist, axis=1)
        hit = dist[np.arange(k), j] < 1.5
        out[hit] = found.uv[j[hit]] - chief[hit]
    out = out.reshape(len(flat), len(phases), 2)
    res = np.full((len(flat), 2), np.nan)
    full = np.all(np.isfinite(out[..., 0]), axis=1)             # a PSF measured at every phase (else the phases do not cancel)
    res[full] = out[full].mean(axis=1)
    return res.reshape(*lead, 2)


class _BenchStars:
    """The forward-model centroider's star image on the bench: each bench star's own PSF (its node's), found
    by the chief ray nearest to the star's position."""

    includes = ("the bench node's own PSF",)

    def __init__(self, psfs, chief, radius_px: int, oversample: int, support_px: int):
        self.psfs, self.chief = psfs, np.asarray(chief, dtype=float)
        self.radius_px, self.oversample, self.support_px = int(radius_px), int(oversample), int(support_px)

    def bind(self, uv, bv=None):
        from rigsim.optics.star_image_model import bind_psf_bins

        uv = np.atleast_2d(np.asarray(uv, dtype=float))
        j = np.argmin(np.linalg.norm(uv[:, None, :] - self.chief[None, :, :], axis=2), axis=1)
        return bind_psf_bins(self.psfs[j], self.radius_px, self.oversample)


def fill_missing(shift) -> np.ndarray:
    """(nx, ny, 2) map with its NaN nodes filled by the mean of their measured 8-neighbours, repeated
    until none is left (the bench's lost nodes: a defocus ring the extraction splits in two)."""
    out = np.array(shift, dtype=float)
    for _ in range(max(out.shape[:2])):
        bad = np.isnan(out[..., 0])
        if not bad.any():
            return out
        pad = np.pad(out, ((1, 1), (1, 1), (0, 0)), constant_values=np.nan)
        nb = np.stack([pad[1 + di:pad.shape[0] - 1 + di, 1 + dj:pad.shape[1] - 1 + dj]
                       for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj])
        cnt = np.sum(np.isfinite(nb[..., 0]), axis=0)
        mean = np.nansum(nb, axis=0) / np.maximum(cnt, 1)[..., None]
        fill = bad & (cnt > 0)
        out[fill] = mean[fill]
    return out


def ground_centroid_map(nominal: NominalStarRig) -> CentroidMap | None:
    """The ground map of the nominal rig's ``centroid_map`` (None without one): the traced lens (design
    values at the nominal focal length) at :data:`MAP_NODES` × :data:`MAP_NODES` directions over the
    nominal camera's field (2 % wider than the detector), for a blackbody star of the reference colour,
    measured by :func:`bench_centroids`, plus the bench's error (σ per node and axis, seeded). Cached
    per nominal sensor and calibration settings in the process, and in the cache folder
    (:func:`rigsim.files.cached_json`) for other processes: keyed also by the package's source and the
    numerical libraries' versions, a file that does not fit is measured again."""
    s, spec = nominal.sensor, nominal.sensor.centroid_map
    if spec is None:
        return None
    key = s.model_dump_json() + nominal.calibration.model_dump_json()
    if key in _CACHE:
        return _CACHE[key]
    import cv2
    import scipy

    # other processes and later runs read it from the cache folder; the key holds the code of the whole package
    # (the lens trace, the PSF table and the pipeline's extraction all shape the map)
    disk_key = {"nominal": key, "code": _package_digest(), "numpy": np.__version__, "opencv": cv2.__version__,
                "scipy": scipy.__version__}
    v = cached_json("star-ground-map", disk_key, lambda: _measured_map(nominal), _is_map)
    _CACHE[key] = CentroidMap(np.array(v["tan_x"]), np.array(v["tan_y"]), np.array(v["shift_px"]))
    return _CACHE[key]


def _measured_map(nominal: NominalStarRig) -> dict:
    """:func:`ground_centroid_map` measured: the traced lens's PSFs on the bench, as plain lists."""
    s, spec = nominal.sensor, nominal.sensor.centroid_map
    lens = StarLens(focal_length_mm=s.focal_length_mm, epd_mm=spec.aperture_diameter_mm,
                    ref_nm=spec.reference_wavelength_nm, defocus_mm=-spec.defocus_um * 1e-3)
    t = field_tangents(s.camera(), s.resolution_px)
    lams = np.linspace(spec.band_min_nm, spec.band_max_nm, spec.wavelengths)
    table = psf_table(lens, tan_max_x=float(t[0]), tan_max_y=float(t[1]), wavelengths_nm=lams,
                      pixel_pitch_um=s.pixel_pitch_um, nodes=MAP_NODES, pupil_rays=spec.pupil_rays,
                      oversample=spec.oversample)
    w = photon_spectrum_weights(bv_temperature_k(spec.reference_bv), lams)[0]
    shift = bench_centroids(np.einsum("l,ijlab->ijab", w, table.psf), table.oversample, table.radius_px, nominal)
    lost = int(np.isnan(shift[..., 0]).sum())
    if lost > shift[..., 0].size // 2:
        raise RuntimeError(f"the ground map's bench lost {lost} of its {shift[..., 0].size} stars")
    shift = fill_missing(shift)
    if spec.sigma_px > 0.0:
        rng = np.random.default_rng(np.random.SeedSequence([int(spec.seed), 0xC0111A7]))
        shift = shift + rng.normal(0.0, spec.sigma_px, shift.shape)
    return {"tan_x": np.asarray(table.tan_x, dtype=float).tolist(), "tan_y": np.asarray(table.tan_y, dtype=float).tolist(),
            "shift_px": shift.tolist()}


def _is_map(v: dict) -> bool:
    """A cached map: increasing node tangents and a finite (nx, ny, 2) shift."""
    try:
        tx, ty, sh = (np.array(v[k], dtype=float) for k in ("tan_x", "tan_y", "shift_px"))
    except (KeyError, TypeError, ValueError):
        return False
    return (tx.ndim == ty.ndim == 1 and tx.size >= 2 and ty.size >= 2 and sh.shape == (tx.size, ty.size, 2)
            and bool(np.all(np.diff(tx) > 0) and np.all(np.diff(ty) > 0) and np.all(np.isfinite(sh))))


@functools.lru_cache(maxsize=1)
def _package_digest() -> str:
    """SHA-256 of every source file of the rigsim package (a cache key part: any code change measures again)."""
    import rigsim

    return source_digest(sorted(Path(rigsim.__file__).parent.rglob("*.py")))


def corrected_centroids(uv, cmap: CentroidMap | None, camera) -> np.ndarray:
    """Measured centroids (M, 2) px less the map's shift at their directions through ``camera`` (the
    nominal camera); unchanged without a map."""
    uv = np.asarray(uv, dtype=float)
    if cmap is None or len(uv) == 0:
        return uv
    d = camera.unproject(uv)
    return uv - cmap.at(d[:, 0] / d[:, 2], d[:, 1] / d[:, 2])
