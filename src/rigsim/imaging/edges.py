"""Sub-pixel circle and ellipse fits for the diaphragm hole and the reflected spot (seed 000).

Seed 000 images the diaphragm hole (spot blocked), fits its centre, then images the reflected
spot on the screen, fits its centre, and adjusts the turntable until the two are concentric
(offset < 1 px in Table 1). rigsim:

* `edge_points`: sub-pixel points where the image crosses a level (default: halfway between the
  outside and inside levels), by linear interpolation along every row and every column.
* `fit_circle_points` / `fit_ellipse_points`: algebraic start (Kasa / OpenCV fitEllipseDirect),
  then geometric least squares with outlier rejection; covariance from the residual scatter.
* `fit_circle` (``method="edge"`` or ``"model"``): from an image. "model" refines by fitting a
  blurred uniform disk, I = B + A * Phi((R - r) / s), to the pixels near the edge with
  noise-weighted least squares (covariance = inverse Fisher matrix).
* `fit_ellipse`: from an image, edge points + geometric ellipse fit.
* `concentricity`: offset of two fitted centres with its uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.special import erf

from ._common import MAD_TO_SD
from .result import Flag, NoiseModel

__all__ = [
    "EdgePoints",
    "CircleFit",
    "EllipseFit",
    "Concentricity",
    "edge_points",
    "fit_circle_points",
    "fit_ellipse_points",
    "fit_circle",
    "fit_ellipse",
    "concentricity",
]


@dataclass(frozen=True)
class EdgePoints:
    uv: np.ndarray  # (M, 2) sub-pixel edge points (u, v)
    level: float  # crossing level (DN)
    outside: float  # estimated outside (dark) level
    inside: float  # estimated inside (bright) level
    noise_sd: float  # estimated pixel noise of the outside level
    flags: Flag


@dataclass(frozen=True)
class CircleFit:
    u: float
    v: float
    radius_px: float
    sigma_u: float
    sigma_v: float
    sigma_radius_px: float
    rms_residual_px: float
    n_points: int
    flags: Flag
    method: str = ""

    @property
    def valid(self) -> bool:
        return not (self.flags & Flag.INVALID)


@dataclass(frozen=True)
class EllipseFit:
    u: float
    v: float
    semi_major_px: float
    semi_minor_px: float
    angle_rad: float  # of the major axis, from +u towards +v, in [0, pi)
    sigma_u: float
    sigma_v: float
    rms_residual_px: float
    n_points: int
    flags: Flag

    @property
    def valid(self) -> bool:
        return not (self.flags & Flag.INVALID)


@dataclass(frozen=True)
class Concentricity:
    du: float  # b.u - a.u (px)
    dv: float  # b.v - a.v (px)
    distance_px: float
    sigma_du: float
    sigma_dv: float
    sigma_distance_px: float


def _invalid_circle(flags: Flag, n: int = 0, method: str = "") -> CircleFit:
    nan = float("nan")
    return CircleFit(nan, nan, nan, nan, nan, nan, nan, n, flags | Flag.INVALID, method)


def _invalid_ellipse(flags: Flag, n: int = 0) -> EllipseFit:
    nan = float("nan")
    return EllipseFit(nan, nan, nan, nan, nan, nan, nan, nan, n, flags | Flag.INVALID)


def _otsu(vals: np.ndarray, bins: int = 256) -> float:
    lo, hi = float(vals.min()), float(vals.max())
    if hi <= lo:
        return lo
    hist, edges = np.histogram(vals, bins=bins, range=(lo, hi))
    centres = 0.5 * (edges[1:] + edges[:-1])
    w0 = np.cumsum(hist)
    w1 = w0[-1] - w0
    m0 = np.cumsum(hist * centres)
    mt = m0[-1]
    with np.errstate(invalid="ignore", divide="ignore"):
        between = (mt * w0 / w0[-1] - m0) ** 2 / (w0 * w1)
    between[~np.isfinite(between)] = -1
    return float(edges[int(np.argmax(between)) + 1])


def edge_points(
    img,
    *,
    level: float | None = None,
    mask=None,
    saturation: float | None = None,
    min_step_sigma: float = 3.0,
) -> EdgePoints:
    """Sub-pixel crossings of ``level`` along rows and columns (linear interpolation between the
    centres of two adjacent pixels). Crossings whose pixel-to-pixel step is below
    ``min_step_sigma`` times the noise (noise crossings) are dropped. Pixels that are non-finite,
    masked or saturated never form a crossing (flags NAN / SATURATED)."""
    a = np.asarray(img)
    if a.ndim != 2 or not np.issubdtype(a.dtype, np.number):
        raise ValueError(f"image must be a 2-D numeric array, got shape {a.shape} dtype {a.dtype}")
    if saturation is None and np.issubdtype(a.dtype, np.integer):
        saturation = float(np.iinfo(a.dtype).max)
    a = a.astype(float)
    good = np.isfinite(a)
    fl = Flag.OK if good.all() else Flag.NAN
    if mask is not None:
        good &= ~np.asarray(mask, dtype=bool)
    if saturation is not None and np.any(good & (a >= saturation)):
        fl |= Flag.SATURATED
        # saturated pixels are still inside the bright region; they may take part in crossings
        # only if the level is below saturation (always true for a midpoint level)
    nan = float("nan")
    if good.sum() < 9:
        return EdgePoints(np.zeros((0, 2)), nan, nan, nan, nan, fl | Flag.EMPTY)
    vals = a[good]
    t = _otsu(vals)
    lo_vals, hi_vals = vals[vals <= t], vals[vals > t]
    if lo_vals.size == 0 or hi_vals.size == 0:
        return EdgePoints(np.zeros((0, 2)), nan, nan, nan, nan, fl | Flag.EMPTY)
    outside = float(np.median(lo_vals))
    inside = float(np.median(hi_vals))
    sd = float(MAD_TO_SD * np.median(np.abs(lo_vals - outside)))
    if level is None:
        level = 0.5 * (outside + inside)
    if not inside - outside > max(min_step_sigma * sd, 0.0) or inside <= outside:
        return EdgePoints(np.zeros((0, 2)), float(level), outside, inside, sd, fl | Flag.EMPTY | Flag.FAINT)
    pts = []
    step_min = min_step_sigma * max(sd, 1e-12 * max(abs(inside), 1.0)) * math.sqrt(2.0)
    for axis in (1, 0):  # 1: along rows (u crossings), 0: along columns (v crossings)
        a0 = a if axis == 1 else a.T
        g0 = good if axis == 1 else good.T
        p, q = a0[:, :-1], a0[:, 1:]
        ok = g0[:, :-1] & g0[:, 1:]
        with np.errstate(invalid="ignore"):
            cross = ok & (((p - level) * (q - level)) < 0) & (np.abs(q - p) > step_min)
        rr, cc = np.nonzero(cross)
        frac = (level - p[rr, cc]) / (q[rr, cc] - p[rr, cc])
        along = cc + frac
        if axis == 1:
            pts.append(np.stack([along, rr.astype(float)], axis=1))
        else:
            pts.append(np.stack([rr.astype(float), along], axis=1))
    uv = np.concatenate(pts, axis=0) if pts else np.zeros((0, 2))
    return EdgePoints(uv, float(level), outside, inside, sd, fl if len(uv) else fl | Flag.EMPTY)


def _kasa(uv: np.ndarray):
    x, y = uv[:, 0], uv[:, 1]
    A = np.stack([x, y, np.ones_like(x)], axis=1)
    b = x * x + y * y
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    cu, cv = sol[0] / 2, sol[1] / 2
    r2 = sol[2] + cu * cu + cv * cv
    return cu, cv, math.sqrt(max(r2, 0.0))


def fit_circle_points(uv, *, reject_nsigma: float = 4.0, max_reject_iter: int = 5) -> CircleFit:
    """Geometric least-squares circle through points (u, v); start from the Kasa fit; points
    beyond ``reject_nsigma`` robust sigmas are rejected iteratively. sigma_* from the residual
    scatter (the points are treated as independent)."""
    uv = np.asarray(uv, dtype=float)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must have shape (M, 2), got {uv.shape}")
    uv = uv[np.all(np.isfinite(uv), axis=1)]
    if len(uv) < 5:
        return _invalid_circle(Flag.EMPTY, len(uv), "points")
    keep = np.ones(len(uv), dtype=bool)
    c = np.array(_kasa(uv))
    # robust (soft L1) start so that a few outliers cannot capture the fit
    c = least_squares(
        lambda p: np.hypot(uv[:, 0] - p[0], uv[:, 1] - p[1]) - p[2], c, loss="soft_l1", f_scale=0.5
    ).x
    res = None
    for _ in range(max_reject_iter):
        pts = uv[keep]
        if len(pts) < 5:
            return _invalid_circle(Flag.EMPTY, len(pts), "points")

        def fun(p, pts=pts):
            return np.hypot(pts[:, 0] - p[0], pts[:, 1] - p[1]) - p[2]

        res = least_squares(fun, c, method="lm")
        c = res.x
        r_all = np.hypot(uv[:, 0] - c[0], uv[:, 1] - c[1]) - c[2]
        rms_rob = MAD_TO_SD * np.median(np.abs(r_all[keep] - np.median(r_all[keep])))
        new_keep = np.abs(r_all) <= reject_nsigma * max(rms_rob, 1e-9)
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    pts = uv[keep]
    r = np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1]) - c[2]
    dof = len(pts) - 3
    s2 = float(np.sum(r * r) / dof) if dof > 0 else np.nan
    J = res.jac
    try:
        cov = np.linalg.inv(J.T @ J) * s2
    except np.linalg.LinAlgError:
        return _invalid_circle(Flag.OK, len(pts), "points")
    fl = Flag.OK if c[2] > 0 else Flag.INVALID
    return CircleFit(
        float(c[0]), float(c[1]), float(abs(c[2])),
        float(math.sqrt(cov[0, 0])), float(math.sqrt(cov[1, 1])), float(math.sqrt(cov[2, 2])),
        float(math.sqrt(s2)), int(len(pts)), fl, "points",
    )


def _ellipse_residual(p, pts):
    cu, cv, a, b, th = p
    c, s = math.cos(th), math.sin(th)
    du, dv = pts[:, 0] - cu, pts[:, 1] - cv
    x = du * c + dv * s
    y = -du * s + dv * c
    rho = np.sqrt((x / a) ** 2 + (y / b) ** 2)
    # approximately the geometric distance: (rho - 1) times the local radius
    rloc = np.hypot(x, y) / np.maximum(rho, 1e-12)
    return (rho - 1.0) * rloc


def fit_ellipse_points(uv, *, reject_nsigma: float = 4.0, max_reject_iter: int = 5) -> EllipseFit:
    """Ellipse through points: OpenCV fitEllipseDirect start, then least squares on the
    (approximately geometric) radial residual, with outlier rejection."""
    uv = np.asarray(uv, dtype=float)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must have shape (M, 2), got {uv.shape}")
    uv = uv[np.all(np.isfinite(uv), axis=1)]
    if len(uv) < 6:
        return _invalid_ellipse(Flag.EMPTY, len(uv))
    (cx, cy), (d1, d2), ang = cv2.fitEllipseDirect(uv.astype(np.float32).reshape(-1, 1, 2))
    # OpenCV: full axis lengths d1 (along angle) and d2; angle in degrees
    th = math.radians(ang)
    a, b = d1 / 2.0, d2 / 2.0
    if b > a:
        a, b, th = b, a, th + math.pi / 2
    p = np.array([cx, cy, max(a, 1e-3), max(b, 1e-3), th], dtype=float)
    p = least_squares(_ellipse_residual, p, args=(uv,), loss="soft_l1", f_scale=0.5).x  # robust start
    keep = np.ones(len(uv), dtype=bool)
    res = None
    for _ in range(max_reject_iter):
        pts = uv[keep]
        if len(pts) < 6:
            return _invalid_ellipse(Flag.EMPTY, len(pts))
        res = least_squares(_ellipse_residual, p, args=(pts,), method="lm")
        p = res.x
        r_all = _ellipse_residual(p, uv)
        rms_rob = MAD_TO_SD * np.median(np.abs(r_all[keep] - np.median(r_all[keep])))
        new_keep = np.abs(r_all) <= reject_nsigma * max(rms_rob, 1e-9)
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    pts = uv[keep]
    r = _ellipse_residual(p, pts)
    dof = len(pts) - 5
    s2 = float(np.sum(r * r) / dof) if dof > 0 else np.nan
    try:
        cov = np.linalg.inv(res.jac.T @ res.jac) * s2
    except np.linalg.LinAlgError:
        return _invalid_ellipse(Flag.OK, len(pts))
    cu, cv_, a, b, th = p
    a, b = abs(a), abs(b)
    if b > a:
        a, b, th = b, a, th + math.pi / 2
    th = th % math.pi
    return EllipseFit(
        float(cu), float(cv_), float(a), float(b), float(th),
        float(math.sqrt(cov[0, 0])), float(math.sqrt(cov[1, 1])), float(math.sqrt(s2)), int(len(pts)), Flag.OK,
    )


def _largest_region_points(ep: EdgePoints, img: np.ndarray, good: np.ndarray) -> np.ndarray:
    """Keep edge points that border the largest bright connected region (drops isolated noise
    and other objects)."""
    bright = (good & (img > ep.level)).astype(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(bright, connectivity=8)
    if n <= 2:
        return ep.uv
    big = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    region = cv2.dilate((lab == big).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    iu = np.clip(np.rint(ep.uv[:, 0]).astype(int), 0, img.shape[1] - 1)
    iv = np.clip(np.rint(ep.uv[:, 1]).astype(int), 0, img.shape[0] - 1)
    return ep.uv[region[iv, iu]]


def _edge_flags(uv: np.ndarray, shape, fit_u, fit_v, radius) -> Flag:
    h, w = shape
    fl = Flag.OK
    if not np.isfinite(fit_u):
        return fl
    if fit_u - radius < 0.5 or fit_v - radius < 0.5 or fit_u + radius > w - 1.5 or fit_v + radius > h - 1.5:
        fl |= Flag.EDGE
    return fl


def fit_circle(
    img,
    *,
    level: float | None = None,
    method: str = "edge",
    mask=None,
    saturation: float | None = None,
    noise: NoiseModel | None = None,
    largest_region: bool = True,
) -> CircleFit:
    """Centre and radius of a bright disk (diaphragm hole, reflected spot) on a dark screen.

    ``method="edge"``: geometric circle through `edge_points` (level halfway between outside and
    inside levels unless ``level``). ``method="model"``: then fits I = B + A * Phi((R - r) / s)
    (Phi the normal CDF, r the distance from the centre) to the pixels within a few s of the edge,
    weighted by ``noise`` (or by measured background noise, gain K = 1 DN/e-); its covariance is the
    inverse Fisher matrix. Flags: EDGE if the circle is cut by the frame, SATURATED, NAN, EMPTY
    / FAINT when no edge is found (then INVALID, NaN centre).
    """
    if method not in ("edge", "model"):
        raise ValueError(f"method must be 'edge' or 'model', got {method!r}")
    a = np.asarray(img)
    ep = edge_points(a, level=level, mask=mask, saturation=saturation)
    if len(ep.uv) < 5:
        return _invalid_circle(ep.flags | Flag.EMPTY, len(ep.uv), method)
    af = a.astype(float)
    good = np.isfinite(af) if mask is None else np.isfinite(af) & ~np.asarray(mask, dtype=bool)
    uv = _largest_region_points(ep, af, good) if largest_region else ep.uv
    cf = fit_circle_points(uv)
    fl = ep.flags | cf.flags | _edge_flags(uv, af.shape, cf.u, cf.v, cf.radius_px)
    if not cf.valid:
        return _invalid_circle(fl, cf.n_points, method)
    if method == "edge":
        return CircleFit(cf.u, cf.v, cf.radius_px, cf.sigma_u, cf.sigma_v, cf.sigma_radius_px,
                         cf.rms_residual_px, cf.n_points, fl, "edge")
    return _fit_disk_model(af, good, ep, cf, fl, saturation, noise)


def _fit_disk_model(af, good, ep: EdgePoints, cf: CircleFit, fl: Flag, saturation, noise) -> CircleFit:
    h, w = af.shape
    use = good.copy()
    if saturation is not None:
        use &= ~(af >= saturation)
    vv, uu = np.mgrid[0:h, 0:w]
    r0 = np.hypot(uu - cf.u, vv - cf.v)
    s0 = 0.5
    band = use & (np.abs(r0 - cf.radius_px) < 4.0 + 3.0 * s0)
    if band.sum() < 10:
        return _invalid_circle(fl | Flag.EMPTY, int(band.sum()), "model")
    d = af[band]
    amp0 = ep.inside - ep.outside
    # the model is averaged over ss x ss sub-pixel samples (pixel integration), so that ``s`` is
    # the optical blur alone and sharp edges are not biased by the pixel box
    ss = 5
    off = (np.arange(ss) + 0.5) / ss - 0.5
    ou, ov = np.meshgrid(off, off)
    x = (uu[band].astype(float)[:, None] + ou.ravel()[None, :])  # (K, ss*ss)
    y = (vv[band].astype(float)[:, None] + ov.ravel()[None, :])

    def model(p):
        cu, cv_, R, A, B, s = p
        r = np.hypot(x - cu, y - cv_)
        return B + A * np.mean(0.5 * (1.0 + erf((R - r) / (math.sqrt(2.0) * s))), axis=1)

    def jac(p):
        cu, cv_, R, A, B, s = p
        r = np.maximum(np.hypot(x - cu, y - cv_), 1e-12)
        z = (R - r) / s
        phi = np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)
        dm_dR = A * phi / s
        return np.stack([
            np.mean(dm_dR * (x - cu) / r, axis=1),  # dr/dcu = -(x-cu)/r, dm/dr = -A phi / s
            np.mean(dm_dR * (y - cv_) / r, axis=1),
            np.mean(dm_dR, axis=1),
            np.mean(0.5 * (1.0 + erf(z / math.sqrt(2.0))), axis=1),
            np.ones(x.shape[0]),
            np.mean(-A * phi * z / s, axis=1),
        ], axis=1)

    def variance(mu):
        if noise is not None:
            return np.maximum(noise.variance(mu), noise.min_variance_dn2)
        return np.maximum(ep.noise_sd**2 + np.maximum(mu - ep.outside, 0.0), 1e-12)

    p = np.array([cf.u, cf.v, cf.radius_px, amp0, ep.outside, s0])
    lo = np.array([-np.inf, -np.inf, 0.5, -np.inf, -np.inf, 0.02])
    hi = np.array([np.inf, np.inf, np.inf, np.inf, np.inf, 50.0])
    for _ in range(3):
        sw = 1.0 / np.sqrt(variance(model(p)))
        res = least_squares(lambda q: (model(q) - d) * sw, p, jac=lambda q: jac(q) * sw[:, None],
                            bounds=(lo, hi), method="trf", x_scale="jac")
        moved = np.max(np.abs(res.x[:2] - p[:2]))
        p = res.x
        if moved < 1e-6:
            break
    Jm = jac(p)
    var = variance(model(p))
    try:
        cov = np.linalg.inv((Jm / var[:, None]).T @ Jm)
    except np.linalg.LinAlgError:
        return _invalid_circle(fl, int(band.sum()), "model")
    rms = float(np.sqrt(np.mean((model(p) - d) ** 2 / var)))
    if not res.success:
        fl |= Flag.NOT_CONVERGED
    dof = d.size - 6
    chi2_red = float(np.sum((model(p) - d) ** 2 / var) / dof)
    if chi2_red > 1.0 + 5.0 * math.sqrt(2.0 / dof):
        fl |= Flag.POOR_FIT
    return CircleFit(
        float(p[0]), float(p[1]), float(p[2]),
        float(math.sqrt(cov[0, 0])), float(math.sqrt(cov[1, 1])), float(math.sqrt(cov[2, 2])),
        rms, int(d.size), fl, "model",
    )


def fit_ellipse(
    img,
    *,
    level: float | None = None,
    mask=None,
    saturation: float | None = None,
    largest_region: bool = True,
) -> EllipseFit:
    """Centre, axes and orientation of a bright elliptical region from its sub-pixel edge."""
    a = np.asarray(img)
    ep = edge_points(a, level=level, mask=mask, saturation=saturation)
    if len(ep.uv) < 6:
        return _invalid_ellipse(ep.flags | Flag.EMPTY, len(ep.uv))
    af = a.astype(float)
    good = np.isfinite(af) if mask is None else np.isfinite(af) & ~np.asarray(mask, dtype=bool)
    uv = _largest_region_points(ep, af, good) if largest_region else ep.uv
    ef = fit_ellipse_points(uv)
    fl = ep.flags | ef.flags | _edge_flags(uv, af.shape, ef.u, ef.v, ef.semi_major_px)
    if not ef.valid:
        return _invalid_ellipse(fl, ef.n_points)
    return EllipseFit(ef.u, ef.v, ef.semi_major_px, ef.semi_minor_px, ef.angle_rad, ef.sigma_u, ef.sigma_v,
                      ef.rms_residual_px, ef.n_points, fl)


def concentricity(a, b) -> Concentricity:
    """Offset of centre ``b`` from centre ``a`` (any objects with u, v, sigma_u, sigma_v; e.g. the
    reflected spot and the diaphragm hole), with 1-sigma uncertainties (independent fits)."""
    du = b.u - a.u
    dv = b.v - a.v
    sdu = math.hypot(a.sigma_u, b.sigma_u)
    sdv = math.hypot(a.sigma_v, b.sigma_v)
    dist = math.hypot(du, dv)
    if dist > 0:
        sdist = math.sqrt((du * sdu) ** 2 + (dv * sdv) ** 2) / dist
    else:
        sdist = math.hypot(sdu, sdv) / math.sqrt(2.0)
    return Concentricity(float(du), float(dv), float(dist), float(sdu), float(sdv), float(sdist))
