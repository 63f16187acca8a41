"""Measuring on a plane seen obliquely through a homography: centroids, circle fits and the
hole/spot offset of the diaphragm screen (seed 000) as the aiming camera sees it.

``H`` is the 3×3 homography from plane coordinates (s, t) in mm to pixels (u, v), OpenCV's pixel
convention. Every function also accepts an object carrying it as ``H_screen_to_uv``.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "BACKGROUNDS",
    "apply_flat",
    "border_plane",
    "flat_field",
    "hole_spot_offset",
    "masked_screen_centroid",
    "pixel_area_mm2",
    "plane_to_uv",
    "screen_centroid",
    "screen_circle_fit",
    "uv_to_plane",
]


def _H(H) -> np.ndarray:
    return np.asarray(getattr(H, "H_screen_to_uv", H), float)


def plane_to_uv(H, st) -> np.ndarray:
    """Plane points (..., 2) mm → pixels (..., 2)."""
    H = _H(H)
    st = np.asarray(st, float)
    h = st @ H[:, :2].T + H[:, 2]
    return h[..., :2] / h[..., 2:3]


def uv_to_plane(H, uv) -> np.ndarray:
    """Pixels (..., 2) → plane points (..., 2) mm."""
    Hi = np.linalg.inv(_H(H))
    uv = np.asarray(uv, float)
    h = uv @ Hi[:, :2].T + Hi[:, 2]
    return h[..., :2] / h[..., 2:3]


def pixel_area_mm2(H, uv: np.ndarray) -> np.ndarray:
    """Plane area (mm²) seen by a pixel at ``uv``: |det d(s,t)/d(u,v)| of the homography."""
    Hi = np.linalg.inv(_H(H))
    h = np.asarray(uv, float) @ Hi[:, :2].T + Hi[:, 2]
    w = h[:, 2]
    # for a homography x = (A u + b) / (c·u + d): det J = det(Hi) / w^3
    return np.abs(np.linalg.det(Hi) / w**3)


def screen_centroid(img, H, *, threshold: float = 0.0, mask=None) -> np.ndarray:
    """Centroid on the plane (s, t mm) of an image of plane radiance (or photons).

    Every pixel above ``threshold`` is mapped onto the plane and weighted by its value (minus the
    threshold) times the plane area it sees, so a uniformly lit disk gives the disk's centre up to
    pixel-phase effects at its rim.
    """
    a = np.asarray(img, float)
    use = a > threshold
    if mask is not None:
        use &= np.asarray(mask, bool)
    vv, uu = np.nonzero(use)
    if len(uu) == 0:
        return np.array([np.nan, np.nan])
    uv = np.stack([uu, vv], axis=1).astype(float)
    w = (a[vv, uu] - threshold) * pixel_area_mm2(H, uv)
    st = uv_to_plane(H, uv)
    return (w[:, None] * st).sum(axis=0) / w.sum()


def screen_circle_fit(img, H, *, level: float | None = None, mask=None):
    """Sub-pixel edge points of the image (:func:`rigsim.imaging.edge_points`) mapped onto the
    plane and fitted with a circle (:func:`rigsim.imaging.fit_circle_points`): centre (s, t) mm and
    radius mm in ``CircleFit.u, .v, .radius_px`` (the units are mm here). None: too few edges."""
    from rigsim.imaging.edges import edge_points, fit_circle_points

    ep = edge_points(np.asarray(img, float), level=level, mask=mask)
    if len(ep.uv) < 5:
        return None
    return fit_circle_points(uv_to_plane(H, ep.uv))


def masked_screen_centroid(img: np.ndarray, H, level: float, *, weights: str = "value") -> tuple[np.ndarray, int]:
    """Centroid on the plane (mm) of the pixels whose smoothed value exceeds ``level`` times the
    smoothed image's robust peak (its 99.95th percentile); weights = value × plane area of the
    pixel (``weights="area"``: the plane area alone, the centre of the region that passes). Returns
    (centre, number of pixels); NaN when fewer than 10 pixels pass."""
    import cv2

    a = np.asarray(img, np.float64)
    sm = cv2.GaussianBlur(a.astype(np.float32), (0, 0), 2.0)
    peak = float(np.percentile(sm, 99.95))
    if not (peak > 0):
        return np.array([np.nan, np.nan]), 0
    vv, uu = np.nonzero(sm > level * peak)
    if len(uu) < 10:
        return np.array([np.nan, np.nan]), len(uu)
    uv = np.stack([uu, vv], axis=1).astype(float)
    w = pixel_area_mm2(H, uv) if weights == "area" else np.clip(a[vv, uu], 0.0, None) * pixel_area_mm2(H, uv)
    st = uv_to_plane(H, uv)
    return (w[:, None] * st).sum(axis=0) / w.sum(), len(uu)


BACKGROUNDS = ("none", "plane")

FLAT_MIN_LEVEL = 0.5
"""A flat-field pixel below this fraction of the flat's median (the hole, the field's dark edge)
is not corrected."""


def flat_field(frames_dn, dark_dn) -> np.ndarray:
    """The screen's and the camera's relative response per pixel from frames of the screen lit
    evenly by a lamp (the simulator shuttered): their mean less ``dark_dn`` (the dark offset, or a
    frame without the lamp: the hole frame, whose room light the flat frames hold too), over its
    median; NaN where it is below :data:`FLAT_MIN_LEVEL` of the median (the hole, which a lamp in
    front of the screen leaves dark). It holds the screen's grain (its albedo) and the detector's
    PRNU."""
    f = np.mean([np.asarray(x, float) for x in frames_dn], axis=0) - np.asarray(dark_dn, float)
    med = float(np.median(f))
    if not med > 0.0:
        raise ValueError(f"flat field: median level {med:.3g} DN above the dark frame; the screen is not lit")
    f = f / med
    f[~(f >= FLAT_MIN_LEVEL)] = np.nan
    return f


def apply_flat(hole_dn: np.ndarray, spot_dn: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """The spot frame with its spot divided by the flat (:func:`flat_field`): hole + (spot − hole)/flat,
    the returned light's irradiance as a uniform screen would show it; pixels without a flat value
    keep theirs. The hole's glow comes through the hole, not off the screen, so it is not divided."""
    hole = np.asarray(hole_dn, float)
    d = np.asarray(spot_dn, float) - hole
    ok = np.isfinite(flat)
    d[ok] = d[ok] / flat[ok]
    return hole + d


