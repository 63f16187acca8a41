"""A FITS world coordinate system (TAN projection with SIP distortion) for a distorted pinhole camera at an
attitude: what a star frame's header carries so that astropy, ds9 or astrometry.net place the catalogue on
it. FITS pixels are 1-based (CRPIX = rigsim's principal point + 1); astropy's ``world_to_pixel`` returns
0-based pixels, rigsim's convention. docs/formats.md gives the derivation and the measured accuracy."""

from __future__ import annotations

import functools
import math

import numpy as np

SIP_ORDER = 7  # the inverse of k1 r³ + k2 r⁵ needs r⁷ for 0.01 px at a 20° field's corners


def _radec(d: np.ndarray) -> tuple[float, float]:
    d = d / np.linalg.norm(d)
    return math.degrees(math.atan2(d[1], d[0])) % 360.0, math.degrees(math.asin(max(-1.0, min(1.0, d[2]))))


def _fit_sip(x: np.ndarray, y: np.ndarray, dx: np.ndarray, dy: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """SIP coefficient arrays [p, q] (terms with 2 ≤ p + q ≤ order) of dx(x, y), dy(x, y) by least squares."""
    s = max(float(np.max(np.abs(x))), float(np.max(np.abs(y))), 1.0)
    terms = [(p, q) for n in range(2, order + 1) for p in range(n + 1) for q in [n - p]]
    A = np.stack([(x / s) ** p * (y / s) ** q for p, q in terms], axis=1)
    cx, *_ = np.linalg.lstsq(A, dx, rcond=None)
    cy, *_ = np.linalg.lstsq(A, dy, rcond=None)
    out_x, out_y = np.zeros((order + 1, order + 1)), np.zeros((order + 1, order + 1))
    for (p, q), a, b in zip(terms, cx, cy):
        out_x[p, q], out_y[p, q] = a / s ** (p + q), b / s ** (p + q)
    return out_x, out_y


@functools.lru_cache(maxsize=16)
def _sip_of(cam, order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The SIP polynomials (A, B, AP, BP) of a camera's distortion: they depend on the camera alone, not on the
    attitude, so a sequence of frames fits them once (a frozen camera is its own cache key)."""
    from rigsim.optics.camera import brown_undistort

    # a grid of detected (distorted) pixels a little beyond the detector, and where the pinhole would put them
    u, v = np.meshgrid(np.linspace(-0.05 * cam.width, 1.05 * cam.width - 1, 61),
                       np.linspace(-0.05 * cam.height, 1.05 * cam.height - 1, 61))
    xd, yd = u.ravel() - cam.cx, v.ravel() - cam.cy
    xn, yn, ok = brown_undistort(xd / cam.fx, yd / cam.fy, cam.k1, cam.k2, cam.p1, cam.p2, cam.k3)
    xd, yd, xu, yu = xd[ok], yd[ok], xn[ok] * cam.fx, yn[ok] * cam.fy
    Ac, Bc = _fit_sip(xd, yd, xu - xd, yu - yd, order)     # pixel → sky: detected to pinhole
    APc, BPc = _fit_sip(xu, yu, xd - xu, yd - yu, order)   # sky → pixel: pinhole to detected
    for a in (Ac, Bc, APc, BPc):
        a.flags.writeable = False
    return Ac, Bc, APc, BPc


def camera_wcs(cam, R_cam_from_icrs, order: int = SIP_ORDER):
    """astropy ``WCS`` of ``cam`` (a :class:`~rigsim.optics.camera.PinholeBrown`: OpenCV's model, pixel centres on
    integers, 0-based) looking along ``R_cam_from_icrs``'s +z."""
    from astropy.wcs import WCS, Sip

    R = np.asarray(R_cam_from_icrs, float)
    xc, yc, b = R[0], R[1], R[2]  # the camera axes in ICRS
    ra0, dec0 = _radec(b)
    a0, d0 = math.radians(ra0), math.radians(dec0)
    east = np.array([-math.sin(a0), math.cos(a0), 0.0])
    north = np.array([-math.sin(d0) * math.cos(a0), -math.sin(d0) * math.sin(a0), math.cos(d0)])
    # undistorted pixel offsets from the principal point = diag(fx, fy) · M · (ξ, η) [rad], standard coordinates
    M = np.array([[xc @ east, xc @ north], [yc @ east, yc @ north]])
    CD = np.degrees(np.linalg.inv(np.diag([cam.fx, cam.fy]) @ M))
    Ac, Bc, APc, BPc = _sip_of(cam, order)
    w = WCS(naxis=2)
    w.wcs.ctype = ["RA---TAN-SIP", "DEC--TAN-SIP"]
    w.wcs.crpix = [cam.cx + 1.0, cam.cy + 1.0]
    w.wcs.crval = [ra0, dec0]
    w.wcs.cd = CD
    w.wcs.radesys = "ICRS"
    w.wcs.cunit = ["deg", "deg"]
    w.sip = Sip(Ac, Bc, APc, BPc, w.wcs.crpix)
    w.pixel_shape = (int(cam.width), int(cam.height))
    return w


def star_frame_header(cam, R_cam_from_icrs, *, exposure_s: float, gain_e_per_dn: float, date_obs: str,
                      seed: int, detector: str = "") -> list[tuple[str, object, str]]:
    """The FITS cards of a star frame: its WCS (TAN-SIP), EXPTIME, GAIN, DATE-OBS, BUNIT, the seed, the detector
    model and the pixel convention."""
    h = camera_wcs(cam, R_cam_from_icrs).to_header(relax=True)
    cards = [(c.keyword, c.value, c.comment) for c in h.cards if c.keyword not in ("DATE-OBS", "MJD-OBS", "WCSAXES")]
    cards += [("EXPTIME", float(exposure_s), "[s] exposure time"),
              ("GAIN", float(gain_e_per_dn), "[e-/adu] conversion gain"),
              ("DATE-OBS", date_obs, "mid-exposure (UTC)"),
              ("BUNIT", "adu", "digital numbers"),
              ("RIGSEED", int(seed) if int(seed) < 2**63 else str(seed), "rigsim frame seed (same seed, same frame)"),
              ("DETMODEL", str(detector)[:40], "rigsim detector model"),
              ("PIXCONV", "FITS 1-based", "rigsim (u, v) are 0-based: FITS = +1")]
    return cards
