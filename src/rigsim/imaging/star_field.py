"""Stars on a real sky: a position-dependent background and noise map, detection by a matched
filter down to the noise floor, and a pixel-integrated Gaussian fit of every star with its noise
taken from the map. Saturated, blended and frame-edge stars are flagged.

1. :func:`sky_map`: sep's mesh background (sigma-clipped mode of each ``mesh_px`` square, median-
   filtered over ``filter_meshes`` meshes, bicubic in between): the level follows sky glow,
   gradients and vignetting; the noise is measured on neighbour differences, which a gradient does
   not inflate. Saturated and non-finite pixels are left out of both.
2. :func:`extract_star_field`: the background-subtracted frame is filtered by the PSF less its local
   mean (a Gaussian of ``psf_sigma_px`` minus a box mean: nearly the matched filter of a faint star in
   white noise, blind to what the level map leaves of the sky) and divided by the filtered noise; every local maximum of that significance map at or above ``threshold_sigma`` is a star.
   Two maxima closer than the fitting window are kept apart only when the significance dips between
   them; both are then BLENDED. Each star is fitted on its own window by
   :func:`rigsim.imaging.centroid_gauss` (σ of the PSF fitted too), with the map's level as its
   start and the map's rms plus the star's own shot noise (gain ``gain_dn_per_e``) as its noise.
3. :func:`photon_transfer`: the gain and dark variance a frame's own sky implies (each mesh square's
   noise against its level), for a camera whose gain nobody stated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.special import erf

from .centroid import centroid_gauss
from .detect import extract_rois
from .result import Flag

__all__ = ["PhotonTransfer", "SkyMap", "StarField", "extract_star_field", "photon_transfer", "sky_map"]

DEFAULT_MESH_PX = 64
DEFAULT_THRESHOLD_SIGMA = 5.0
PSF_FITS = ("frame", "star", "fixed")
#: stars at least this significant (and unflagged) measure the frame's PSF width
PSF_STAR_SIGNIFICANCE = 20.0
MIN_PSF_STARS = 5


@dataclass(frozen=True)
class SkyMap:
    """The sky's background level and noise (DN), per pixel and per mesh square."""

    level: np.ndarray       # (h, w)
    rms: np.ndarray         # (h, w)
    mesh_level: np.ndarray  # (ny, nx) the level of each mesh square
    mesh_rms: np.ndarray    # (ny, nx)
    mesh_px: int

    @property
    def global_level(self) -> float:
        return float(np.median(self.mesh_level))

    @property
    def global_rms(self) -> float:
        return float(np.median(self.mesh_rms))


