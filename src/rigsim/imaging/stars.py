"""Star extraction and centroiding on a DN frame, through :mod:`rigsim.imaging` (no truth used).

Any user's frame works: pass a 2-D array and a :class:`rigsim.detector.DetectorConfig` (for the
noise model) and the PSF σ. ``method="model"`` refits every detected star with the image its optics
predict (a model of :mod:`rigsim.optics.star_image_model`, by :func:`rigsim.imaging.star_model_fit.fit_star_models`):
positions referenced to the camera model's image point. Returns :class:`Observations`: positions in px (OpenCV convention),
per-axis 1σ from the centroider (Cramér–Rao-attaining Gaussian fit by default), flux (DN) and
flags; ``usable`` excludes INVALID, SATURATED, EDGE and BLENDED spots (their σ is not to be
trusted for calibration).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rigsim.imaging import Flag, NoiseModel, find_spots

__all__ = ["BACKGROUNDS", "BAD_FLAGS", "POOR_FIT_REFERENCES", "Observations", "extract_stars", "frame_poor_fits",
           "model_centroids", "refit_windows", "star_windows", "StarWindows"]

POOR_FIT_REFERENCES = ("model", "frame")
# a star's unexplained share of signal is an outlier of its frame beyond this many robust σ
FRAME_OUTLIER_SIGMA = 3.0
MIN_FRAME_STARS = 8

BAD_FLAGS = int(Flag.INVALID | Flag.SATURATED | Flag.EDGE | Flag.BLENDED | Flag.NAN)


@dataclass(frozen=True)
class Observations:
    uv: np.ndarray        # (M, 2) px
    sigma_uv: np.ndarray  # (M, 2) px, 1σ per axis
    flux: np.ndarray      # (M,) DN above background
    flags: np.ndarray     # (M,) rigsim.imaging.Flag bits

    def __len__(self) -> int:
        return int(self.uv.shape[0])

    @property
    def usable(self) -> np.ndarray:
        return ((self.flags & BAD_FLAGS) == 0) & np.all(np.isfinite(self.uv), axis=1) & np.all(self.sigma_uv > 0, axis=1)

    def subset(self, idx) -> Observations:
        return Observations(self.uv[idx], self.sigma_uv[idx], self.flux[idx], self.flags[idx])


BACKGROUNDS = ("model", "map")
"""``model``: one background, the detector model's offset and noise; ``map``: a position-dependent sky
level and noise measured on the frame (sky glow, gradients, vignetting; :mod:`rigsim.imaging.star_field`)."""


def extract_stars(dn: np.ndarray, detector, sigma_px: float, *, method: str = "gauss",
                  threshold_sigma: float = 5.0, saturation: float | None = None,
                  repair_single_pixels: bool = False, poor_fit: str = "model", background: str = "model",
                  psf_model=None) -> Observations:
    """Detect and centroid every star of a frame (``find_spots`` with the detector's noise model).

    ``saturation`` defaults to the ADC's top code (in the frame's DN). For the Gaussian fit σ starts at ``sigma_px``
    and is fitted (smeared spots are slightly wider than the static PSF). ``repair_single_pixels``:
    first replace the pixels no PSF could have lit alone (hot pixels, particle hits:
    :func:`rigsim.imaging.cosmetics.single_pixel_events`) by their neighbours' mean.
    ``poor_fit`` (Gaussian fit only): what a star's fit is judged against before it is flagged
    POOR_FIT. ``"model"``: the noise model (reduced χ² far above 1). ``"frame"``: the frame's other
    stars as well (:func:`frame_poor_fits`), for a PSF that is not a Gaussian at all.
    ``background``: one of :data:`BACKGROUNDS`; with ``map`` the stars are found by a matched filter
    against the measured sky and fitted with the frame's PSF width (Gaussian fit only).
    ``method="model"``: the stars found and fitted as with ``"gauss"``, then each refitted with
    ``psf_model`` (a star image model: :class:`rigsim.optics.star_image_model.GaussianStarImage` or
    ``TracedStarImage``; default the Gaussian of ``sigma_px``) by :func:`model_centroids`.
    """
    if poor_fit not in POOR_FIT_REFERENCES:
        raise ValueError(f"poor_fit = {poor_fit!r}: allowed {', '.join(POOR_FIT_REFERENCES)}")
    if background not in BACKGROUNDS:
        raise ValueError(f"background = {background!r}: allowed {', '.join(BACKGROUNDS)}")
    noise = NoiseModel.from_detector(detector)
    if repair_single_pixels:
        from rigsim.imaging.cosmetics import repair_pixels, single_pixel_events

        dn = repair_pixels(dn, single_pixel_events(dn, noise, sigma_px))
    sat = float(detector.saturation_dn) if saturation is None else float(saturation)
    if background == "map":
        from rigsim.imaging.star_field import extract_star_field

        sf = extract_star_field(np.asarray(dn), psf_sigma_px=float(sigma_px), threshold_sigma=threshold_sigma,
                                saturation=sat, gain_dn_per_e=noise.gain_dn_per_e)  # the frame's DN per electron
        flags = np.asarray(sf.flags, np.int64)
        if poor_fit == "frame" and len(sf):
            flags = _frame_poor_fit_flags(flags, sf.chi2_red, sf.flux / sf.sigma_flux)
        return Observations(sf.uv.astype(float), sf.sigma_uv.astype(float), np.asarray(sf.flux, float), flags)
    if background == "model" and method == "model":
        # the Gaussian fits are the model fits' start only: no joint refit of "blends" (a defocus ring's two maxima)
        res, det = find_spots(np.asarray(dn), method="gauss", sigma_px=float(sigma_px), noise=noise,
                              threshold_sigma=threshold_sigma, saturation=sat, fit_sigma=True, deblend_fit=False)
        if psf_model is None:
            from rigsim.optics.star_image_model import GaussianStarImage

            psf_model = GaussianStarImage(float(sigma_px))
        res = model_centroids(np.asarray(dn), res, det, psf_model, noise, saturation=sat)
    else:
        kw = {}
        if method == "gauss":
            kw["fit_sigma"] = True
        res, _det = find_spots(np.asarray(dn), method=method, sigma_px=float(sigma_px), noise=noise,
                               threshold_sigma=threshold_sigma, saturation=sat, **kw)
    uv = np.stack([res.u, res.v], axis=1) if len(res) else np.zeros((0, 2))
    sig = np.stack([res.sigma_u, res.sigma_v], axis=1) if len(res) else np.zeros((0, 2))
    flags = np.asarray(res.flags, np.int64)
    if poor_fit == "frame" and method in ("gauss", "model") and len(res):
        flags = _frame_poor_fit_flags(flags, res.extra["chi2_red"], res.flux / res.extra["sigma_flux"])
    return Observations(uv.astype(float), sig.astype(float), np.asarray(res.flux, float), flags)


def model_centroids(dn: np.ndarray, start, det, psf_model, noise: NoiseModel, *, saturation: float | None = None):
    """Every detected star of ``start`` (``find_spots``' Gaussian fits and their detections ``det``)
    refitted with ``psf_model`` on a window of ±``psf_model.support_px`` around its Gaussian position
    (:func:`rigsim.imaging.star_model_fit.fit_star_models`). A star's flags keep what the window says
    (SATURATED, EDGE, NAN). The judgements of the spot's shape made for a Gaussian (BLENDED from two
    peaks in one detected region or a second peak in the window, POOR_FIT, FAINT, NOT_CONVERGED) are
    replaced by the model fit's: a defocus ring with two maxima is one star. Two detections whose
    model fits land within 1 px of each other are one star split in two: the fainter is INVALID.
    Stars whose fitted positions are closer than the window's half width are BLENDED; a neighbour
    the fit does not hold shows in its χ² (POOR_FIT)."""
    from rigsim.imaging.detect import extract_rois
    from rigsim.imaging.star_model_fit import fit_star_models
    from rigsim.imaging.result import CentroidBatch

    n = len(start)
    if n == 0:
        return start
    ok = (start.flags & int(Flag.INVALID)) == 0
    keep_fl = int(Flag.SATURATED | Flag.EDGE | Flag.NAN)
    base = np.asarray(start.flags, np.int64) & keep_fl
    r = int(psf_model.support_px)
    u0 = np.where(ok, start.u, det.peak_u.astype(float))
    v0 = np.where(ok, start.v, det.peak_v.astype(float))
    rois = extract_rois(dn, u0, v0, 2 * r + 1)
    res = fit_star_models(rois.stack, rois.origin_uv, psf_model.bind(np.stack([u0, v0], axis=1)), noise, u0, v0,
                          flags=base | rois.flags, saturation=saturation)
    fl = np.asarray(res.flags, np.int64).copy()
    uv = res.uv
    valid = (fl & int(Flag.INVALID)) == 0
    idx = np.flatnonzero(valid)
    if idx.size > 1:
        d = np.abs(uv[idx, None, :] - uv[None, idx, :]).max(axis=2)
        np.fill_diagonal(d, np.inf)
        order = idx[np.argsort(-res.flux[idx], kind="stable")]
        dropped = np.zeros(n, bool)
        pos = {int(i): k for k, i in enumerate(idx)}
        for i in order:                       # one star split into two detections: keep the brighter fit
            if dropped[i]:
                continue
            same = idx[(d[pos[int(i)]] < 1.0) & ~dropped[idx]]
            dropped[same] = True
        fl[dropped] |= int(Flag.INVALID)
        kept = idx[~dropped[idx]]
        dk = np.abs(uv[kept, None, :] - uv[None, kept, :]).max(axis=2)
        np.fill_diagonal(dk, np.inf)
        fl[kept[(dk <= r).any(axis=1)]] |= int(Flag.BLENDED)
    inv = (fl & int(Flag.INVALID)) != 0
    return CentroidBatch(np.where(inv, np.nan, res.u), np.where(inv, np.nan, res.v), np.where(inv, np.nan, res.sigma_u),
                         np.where(inv, np.nan, res.sigma_v), res.flux, res.background, fl, "model", extra=res.extra)


@dataclass(frozen=True)
class StarWindows:
    """The pixels of some stars of a frame, kept for fitting them again: ``index`` into the frame's
    :class:`Observations`, their windows (N, h, w, DN; the frame prepared as :func:`extract_stars`
    prepares it), each window's pixel (0, 0) position and each star's colour (B−V, NaN: unknown)."""

    index: np.ndarray
    stack: np.ndarray
    origin_uv: np.ndarray
    bv: np.ndarray


def star_windows(dn: np.ndarray, detector, sigma_px: float, found: Observations, index, radius_px: int, *, bv=None,
                 repair_single_pixels: bool = False) -> StarWindows:
    """The windows of ±``radius_px`` around the stars ``index`` of ``found`` (:class:`StarWindows`)."""
    from rigsim.imaging.detect import extract_rois

    idx = np.asarray(index, dtype=np.int64)
    if repair_single_pixels and idx.size:
        from rigsim.imaging.cosmetics import repair_pixels, single_pixel_events

        dn = repair_pixels(dn, single_pixel_events(dn, NoiseModel.from_detector(detector), sigma_px))
    uv0 = found.uv[idx]
    rois = extract_rois(np.asarray(dn), uv0[:, 0], uv0[:, 1], 2 * int(radius_px) + 1)
    bv = np.full(idx.size, np.nan) if bv is None else np.asarray(bv, dtype=float)
    return StarWindows(idx, rois.stack, rois.origin_uv, bv)


def refit_windows(found: Observations, win: StarWindows, psf_model, detector) -> Observations:
    """``found`` with the stars of ``win`` fitted again by the forward model ``psf_model`` from their
    positions in ``found``, each with its own colour (:func:`rigsim.imaging.star_model_fit.fit_star_models`).
    A star whose refit fails (INVALID) keeps its position in ``found``."""
    from rigsim.imaging.star_model_fit import fit_star_models

    idx = win.index
    if idx.size == 0:
        return found
    uv0 = found.uv[idx]
    res = fit_star_models(win.stack, win.origin_uv, psf_model.bind(uv0, win.bv), NoiseModel.from_detector(detector),
                          uv0[:, 0], uv0[:, 1], saturation=float(detector.saturation_dn))
    ok = (res.flags & int(Flag.INVALID)) == 0
    uv, sig, flux = found.uv.copy(), found.sigma_uv.copy(), found.flux.copy()
    uv[idx[ok]] = res.uv[ok]
    sig[idx[ok]] = np.stack([res.sigma_u, res.sigma_v], axis=1)[ok]
    flux[idx[ok]] = res.flux[ok]
    return Observations(uv, sig, flux, found.flags.copy())


def _frame_poor_fit_flags(flags: np.ndarray, chi2_red, snr) -> np.ndarray:
    """POOR_FIT kept only on the stars that are outliers of their frame (:func:`frame_poor_fits`)."""
    poor = int(Flag.POOR_FIT)
    outlier = frame_poor_fits(chi2_red, snr, (flags & BAD_FLAGS) == 0)
    return np.where((flags & poor) != 0, np.where(outlier, flags, flags & ~poor), flags)


def frame_poor_fits(chi2_red, snr, judged) -> np.ndarray:
    """Which stars' PSF fits are poor next to the rest of their frame.

    A PSF that is not the fitted Gaussian (a defocus ring, coma) leaves a residual proportional to
    the star's signal, so its excess reduced χ² grows as SNR²: the share of the signal the model
    leaves unexplained, e = (χ²_red − 1) / SNR², is about the same for every star of the frame (it
    varies with field as the PSF does). A particle hit on a star or a blend adds residual that is not
    proportional to the star: its e stands out. A star is an outlier when its e exceeds the median
    of the ``judged`` stars by ``FRAME_OUTLIER_SIGMA`` robust σ (1.4826 · MAD). With fewer than
    ``MIN_FRAME_STARS`` judged stars there is no population to compare with: every star is an
    outlier (the noise-model test alone decides)."""
    chi2_red, snr = np.asarray(chi2_red, float), np.asarray(snr, float)
    judged = np.asarray(judged, bool) & np.isfinite(chi2_red) & (snr > 0)
    e = np.full(chi2_red.shape, np.inf)
    e[judged] = (chi2_red[judged] - 1.0) / snr[judged] ** 2
    if judged.sum() < MIN_FRAME_STARS:
        return np.ones(chi2_red.shape, bool)
    med = float(np.median(e[judged]))
    scale = 1.4826 * float(np.median(np.abs(e[judged] - med)))
    return ~(e <= med + FRAME_OUTLIER_SIGMA * scale)