def border_plane(img: np.ndarray, border: float = 0.05) -> np.ndarray:
    """The least-squares quadratic surface in (u, v) through the frame's border strip (``border`` of
    its width and height on each side), over the whole frame: the room light's level and gradient
    (a linear gradient on the screen is slightly curved in the obliquely viewing camera) where
    neither the hole nor the returned spot reaches."""
    a = np.asarray(img, float)
    Hh, Ww = a.shape
    bw, bh = max(1, int(border * Ww)), max(1, int(border * Hh))
    m = np.zeros(a.shape, bool)
    m[:bh], m[-bh:], m[:, :bw], m[:, -bw:] = True, True, True, True
    vv, uu = np.nonzero(m)
    x, y = (uu - 0.5 * Ww) / Ww, (vv - 0.5 * Hh) / Hh
    A = np.column_stack([np.ones(len(uu)), x, y, x * x, x * y, y * y])
    coef, *_ = np.linalg.lstsq(A, a[vv, uu], rcond=None)
    U, V = np.meshgrid((np.arange(Ww) - 0.5 * Ww) / Ww, (np.arange(Hh) - 0.5 * Hh) / Hh)
    return coef[0] + coef[1] * U + coef[2] * V + coef[3] * U * U + coef[4] * U * V + coef[5] * V * V


def hole_spot_offset(hole_dn: np.ndarray, spot_dn: np.ndarray, H, *, object_pixel_mm: float, offset_dn: float,
                     hole_level: float = 0.5, spot_level: float = 0.1, background: str = "none") -> dict:
    """Centres of the hole and of the returned spot on the screen (mm) and their offset in the
    aiming camera's object pixels (spot − hole; x, y = the plane's s, t axes).

    The hole is fitted on the hole frame (the spot blocked); the spot on spot − hole frame (the
    hole's glow, present in both frames, cancels). ``object_pixel_mm``: the size of one camera pixel
    on the screen, the unit of the offset (seed 000's Table 1 counts in it).

    ``background``: ``"none"`` (the frames' dark offset only) or ``"plane"``: the hole frame's
    room-light level and gradient (:func:`border_plane`) are subtracted before its fit, so that a
    lit screen does not pass the hole's threshold, and the hole is fitted on its contrast's magnitude
    (a hole glowing less than the lit screen around it is a dark disk), its centre the centre of the
    region above ``hole_level`` of it (the contrast inside follows the light's gradient). Room light is in both
    frames: it cancels in spot − hole."""
    if background not in BACKGROUNDS:
        raise ValueError(f"background = {background!r}: must be one of {BACKGROUNDS}")
    hole = np.asarray(hole_dn, float) - offset_dn
    if background == "plane":  # the hole's contrast against the lit screen, glowing or dark
        hole = np.abs(hole - border_plane(hole))
    spot = np.asarray(spot_dn, float) - np.asarray(hole_dn, float)
    # under room light the hole's contrast follows the light's gradient: fit the region, not its values
    hc, nh = masked_screen_centroid(hole, H, hole_level, weights="area" if background == "plane" else "value")
    sc, ns = masked_screen_centroid(spot, H, spot_level)
    return {"hole_mm": hc, "spot_mm": sc, "offset_mm": sc - hc, "offset_px": (sc - hc) / object_pixel_mm,
            "hole_pixels": nh, "spot_pixels": ns}
