"""The project's pinhole + Brown–Conrady camera model, in OpenCV's convention and parameter order.

Pure numpy. Module-level functions (``distort``, ``project``, ``unproject``) broadcast over the
leading dimensions of points and of parameter vectors ``(..., 9)`` ordered as ``PARAM_NAMES``,
and optionally return analytic Jacobians (``get_gradients=True``); :class:`PinholeBrown` wraps
one parameter set with detector size.

Conventions: camera frame x right, y down, z forward (boresight); pixel (0, 0)'s centre is at
(u, v) = (0, 0), +u right, +v down, arrays indexed ``img[v, u]``; pixel (i, j) covers
[i-0.5, i+0.5) x [j-0.5, j+0.5). With x = X/Z, y = Y/Z::

    r2 = x² + y²,  radial = 1 + k1 r2 + k2 r2² + k3 r2³
    xd = x radial + 2 p1 x y + p2 (r2 + 2x²)
    yd = y radial + p1 (r2 + 2y²) + 2 p2 x y
    u = fx xd + cx,  v = fy yd + cy

i.e. ``cv2.projectPoints`` with distCoeffs (k1, k2, p1, p2, k3). Beyond ``radial_r2_max`` the
radial map folds back; points there (and points with Z <= 0) are outside the model's domain.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from functools import lru_cache

import numpy as np

__all__ = [
    "PARAM_NAMES", "DIST_NAMES", "brown_distort", "brown_jacobian", "brown_undistort", "radial_r2_max",
    "distort", "project", "unproject", "PinholeBrown", "TelecentricCamera",
]

PARAM_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
DIST_NAMES = PARAM_NAMES[4:]  # OpenCV distCoeffs order


# -- scalar-coefficient building blocks (imported elsewhere; signatures fixed) -------------------
def brown_distort(x, y, k1, k2, p1, p2, k3):
    """Normalised undistorted (x, y) → distorted (xd, yd), OpenCV's Brown model; broadcasts."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


