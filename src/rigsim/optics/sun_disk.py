"""The finite solar disk (0.53°) through a camera: sampled directions, spot outline, true spot
centroid and geometry flags.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from rigsim.optics.camera import PinholeBrown

SUN_FULL_ANGLE_RAD = math.radians(0.53)


SIMULATOR_32ARCMIN_RAD = math.radians(32.0 / 60.0)


_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64).reshape(3)
    n = np.linalg.norm(v)
    if not (np.isfinite(n) and n > 0):
        raise ValueError(f"sun direction {v!r} must be a finite non-zero 3-vector")
    return v / n


def _basis(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing s (a unit 3-vector, or (..., 3) of them) to a right-handed orthonormal frame."""
    a = np.where((np.abs(s[..., 0]) < 0.9)[..., None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    e1 = np.cross(s, a)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    return e1, np.cross(s, e1)


def _rim_directions(s: np.ndarray, full_angle_rad: float, n: int) -> np.ndarray:
    """The ``n`` directions of the disk's rim around each unit direction s ((3,) or (..., 3)): (..., n, 3)."""
    e1, e2 = _basis(s)
    psi = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)[:, None]
    h = full_angle_rad / 2.0
    return math.cos(h) * s[..., None, :] + math.sin(h) * (np.cos(psi) * e1[..., None, :] + np.sin(psi) * e2[..., None, :])


@functools.lru_cache(maxsize=4)
def _disk_pattern(full_angle_rad: float, n: int) -> np.ndarray:
    """The sunflower pattern of :func:`disk_directions` in the sun's own frame, (n, 3) columns
    (along s, along e1, along e2): computed once per (angle, n), shared by every direction."""
    i = np.arange(n, dtype=np.float64)
    t = (i + 0.5) / n
    cos_phi = 1.0 - t * (1.0 - math.cos(full_angle_rad / 2.0))
    sin_phi = np.sqrt(np.maximum(0.0, 1.0 - cos_phi * cos_phi))
    psi = i * _GOLDEN_ANGLE
    out = np.column_stack([cos_phi, sin_phi * np.cos(psi), sin_phi * np.sin(psi)])
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=4)
def _disk_pattern_rows(full_angle_rad: float, n: int) -> np.ndarray:
    """:func:`_disk_pattern` transposed, (3, n) contiguous: what :func:`spot_truth` reads."""
    out = np.ascontiguousarray(_disk_pattern(full_angle_rad, n).T)
    out.flags.writeable = False
    return out


def disk_directions(sun_dir, full_angle_rad: float, n: int) -> np.ndarray:
    """``n`` unit directions filling the cone of the given full angle with equal solid angle each.

    Deterministic sunflower quadrature: ring position uniform in (1 - cos phi), azimuth stepped by
    the golden angle. Each point carries solid angle ``2 pi (1 - cos(a/2)) / n``. The pattern is
    cached per (angle, n); a direction costs one (n, 3) × (3, 3) product.
    """
    s = _unit(sun_dir)
    e1, e2 = _basis(s)
    return np.einsum("nk,kj->nj", _disk_pattern(float(full_angle_rad), int(n)), np.array([s, e1, e2]))


def spot_outline(camera: PinholeBrown, sun_dir, full_angle_rad: float, n: int = 90):
    """Projected rim of the disk: (n, 2) pixel positions and a validity mask."""
    return camera.project_valid(_rim_directions(_unit(sun_dir), full_angle_rad, n))