def sky_map(img, *, mesh_px: int = DEFAULT_MESH_PX, filter_meshes: int = 3, saturation: float | None = None,
            mask=None) -> SkyMap:
    """The background and noise map of a frame (``img[v, u]`` in DN). ``mask``: pixels to leave out
    (True); saturated (≥ ``saturation``) and non-finite pixels are left out as well.

    The level is sep's mesh background of the frame. The noise is sep's mesh rms of the differences
    of horizontal neighbours / √2 on every other row: a mesh's own rms would count the level's change
    across the mesh (vignetting, glow) as noise; neighbour differences do not see it, and white noise
    keeps its σ."""
    import sep

    a = np.ascontiguousarray(np.asarray(img, dtype=np.float32))
    if a.ndim != 2:
        raise ValueError(f"a frame is a 2-D image; got shape {a.shape}")
    h, w = a.shape
    mesh = int(mesh_px)
    if not 8 <= mesh <= max(8, min(h, w)):
        raise ValueError(f"mesh_px = {mesh_px}: allowed 8 to the frame's shorter side ({min(h, w)} px)")
    bad = np.zeros(a.shape, bool) if np.issubdtype(np.asarray(img).dtype, np.integer) else ~np.isfinite(a)
    if saturation is not None and float(np.nanmax(a)) >= float(saturation):
        bad |= a >= float(saturation)
    if mask is not None:
        bad |= np.asarray(mask, bool)
    any_bad = bool(bad.any())
    if any_bad:
        a = np.where(bad, 0.0, a).astype(np.float32)
    fm = max(1, int(filter_meshes)) | 1  # odd
    if h >= 4 * mesh and w >= 4 * mesh:
        # the level on 2 × 2 bins (a quarter of the pixels; the level varies over meshes, not pixels)
        h2, w2 = h // 2 * 2, w // 2 * 2
        b = (a[0:h2:2, 0:w2:2] + a[1:h2:2, 0:w2:2] + a[0:h2:2, 1:w2:2] + a[1:h2:2, 1:w2:2]) * np.float32(0.25)
        bbad = (bad[0:h2:2, 0:w2:2] | bad[1:h2:2, 0:w2:2] | bad[0:h2:2, 1:w2:2] | bad[1:h2:2, 1:w2:2]) if any_bad else None
        half = sep.Background(np.ascontiguousarray(b), mask=bbad, bw=mesh // 2, bh=mesh // 2, fw=fm, fh=fm).back()
        # bin centres sit at 2j + 0.5: resize maps them onto the full-resolution pixel grid
        level = cv2.resize(half, (w2, h2), interpolation=cv2.INTER_LINEAR)
        if (h2, w2) != (h, w):
            level = np.pad(level, ((0, h - h2), (0, w - w2)), mode="edge")
    else:
        level = sep.Background(a, mask=bad if any_bad else None, bw=mesh, bh=mesh, fw=fm, fh=fm).back()
    d = np.ascontiguousarray((a[::2, 1:] - a[::2, :-1]) * np.float32(1.0 / math.sqrt(2.0)))
    dbad = (bad[::2, 1:] | bad[::2, :-1]) if any_bad else None
    rms_half = sep.Background(d, mask=dbad, bw=mesh, bh=max(4, mesh // 2), fw=fm, fh=fm).rms()
    rms = cv2.resize(rms_half, (w, h), interpolation=cv2.INTER_LINEAR)
    ny, nx = -(-h // mesh), -(-w // mesh)
    cy = np.clip((np.arange(ny) + 0.5) * mesh, 0, h - 1).astype(int)
    cx = np.clip((np.arange(nx) + 0.5) * mesh, 0, w - 1).astype(int)
    return SkyMap(level, rms, level[np.ix_(cy, cx)], rms[np.ix_(cy, cx)], mesh)


@dataclass(frozen=True)
class PhotonTransfer:
    """var = K · level + c over the mesh squares of a frame: K is the gain (DN per electron) that
    the sky's own shot noise implies, c = σ_dark² − K · offset (DN²)."""

    gain_dn_per_e: float
    intercept_dn2: float
    gain_sigma: float
    n_meshes: int
    level_span_dn: tuple[float, float]


def photon_transfer(img, *, mesh_px: int = 32, saturation: float | None = None, min_span: float = 1.2
                    ) -> PhotonTransfer | None:
    """The gain a frame's sky implies: in each ``mesh_px`` square, the level (median) and the noise
    (the standard deviation of horizontal neighbour differences / √2 within 4 robust σ: a gradient,
    vignetting or glow does not enter it, and the stars are clipped); then the weighted least-squares line of the
    variance against the level. None when the levels span less than ``min_span`` × (no leverage),
    fewer than 4 squares are usable, or the slope is not positive."""
    a = np.asarray(img, dtype=float)
    h, w = a.shape
    m = int(mesh_px)
    ny, nx = h // m, w // m
    if ny * nx < 4:
        return None
    d = np.empty_like(a)
    d[:, :-1] = (a[:, 1:] - a[:, :-1]) / math.sqrt(2.0)
    d[:, -1] = np.nan
    bad = ~np.isfinite(a)
    if saturation is not None:
        bad |= a >= float(saturation)
    d[bad] = np.nan
    d[:, :-1][bad[:, 1:]] = np.nan

    def tiles(x):
        return x[:ny * m, :nx * m].reshape(ny, m, nx, m).transpose(0, 2, 1, 3).reshape(ny * nx, m * m)

    median = np.nanmedian if bad.any() else np.median
    d[:, -1] = d[:, -2]  # (the last column has no right neighbour: repeat its left one's difference)
    with np.errstate(all="ignore"):
        A, D = tiles(np.where(bad, np.nan, a)), tiles(d)
        lev = median(A, axis=1)
        med = median(D, axis=1)
        dev = np.abs(D - med[:, None])
        # the standard deviation within 4 robust σ (a MAD alone is coarse on quantised data); a Gaussian
        # keeps 0.99893 of its variance inside ±4σ
        keep = dev <= 4.0 * 1.482602218505602 * median(dev, axis=1)[:, None]
        var = np.nansum(np.where(keep, dev, 0.0) ** 2, axis=1) / np.maximum(keep.sum(axis=1) - 1, 1) / 0.99893
    ok = np.isfinite(lev) & np.isfinite(var) & (var > 0) & (np.isfinite(D).sum(axis=1) > m * m // 2)
    lev, var = lev[ok], var[ok]
    if lev.size < 4 or lev.min() <= 0 or lev.max() < min_span * lev.min():
        return None
    wts = 1.0 / var  # a variance's error is proportional to the variance
    M = np.stack([lev, np.ones_like(lev)], axis=1) * wts[:, None]
    coef, *_ = np.linalg.lstsq(M, var * wts, rcond=None)
    resid = var * wts - M @ coef
    cov = np.linalg.pinv(M.T @ M) * float(resid @ resid) / max(lev.size - 2, 1)
    if not coef[0] > 0:
        return None
    return PhotonTransfer(float(coef[0]), float(coef[1]), float(math.sqrt(max(cov[0, 0], 0.0))), int(lev.size),
                          (float(lev.min()), float(lev.max())))


@dataclass(frozen=True)
class StarField:
    """Every star of a frame, brightest first: positions (px, OpenCV convention), 1σ from the fit's
    inverse Fisher matrix, flux above the sky (DN), the PSF σ fitted to each star (px), its
    detection significance (matched filter, σ) and flags (:class:`rigsim.imaging.Flag`)."""

    u: np.ndarray
    v: np.ndarray
    sigma_u: np.ndarray
    sigma_v: np.ndarray
    flux: np.ndarray
    sigma_flux: np.ndarray
    psf_sigma: np.ndarray
    significance: np.ndarray
    background: np.ndarray
    chi2_red: np.ndarray
    flags: np.ndarray
    sky: SkyMap
    threshold_sigma: float

    def __len__(self) -> int:
        return int(self.u.shape[0])

    @property
    def uv(self) -> np.ndarray:
        return np.stack([self.u, self.v], axis=1) if len(self) else np.zeros((0, 2))

    @property
    def sigma_uv(self) -> np.ndarray:
        return np.stack([self.sigma_u, self.sigma_v], axis=1) if len(self) else np.zeros((0, 2))


def _gauss_kernel_1d(sigma: float) -> np.ndarray:
    r = max(1, int(math.ceil(3.0 * sigma)))
    x = np.arange(-r, r + 1, dtype=float)
    e = np.diff(erf(np.append(x - 0.5, r + 0.5) / (math.sqrt(2.0) * sigma)))
    return (e / e.sum()).astype(np.float32)


def _local_maxima(sig: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the pixels at or above ``threshold`` that are ≥ their 8 neighbours (the
    frame's border counts as −∞); only the pixels above the threshold are examined."""
    h, w = sig.shape
    cv, cu = np.nonzero(sig >= threshold)
    val = sig[cv, cu]
    peak = np.ones(cv.size, bool)
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            if dv == 0 and du == 0:
                continue
            nv, nu = cv + dv, cu + du
            inside = (nv >= 0) & (nv < h) & (nu >= 0) & (nu < w)
            nb = np.full(cv.size, -np.inf, np.float32)
            nb[inside] = sig[nv[inside], nu[inside]]
            peak &= val >= nb
    return cv[peak], cu[peak]


def _dip_separates(sig: np.ndarray, p1, p2, dip_sigma: float) -> bool:
    """True when the significance along the straight line from peak p1 to the fainter p2 drops
    below p2's by more than ``dip_sigma`` (the significance map is in noise units)."""
    (v1, u1), (v2, u2) = p1, p2
    n = int(max(abs(v2 - v1), abs(u2 - u1))) * 2 + 1
    t = np.linspace(0.0, 1.0, n + 1)
    line = sig[np.rint(v1 + t * (v2 - v1)).astype(int), np.rint(u1 + t * (u2 - u1)).astype(int)]
    return float(sig[v2, u2] - line.min()) > dip_sigma


def extract_star_field(img, *, psf_sigma_px: float = 1.0, threshold_sigma: float = DEFAULT_THRESHOLD_SIGMA,
                       saturation: float | None = None, gain_dn_per_e: float | None = None,
                       mesh_px: int = DEFAULT_MESH_PX, sky: SkyMap | None = None, roi_px: int | None = None,
                       dip_sigma: float = 3.0, max_stars: int | None = None, mask=None,
                       fit_psf: str = "frame") -> StarField:
    """Every star of a frame (``img[v, u]`` in DN, any offset: the sky map takes it away).

    ``psf_sigma_px``: the PSF's σ, for the matched filter and as the fits' start. ``fit_psf``:
    ``"frame"`` (default) fits σ on the frame's bright clean stars (significance ≥ 20) and then every
    star with their median σ (a faint star's own σ is poorly measured and its noise leaks into the
    position); ``"star"`` fits each star's σ; ``"fixed"`` uses ``psf_sigma_px``. ``saturation``:
    raw DN of a saturated pixel (default: the dtype's top for integer frames). ``gain_dn_per_e``: K for the stars' own shot noise (default 1 DN/e-; the sky's noise
    comes from the map). ``sky``: a map made beforehand (default :func:`sky_map`). ``max_stars``:
    keep the most significant N. Stars are returned brightest (largest flux) first."""
    raw = np.asarray(img)
    if raw.ndim != 2:
        raise ValueError(f"a frame is a 2-D image; got shape {raw.shape}")
    if saturation is None and np.issubdtype(raw.dtype, np.integer):
        saturation = float(np.iinfo(raw.dtype).max)
    if fit_psf not in PSF_FITS:
        raise ValueError(f"fit_psf = {fit_psf!r}: allowed {', '.join(PSF_FITS)}")
    s_psf = float(psf_sigma_px)
    if not (np.isfinite(s_psf) and 0.2 <= s_psf <= 20.0):
        raise ValueError(f"psf_sigma_px = {psf_sigma_px}: allowed 0.2 to 20 px")
    a = raw.astype(np.float32, copy=False)
    h, w = a.shape
    all_finite = np.issubdtype(raw.dtype, np.integer) or bool(np.isfinite(a).all())
    any_sat = saturation is not None and float(np.nanmax(a)) >= saturation
    sat = (a >= saturation) if any_sat else None
    sky = sky if sky is not None else sky_map(a, mesh_px=mesh_px, saturation=saturation, mask=mask)
    resid = a - sky.level.astype(np.float32, copy=False)  # NaN stays NaN: the fits leave such pixels out
    finite_resid = resid if all_finite else np.nan_to_num(resid, nan=0.0, posinf=0.0, neginf=0.0)
    k1 = _gauss_kernel_1d(max(s_psf, 0.5))
    box = max(7, 2 * int(math.ceil(5.0 * s_psf)) + 1)
    # the PSF less its local mean (a zero-sum kernel, as DAOFIND's): a level or a linear gradient left
    # by the sky map does not reach the significance, at a few % of the matched filter's SNR
    filt = cv2.sepFilter2D(finite_resid, cv2.CV_32F, k1, k1, borderType=cv2.BORDER_REFLECT)
    filt -= cv2.blur(finite_resid, (box, box), borderType=cv2.BORDER_REFLECT)
    kern = np.zeros((box, box))
    r1 = k1.size // 2
    kern[box // 2 - r1:box // 2 + r1 + 1, box // 2 - r1:box // 2 + r1 + 1] = np.outer(k1, k1)
    kern -= 1.0 / box**2
    inv_noise = np.float32(1.0 / math.sqrt(float(np.sum(kern**2)))) / np.maximum(sky.rms.astype(np.float32, copy=False),
                                                                                 np.float32(1e-30))
    sig = filt * inv_noise
    pv, pu = _local_maxima(sig, threshold_sigma)
    order = np.argsort(-sig[pv, pu], kind="stable")
    pv, pu = pv[order], pu[order]
    size = int(roi_px) if roi_px is not None else max(7, 2 * int(math.ceil(4.0 * s_psf)) + 1)
    r = size // 2
    # maxima within a fitting window of a more significant one: the same star unless the map dips
    keep = np.ones(pv.size, bool)
    blended = np.zeros(pv.size, bool)
    if pv.size > 1:
        from scipy.spatial import cKDTree

        tree = cKDTree(np.stack([pu, pv], axis=1))
        for i, j in sorted(tree.query_pairs(r, output_type="set")):
            if not (keep[i] and keep[j]):
                continue
            hi, lo = (i, j) if i < j else (j, i)
            if sat is not None and sat[pv[hi], pu[hi]] and sat[pv[lo], pu[lo]]:
                keep[lo] = False  # one saturated plateau
            elif _dip_separates(sig, (pv[hi], pu[hi]), (pv[lo], pu[lo]), dip_sigma):
                blended[hi] = blended[lo] = True
            else:
                keep[lo] = False
    pv, pu, blended = pv[keep], pu[keep], blended[keep]
    if max_stars is not None:
        pv, pu, blended = pv[:max_stars], pu[:max_stars], blended[:max_stars]
    significance = sig[pv, pu].astype(float)
    n = pv.size
    if n == 0:
        z = np.zeros(0)
        return StarField(z, z, z, z, z, z, z, z, z, z, np.zeros(0, np.int64), sky, float(threshold_sigma))
    # each star is fitted on the frame less the sky map (a gradient under the star would pull a fit with
    # a constant background), a constant left free; saturated pixels are left out of the fit
    rois = extract_rois(resid, pu.astype(float), pv.astype(float), size)
    fl = rois.flags.copy()
    fl[blended] |= int(Flag.BLENDED)
    sat_roi = None
    if sat is not None:
        sat_roi = extract_rois(sat.astype(np.float32), pu.astype(float), pv.astype(float), size, fill=0.0).stack > 0.5
        fl[sat_roi.any(axis=(1, 2))] |= int(Flag.SATURATED)
    kw = dict(background=np.zeros(n), background_sd=sky.rms[pv, pu].astype(float), gain=gain_dn_per_e,
              saturation=None, max_iter=12, tol_px=1e-3)
    psf = s_psf
    if fit_psf == "frame":  # the frame's PSF width from its bright, clean stars; every star fitted with it
        bright = np.flatnonzero((significance >= PSF_STAR_SIGNIFICANCE) & (fl == 0))[:50]
        if bright.size >= MIN_PSF_STARS:
            kb = {k: (v[bright] if isinstance(v, np.ndarray) else v) for k, v in kw.items()}
            rb = centroid_gauss(rois.stack[bright], sigma_px=s_psf, fit_sigma=True, flags=fl[bright],
                                mask=None if sat_roi is None else sat_roi[bright], **kb)
            ok = (rb.flags & int(Flag.INVALID | Flag.SATURATED | Flag.EDGE | Flag.BLENDED)) == 0
            if ok.sum() >= MIN_PSF_STARS:
                psf = float(np.median(rb.extra["sigma_px"][ok]))
    res = centroid_gauss(rois.stack, sigma_px=psf, fit_sigma=fit_psf == "star", flags=fl, origin_uv=rois.origin_uv,
                         mask=sat_roi, **kw)
    psf_each = res.extra["sigma_px"] if fit_psf == "star" else np.full(n, psf)
    flags = np.asarray(res.flags, np.int64)
    only_outside = (rois.flags & int(Flag.EDGE)) != 0
    if only_outside.any() and all_finite:
        flags[only_outside] &= ~int(Flag.NAN)
    valid = ((flags & int(Flag.INVALID)) == 0) & np.isfinite(res.flux)
    o = np.argsort(-np.where(valid, res.flux, -np.inf), kind="stable")
    background = res.background + sky.level[pv, pu]
    return StarField(res.u[o], res.v[o], res.sigma_u[o], res.sigma_v[o], res.flux[o], res.extra["sigma_flux"][o],
                     psf_each[o], significance[o], background[o], res.extra["chi2_red"][o], flags[o],
                     sky, float(threshold_sigma))