def brown_jacobian(x, y, k1, k2, p1, p2, k3):
    """Entries (a, b, c, d) of ∂(xd, yd)/∂(x, y) = [[a, b], [c, d]]."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dr = 2.0 * k1 + r2 * (4.0 * k2 + 6.0 * k3 * r2)  # 2·d(rad)/d(r²)
    a = rad + dr * x * x + 2.0 * p1 * y + 6.0 * p2 * x
    b = dr * x * y + 2.0 * p1 * x + 2.0 * p2 * y
    d = rad + dr * y * y + 6.0 * p1 * y + 2.0 * p2 * x
    return a, b, b, d


def brown_undistort(xd, yd, k1, k2, p1, p2, k3, r2_max=np.inf, iterations: int = 20):
    """Distorted → undistorted normalised coordinates (Newton). Returns (x, y, valid)."""
    xd = np.asarray(xd, dtype=np.float64)
    yd = np.asarray(yd, dtype=np.float64)
    c = (k1, k2, p1, p2, k3)
    x, y = xd.copy(), yd.copy()
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(iterations):
            fxd, fyd = brown_distort(x, y, *c)
            ex, ey = fxd - xd, fyd - yd
            a, b, cc, d = brown_jacobian(x, y, *c)
            det = a * d - b * cc
            sx, sy = (d * ex - b * ey) / det, (-cc * ex + a * ey) / det
            x, y = x - sx, y - sy
            # stop once every finite point has converged to rounding (quadratic convergence)
            if not np.any(np.abs(sx) + np.abs(sy) > 1e-15 * (1.0 + np.abs(x) + np.abs(y))):
                break
    fxd, fyd = brown_distort(x, y, *c)
    a, b, cc, d = brown_jacobian(x, y, *c)
    valid = (np.hypot(fxd - xd, fyd - yd) < 1e-9) & (x * x + y * y < r2_max) & (a * d - b * cc > 0)
    return x, y, valid


def radial_r2_max(k1: float, k2: float, k3: float, cap: float = 1e6) -> float:
    """Largest r² (normalised, undistorted) below which r·radial(r) is strictly increasing.

    d/dr [r(1 + k1 r² + k2 r⁴ + k3 r⁶)] = 1 + 3k1 s + 5k2 s² + 7k3 s³ with s = r²; beyond its
    first positive root the radial map folds back and a projection would land in a wrong place.
    """
    return _radial_r2_max_cached(float(k1), float(k2), float(k3), float(cap))


@lru_cache(maxsize=4096)
def _radial_r2_max_cached(k1: float, k2: float, k3: float, cap: float) -> float:
    coeffs = [7.0 * k3, 5.0 * k2, 3.0 * k1, 1.0]
    while coeffs and coeffs[0] == 0.0:
        coeffs.pop(0)
    if len(coeffs) <= 1:
        return cap
    roots = np.roots(coeffs)
    pos = [r.real for r in roots if abs(r.imag) < 1e-12 * max(1.0, abs(r.real)) and r.real > 0]
    return float(min(min(pos), cap)) if pos else cap


def _radial_r2_max_array(k1, k2, k3, cap: float = 1e6) -> np.ndarray:
    """``radial_r2_max`` elementwise over broadcast arrays (NaN where a coefficient is not finite).

    Builds the same companion matrices as ``np.roots`` and solves them batched, so the values
    equal the scalar function's.
    """
    k1, k2, k3 = np.broadcast_arrays(*(np.asarray(k, dtype=np.float64) for k in (k1, k2, k3)))
    if k1.size == 1:
        a, b, c = float(k1.flat[0]), float(k2.flat[0]), float(k3.flat[0])
        v = radial_r2_max(a, b, c, cap) if all(map(math.isfinite, (a, b, c))) else math.nan
        return np.full(k1.shape, v)
    out = np.full(k1.shape, float(cap))
    fin = np.isfinite(k1) & np.isfinite(k2) & np.isfinite(k3)
    out[~fin] = np.nan
    c3, c2, c1 = 7.0 * k3, 5.0 * k2, 3.0 * k1
    for deg, sel in ((3, fin & (c3 != 0)), (2, fin & (c3 == 0) & (c2 != 0)),
                     (1, fin & (c3 == 0) & (c2 == 0) & (c1 != 0))):
        if not sel.any():
            continue
        p = np.stack([c3[sel], c2[sel], c1[sel], np.ones(int(sel.sum()))], -1)[:, 3 - deg:]
        if p.shape[0] > 64:  # many parameter sets: solve each distinct one once
            p, inverse = np.unique(p, axis=0, return_inverse=True)
            inverse = inverse.reshape(-1)
        else:
            inverse = None
        A = np.zeros((p.shape[0], deg, deg))
        if deg > 1:
            A[:, np.arange(1, deg), np.arange(deg - 1)] = 1.0
        A[:, 0, :] = -p[:, 1:] / p[:, :1]
        r = np.linalg.eigvals(A)
        re, im = r.real, r.imag
        ok = (np.abs(im) < 1e-12 * np.maximum(1.0, np.abs(re))) & (re > 0)
        m = np.min(np.where(ok, re, np.inf), axis=-1)
        m = np.where(np.isfinite(m), np.minimum(m, cap), cap)
        out[sel] = m if inverse is None else m[inverse]
    return out


# -- vectorised model over parameter arrays ------------------------------------------------------
def _split(a: np.ndarray, n: int, what: str):
    if a.shape[-1:] != (n,):
        raise ValueError(f"{what} must have shape (..., {n}), got {a.shape}")
    return tuple(a[..., i] for i in range(n))


def _dist_partials(x, y, r2):
    """∂xd/∂dist and ∂yd/∂dist, each a tuple over (k1, k2, p1, p2, k3)."""
    r4 = r2 * r2
    r6 = r4 * r2
    xy2 = 2.0 * x * y
    return ((x * r2, x * r4, xy2, r2 + 2.0 * x * x, x * r6),
            (y * r2, y * r4, r2 + 2.0 * y * y, xy2, y * r6))


def distort(xy, dist, *, get_gradients: bool = False):
    """Normalised undistorted ``xy`` (..., 2) → distorted (..., 2); ``dist`` (..., 5) OpenCV order.

    With ``get_gradients`` returns ``(xyd, d_xyd_d_xy (..., 2, 2), d_xyd_d_dist (..., 2, 5))``.
    """
    xy = np.asarray(xy, dtype=np.float64)
    dist = np.asarray(dist, dtype=np.float64)
    x, y = _split(xy, 2, "xy")
    k1, k2, p1, p2, k3 = _split(dist, 5, "dist")
    shape = np.broadcast_shapes(xy.shape[:-1], dist.shape[:-1])
    xd, yd = brown_distort(x, y, k1, k2, p1, p2, k3)
    out = np.empty(shape + (2,))
    out[..., 0], out[..., 1] = xd, yd
    if not get_gradients:
        return out
    a, b, c, d = brown_jacobian(x, y, k1, k2, p1, p2, k3)
    J = np.empty(shape + (2, 2))
    J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1] = a, b, c, d
    gx, gy = _dist_partials(x, y, x * x + y * y)
    D = np.empty(shape + (2, 5))
    for j in range(5):
        D[..., 0, j], D[..., 1, j] = gx[j], gy[j]
    return out, J, D


def project(p, params, *, get_gradients: bool = False):
    """Points or directions ``p`` (..., 3) in the camera frame → pixels (..., 2).

    ``params`` (..., 9) ordered as ``PARAM_NAMES``. NaN where Z <= 0 or x² + y² >= radial_r2_max.
    With ``get_gradients`` returns ``(uv, du_dp (..., 2, 3), du_dparams (..., 2, 9))``, NaN where
    uv is NaN.
    """
    p = np.asarray(p, dtype=np.float64)
    params = np.asarray(params, dtype=np.float64)
    X, Y, Z = _split(p, 3, "p")
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = _split(params, 9, "params")
    shape = np.broadcast_shapes(p.shape[:-1], params.shape[:-1])
    r2_max = _radial_r2_max_array(k1, k2, k3)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = X / Z
        y = Y / Z
        r2 = x * x + y * y
        invalid = np.broadcast_to(~((Z > 0) & (r2 < r2_max)), shape)
        xd, yd = brown_distort(x, y, k1, k2, p1, p2, k3)
        uv = np.empty(shape + (2,))
        uv[..., 0] = fx * xd + cx
        uv[..., 1] = fy * yd + cy
        uv[invalid] = np.nan
        if not get_gradients:
            return uv
        a, b, c, d = brown_jacobian(x, y, k1, k2, p1, p2, k3)
        iz = 1.0 / Z
        du_dp = np.empty(shape + (2, 3))
        fa, fb = fx * a * iz, fx * b * iz
        fc, fd = fy * c * iz, fy * d * iz
        du_dp[..., 0, 0], du_dp[..., 0, 1], du_dp[..., 0, 2] = fa, fb, -(fa * x + fb * y)
        du_dp[..., 1, 0], du_dp[..., 1, 1], du_dp[..., 1, 2] = fc, fd, -(fc * x + fd * y)
        du_dk = np.zeros(shape + (2, 9))
        du_dk[..., 0, 0] = xd
        du_dk[..., 1, 1] = yd
        du_dk[..., 0, 2] = 1.0
        du_dk[..., 1, 3] = 1.0
        gx, gy = _dist_partials(x, y, r2)
        for j in range(5):
            du_dk[..., 0, 4 + j] = fx * gx[j]
            du_dk[..., 1, 4 + j] = fy * gy[j]
    du_dp[invalid] = np.nan
    du_dk[invalid] = np.nan
    return uv, du_dp, du_dk


def unproject(uv, params, *, get_gradients: bool = False, iterations: int = 20, keep_invalid: bool = False):
    """Pixels (..., 2) → normalised undistorted ``xy`` (..., 2) (z = 1 implied); NaN where invalid.

    Newton inversion as :func:`brown_undistort`, valid where it decides so with
    r2_max = radial_r2_max. With ``get_gradients`` returns ``(xy, dxy_duv (..., 2, 2),
    dxy_dparams (..., 2, 9))`` by the implicit function theorem, NaN where xy is NaN.
    ``keep_invalid``: keep Newton's values (and their gradients) where they are not valid instead
    of NaN, and append the valid mask (...,) to what is returned — for iterative estimators that
    may wander outside the domain on their way.
    """
    uv = np.asarray(uv, dtype=np.float64)
    params = np.asarray(params, dtype=np.float64)
    u, v = _split(uv, 2, "uv")
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = _split(params, 9, "params")
    shape = np.broadcast_shapes(uv.shape[:-1], params.shape[:-1])
    r2_max = _radial_r2_max_array(k1, k2, k3)
    xd = (u - cx) / fx
    yd = (v - cy) / fy
    x, y, ok = brown_undistort(xd, yd, k1, k2, p1, p2, k3, r2_max, iterations)
    valid = np.broadcast_to(ok, shape)
    invalid = ~valid if not keep_invalid else np.zeros(shape, bool)
    xy = np.empty(shape + (2,))
    xy[..., 0], xy[..., 1] = x, y
    xy[invalid] = np.nan
    if not get_gradients:
        return (xy, valid) if keep_invalid else xy
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b, c, d = brown_jacobian(x, y, k1, k2, p1, p2, k3)
        det = a * d - b * c
        # J⁻¹ = [[ia, ib], [ic, id]]
        ia, ib, ic, id_ = d / det, -b / det, -c / det, a / det
        ifx, ify = 1.0 / fx, 1.0 / fy
        dxy_duv = np.empty(shape + (2, 2))
        dxy_duv[..., 0, 0], dxy_duv[..., 0, 1] = ia * ifx, ib * ify
        dxy_duv[..., 1, 0], dxy_duv[..., 1, 1] = ic * ifx, id_ * ify
        dxy_dk = np.empty(shape + (2, 9))
        # target (xd, yd) = ((u - cx)/fx, (v - cy)/fy): d/dfx = -xd/fx, d/dcx = -1/fx, …
        dxy_dk[..., 0, 0], dxy_dk[..., 1, 0] = -ia * xd * ifx, -ic * xd * ifx
        dxy_dk[..., 0, 1], dxy_dk[..., 1, 1] = -ib * yd * ify, -id_ * yd * ify
        dxy_dk[..., 0, 2], dxy_dk[..., 1, 2] = -ia * ifx, -ic * ifx
        dxy_dk[..., 0, 3], dxy_dk[..., 1, 3] = -ib * ify, -id_ * ify
        gx, gy = _dist_partials(x, y, x * x + y * y)
        for j in range(5):
            dxy_dk[..., 0, 4 + j] = -(ia * gx[j] + ib * gy[j])
            dxy_dk[..., 1, 4 + j] = -(ic * gx[j] + id_ * gy[j])
    dxy_duv[invalid] = np.nan
    dxy_dk[invalid] = np.nan
    return (xy, dxy_duv, dxy_dk, valid) if keep_invalid else (xy, dxy_duv, dxy_dk)


# -- camera objects ---------------------------------------------------------------------------
@dataclass(frozen=True)
class PinholeBrown:
    """One pinhole + Brown camera (pixels, OpenCV convention) with its detector size."""

    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    width: int = 1024
    height: int = 1024

    def __post_init__(self) -> None:
        for name in PARAM_NAMES + ("width", "height"):
            v = getattr(self, name)
            try:
                f = float(v)
                shown = repr(f)
            except (TypeError, ValueError):
                f, shown = math.nan, repr(v)
            if name in ("width", "height"):
                if math.isfinite(f) and f == int(f):
                    shown = repr(int(f))
                if not (math.isfinite(f) and f == int(f) and f >= 1):
                    raise ValueError(f"PinholeBrown.{name} = {shown}: must be an integer >= 1 px")
                f = int(f)
            elif name in ("fx", "fy"):
                if not (math.isfinite(f) and f > 0):
                    raise ValueError(f"PinholeBrown.{name} = {shown}: must be a finite number > 0 px")
            elif not math.isfinite(f):
                raise ValueError(f"PinholeBrown.{name} = {shown}: must be a finite number")
            object.__setattr__(self, name, f)

    # -- construction / parameters -----------------------------------------------------------
    @classmethod
    def from_params(cls, p: np.ndarray, width: int, height: int) -> "PinholeBrown":
        """From ``[fx, fy, cx, cy, k1, k2, p1, p2, k3]`` (trailing terms optional)."""
        return cls(**{n: float(v) for n, v in zip(PARAM_NAMES, p)}, width=width, height=height)

    def params(self) -> np.ndarray:
        """``[fx, fy, cx, cy, k1, k2, p1, p2, k3]`` (``PARAM_NAMES`` order)."""
        return np.array([self.fx, self.fy, self.cx, self.cy, self.k1, self.k2, self.p1, self.p2, self.k3])

    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def dist_coeffs(self) -> np.ndarray:
        """OpenCV order (k1, k2, p1, p2, k3)."""
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])

    @property
    def r2_max(self) -> float:
        """``radial_r2_max(k1, k2, k3)``: the model's domain is x² + y² < r2_max."""
        return radial_r2_max(self.k1, self.k2, self.k3)

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def with_params(self, **changes) -> "PinholeBrown":
        """A copy with some fields replaced (validated)."""
        return replace(self, **changes)

    # -- distortion ---------------------------------------------------------------------------
    def distort(self, x, y):
        """Normalised undistorted (x, y) → distorted (xd, yd); broadcasts."""
        return brown_distort(x, y, self.k1, self.k2, self.p1, self.p2, self.k3)

    def distort_jacobian(self, x, y):
        """Entries (a, b, c, d) of ∂(xd, yd)/∂(x, y) = [[a, b], [c, d]]."""
        return brown_jacobian(x, y, self.k1, self.k2, self.p1, self.p2, self.k3)

    def undistort(self, xd, yd, iterations: int = 20):
        """Distorted → undistorted normalised coordinates (Newton). Returns (x, y, valid)."""
        return brown_undistort(xd, yd, self.k1, self.k2, self.p1, self.p2, self.k3, self.r2_max, iterations)

    def normalized_to_pixel(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        xd, yd = self.distort(xy[..., 0], xy[..., 1])
        return np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)

    # -- projection ---------------------------------------------------------------------------
    def project(self, dirs: np.ndarray, get_gradients: bool = False):
        """Directions or points (…, 3) in the camera frame → pixels (…, 2).

        NaN where s_z ≤ 0 or beyond the distortion model's monotonic domain (``r2_max``). With
        ``get_gradients`` returns ``(uv, du_ddir (…, 2, 3), du_dparams (…, 2, 9))``.
        """
        return project(dirs, self.params(), get_gradients=get_gradients)

    def project_valid(self, p):
        """Points (…, 3) → pixels (…, 2) computed wherever finite, and the domain mask (…,).

        The mask is False behind the camera (z ≤ 0) and beyond ``r2_max``; uv is not cleared
        there. Points off the detector are projected (see :meth:`on_detector`).
        """
        p = np.asarray(p, dtype=np.float64)
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = p[..., 0] / z
            y = p[..., 1] / z
            valid = (z > 0) & (x * x + y * y < self.r2_max)
            xd, yd = self.distort(x, y)
        uv = np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)
        return uv, valid

    def pixel_to_normalized(self, uv: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Invert the distortion (Newton); NaN where it has no valid inverse."""
        return unproject(uv, self.params(), iterations=iterations)

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Pixels (…, 2) → unit directions (…, 3); NaN where there is no valid inverse."""
        xy = self.pixel_to_normalized(uv)
        v = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    def backproject(self, uv):
        """Pixels (…, 2) → unit directions (…, 3) and valid mask (directions not cleared)."""
        uv = np.asarray(uv, dtype=np.float64)
        xd = (uv[..., 0] - self.cx) / self.fx
        yd = (uv[..., 1] - self.cy) / self.fy
        x, y, valid = self.undistort(xd, yd)
        d = np.stack([x, y, np.ones_like(x)], axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True), valid

    def flux_weight(self, uv):
        """Relative flux per unit detector area for a uniform-radiance scene, 1 on axis.

        ``cos⁴θ / det(∂(xd, yd)/∂(x, y))`` (aperture normal to the optical axis); 0 where invalid.
        """
        d, valid = self.backproject(uv)
        ct = d[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = d[..., 0] / ct, d[..., 1] / ct
            a, b, c, dd = self.distort_jacobian(x, y)
            return np.where(valid, ct ** 4 / (a * dd - b * c), 0.0)

    def on_detector(self, uv: np.ndarray, margin_px: float = 0.0) -> np.ndarray:
        """True where uv lies at least ``margin_px`` inside the detector [-0.5, W-0.5) x [-0.5, H-0.5)."""
        uv = np.asarray(uv, dtype=np.float64)
        u, v = uv[..., 0], uv[..., 1]
        with np.errstate(invalid="ignore"):
            return (np.isfinite(u) & np.isfinite(v)
                    & (u >= -0.5 + margin_px) & (u < self.width - 0.5 - margin_px)
                    & (v >= -0.5 + margin_px) & (v < self.height - 0.5 - margin_px))


@dataclass(frozen=True)
class TelecentricCamera:
    """Object-space telecentric (orthographic) camera: u = x / pixel_size_mm + cx, likewise v."""

    pixel_size_mm: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        if not (math.isfinite(self.pixel_size_mm) and self.pixel_size_mm > 0):
            raise ValueError(f"TelecentricCamera.pixel_size_mm = {self.pixel_size_mm!r}: must be "
                             "a finite number > 0 mm")
        for name in ("width", "height"):
            v = getattr(self, name)
            if int(v) != v or v < 1:
                raise ValueError(f"TelecentricCamera.{name} = {v!r}: must be an integer >= 1 px")

    def as_dict(self) -> dict:
        return asdict(self)

    def project(self, p_cam):
        p = np.asarray(p_cam, dtype=np.float64)
        uv = np.stack([p[..., 0] / self.pixel_size_mm + self.cx,
                       p[..., 1] / self.pixel_size_mm + self.cy], axis=-1)
        return uv, p[..., 2] > 0