def disk_image_points(camera: PinholeBrown, sun_dir, full_angle_rad: float, *, n: int, response: str = "flux",
                      radiance=None, radiance_axis=None, direction_weight=None) -> dict:
    """The quadrature of :func:`spot_truth`: each of ``n`` points of the disk projected through
    ``camera`` (``uv``, (n, 2)) with its weight (``weight``: per solid angle, × the radiance and the
    direction weight when given), and the centre's projection (``center_uv``). ``valid`` False (and no
    points) when part of the disk falls outside the camera model."""
    s = _unit(sun_dir)
    e1, e2 = _basis(s)
    # the directions of disk_directions as rows (x, y, z) of one (3, n) array: contiguous columns
    d = np.einsum("kn,kj->jn", _disk_pattern_rows(float(full_angle_rad), int(n)), np.array([s, e1, e2]))
    z = d[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = d[0] / z, d[1] / z
        valid = bool(np.all(z > 0)) and bool(np.all(x * x + y * y < camera.r2_max))  # project_valid's mask
    c_uv, c_valid = camera.project_valid(s[None, :])
    if not (valid and c_valid[0]):
        return {"valid": False, "center_uv": c_uv[0].tolist() if c_valid[0] else None}
    xd, yd = camera.distort(x, y)
    uv = np.empty((len(z), 2))  # (n, 2) as project_valid returns it: the sums below add in its order
    np.multiply(camera.fx, xd, out=uv[:, 0])
    np.multiply(camera.fy, yd, out=uv[:, 1])
    uv += (camera.cx, camera.cy)
    if response == "flux":
        w = z
    elif response == "radiance":
        a, b, c, dd = camera.distort_jacobian(x, y)
        w = (a * dd - b * c) / z ** 3
    else:
        raise ValueError(f"response = {response!r}: must be 'flux' or 'radiance'")
    if radiance is not None:
        w = w * _disk_weight(radiance, radiance_axis, s, e1, e2, float(full_angle_rad), int(n))
    if direction_weight is not None:
        w = w * direction_weight(d)
    return {"valid": True, "uv": uv, "weight": w, "center_uv": c_uv[0]}


def spot_truth(camera: PinholeBrown, sun_dir, full_angle_rad: float, *, n: int = 2_000_000,
               response: str = "flux", radiance=None, radiance_axis=None, direction_weight=None) -> dict:
    """Exact (quadrature) description of the spot image of a uniform disk. Pure numpy.

    Returns pixel positions (u, v) in the OpenCV convention:

    * ``center_uv``: distorted projection of the disk centre (the sun direction itself);
    * ``mean_uv``: flux-weighted mean of the projection over the disk = centroid of the continuous
      image (weight per solid angle: cos(theta) for ``flux``, |dA/dOmega| for ``radiance``);
    * ``pixel_centroid_uv``: the first moment of the pixel-integrated image (each quadrature point
      binned into the pixel that contains it) -- what a perfect renderer's window centroid is;
    * ``disk_bias_px`` = mean - centre, ``pixel_bias_px`` = pixel_centroid - mean;
    * ``relative_flux``: flux relative to the same disk on axis (= <cos theta> for ``flux``).

    ``radiance``: a non-uniform disk, a callable L(r, cos φ) of the position on the disk (r = tan ρ
    / tan(a/2), φ the azimuth from ``radiance_axis``, a camera-frame vector across the disk), e.g.
    :class:`rigsim.optics.sun_radiance.DiskRadiance`; each point's weight is multiplied by L.
    ``direction_weight``: a callable of the directions (3, n) rows (x, y, z in the camera frame)
    multiplying each point's weight (e.g. a thick pinhole's vignetting).
    """
    pts = disk_image_points(camera, sun_dir, full_angle_rad, n=n, response=response, radiance=radiance,
                            radiance_axis=radiance_axis, direction_weight=direction_weight)
    if not pts["valid"]:
        return {"valid": False, "center_uv": pts["center_uv"]}
    uv, w, c_uv = pts["uv"], pts["weight"], pts["center_uv"][None, :]
    wsum = w.sum()
    mean = (w[:, None] * uv).sum(axis=0) / wsum
    np.floor(uv + 0.5, out=uv)  # each point binned into the pixel that holds it
    pix = (w[:, None] * uv).sum(axis=0) / wsum
    return {
        "valid": True,
        "center_uv": c_uv[0].tolist(),
        "mean_uv": mean.tolist(),
        "pixel_centroid_uv": pix.tolist(),
        "disk_bias_px": (mean - c_uv[0]).tolist(),
        "pixel_bias_px": (pix - mean).tolist(),
        "relative_flux": float(wsum / n),
        "quadrature_points": int(n),
    }


def _disk_weight(radiance, axis, s, e1, e2, full_angle_rad: float, n: int) -> np.ndarray:
    """L(r, cos φ) at the quadrature points of :func:`spot_truth` (sun's frame s, e1, e2)."""
    p = _disk_pattern_rows(full_angle_rad, n)  # rows: along s, e1, e2
    sin_rho = np.hypot(p[1], p[2])
    r = sin_rho / p[0] / math.tan(full_angle_rad / 2.0)
    if axis is None:
        cos_az = np.zeros_like(r)
    else:
        a = np.asarray(axis, dtype=np.float64).reshape(3)
        a = a - (a @ s) * s
        a /= np.linalg.norm(a)
        with np.errstate(divide="ignore", invalid="ignore"):
            cos_az = np.where(sin_rho > 0, (p[1] * (a @ e1) + p[2] * (a @ e2)) / sin_rho, 0.0)
    return radiance(np.minimum(r, 1.0), cos_az)


def window_centroid(image: np.ndarray, origin_uv=(0, 0)) -> np.ndarray:
    """First moment (u, v) of a non-negative image in detector pixel coordinates."""
    img = np.asarray(image, dtype=np.float64)
    tot = img.sum()
    if not tot > 0:
        return np.array([np.nan, np.nan])
    v, u = np.indices(img.shape)
    return np.array([(img * u).sum() / tot + origin_uv[0], (img * v).sum() / tot + origin_uv[1]])


def spot_geometry_flags(camera: PinholeBrown, sun_dir, full_angle_rad: float,
                        window: tuple[int, int, int, int] | None = None,
                        margin_px: float = 1.0) -> dict:
    """Geometry flags for a spot, from the projected rim.

    ``spot_outside_model`` (behind the camera or beyond the distortion model's domain),
    ``spot_off_detector`` (no part on the detector), ``spot_cut_by_edge`` (partly off),
    ``spot_exceeds_window`` (rim closer than ``margin_px`` to the window edge; flux would be lost).
    ``window`` is (u0, v0, width, height) in detector pixels.
    """
    s = _unit(sun_dir)
    rim, rim_ok = spot_outline(camera, s, full_angle_rad)
    c_uv, c_ok = camera.project_valid(s[None, :])
    flags = {"spot_outside_model": bool(not (np.all(rim_ok) and c_ok[0]))}
    if flags["spot_outside_model"]:
        flags.update(spot_off_detector=True, spot_cut_by_edge=False, spot_exceeds_window=False)
        return flags
    on = camera.on_detector(rim)
    c_on = bool(camera.on_detector(c_uv)[0])
    lo, hi = rim.min(axis=0), rim.max(axis=0)
    overlaps = (hi[0] >= -0.5 and lo[0] < camera.width - 0.5 and hi[1] >= -0.5
                and lo[1] < camera.height - 0.5)
    flags["spot_off_detector"] = bool(not (np.any(on) or c_on or overlaps))
    flags["spot_cut_by_edge"] = bool(not flags["spot_off_detector"] and not np.all(on))
    if window is not None:
        u0, v0, w, h = window
        flags["spot_exceeds_window"] = bool(
            lo[0] < u0 - 0.5 + margin_px or hi[0] > u0 + w - 0.5 - margin_px
            or lo[1] < v0 - 0.5 + margin_px or hi[1] > v0 + h - 0.5 - margin_px)
    else:
        flags["spot_exceeds_window"] = False
    flags["spot_extent_px"] = [float(hi[0] - lo[0]), float(hi[1] - lo[1])]
    return flags


def max_spot_extent_px(camera: PinholeBrown, full_angle_rad: float, grid: int = 9) -> float:
    """The largest width or height (px) of the sun's image anywhere on the detector: its projected
    rim at a grid of points over the detector (distortion and obliquity stretch it off axis)."""
    uu = np.linspace(0.0, camera.width - 1.0, grid)
    vv = np.linspace(0.0, camera.height - 1.0, grid)
    U, V = np.meshgrid(uu, vv)
    dirs = camera.unproject(np.column_stack([U.ravel(), V.ravel()]))
    ext = 2.0 * math.tan(full_angle_rad / 2.0) * max(camera.fx, camera.fy)
    dirs = dirs[np.all(np.isfinite(dirs), axis=1)]
    if len(dirs) == 0:
        return ext
    # every grid point's rim (spot_outline's, n = 90) in one projection: (points, 90, 2)
    s = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    rim, rim_ok = camera.project_valid(_rim_directions(s, full_angle_rad, 90).reshape(-1, 3))
    rim, rim_ok = rim.reshape(len(s), 90, 2), rim_ok.reshape(len(s), 90)
    whole = np.all(rim_ok, axis=1)
    if np.any(whole):
        ext = max(ext, float(np.max(rim[whole].max(axis=1) - rim[whole].min(axis=1))))
    return ext


def sun_window_px(camera: PinholeBrown, full_angle_rad: float, minimum: int = 32, margin_px: int = 6) -> int:
    """The render/readout window for the sun's image on this camera: the largest spot plus a margin
    on each side, even, at least ``minimum``."""
    w = int(math.ceil(max_spot_extent_px(camera, full_angle_rad))) + 2 * margin_px
    return max(int(minimum), w + (w % 2))

