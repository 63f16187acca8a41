"""The FITS WCS of a distorted pinhole camera (rigsim.optics.wcs) against independent truths: OpenCV's
projectPoints for where a sky direction lands on the detector, astropy's own spherical coordinates for the
tangent point, and a hand-made polynomial for the SIP fit. Fast (no catalogue, no render)."""

import math

import cv2
import numpy as np
import pytest
from astropy.coordinates import SkyCoord
from astropy.io import fits
from astropy.wcs import WCS
from scipy.spatial.transform import Rotation

from rigsim.optics.camera import PinholeBrown
from rigsim.optics.wcs import _fit_sip, _radec, camera_wcs, star_frame_header

# a non-square detector, fx ≠ fy, an off-centre principal point, radial and tangential distortion (about 17° × 12°)
CAM = PinholeBrown(fx=2400.0, fy=2430.0, cx=655.3, cy=470.8, k1=-0.08, k2=0.12, p1=4e-4, p2=-3e-4, k3=0.0,
                   width=1280, height=960)


def _icrs(d):
    from astropy.coordinates import CartesianRepresentation

    d = np.atleast_2d(d)
    return SkyCoord(CartesianRepresentation(d[:, 0], d[:, 1], d[:, 2]), frame="icrs")


def _opencv_pixels(R, dirs_icrs, cam=CAM):
    """OpenCV's projection of ICRS directions by a camera at R_cam_from_icrs (0-based pixels)."""
    rvec, _ = cv2.Rodrigues(np.asarray(R, float))
    K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1.0]])
    dist = np.array([cam.k1, cam.k2, cam.p1, cam.p2, cam.k3])
    uv, _ = cv2.projectPoints(np.asarray(dirs_icrs, float).reshape(-1, 1, 3), rvec, np.zeros(3), K, dist)
    return uv.reshape(-1, 2)


def _dirs_in_view(R, n, rng, cam=CAM):
    """n ICRS directions whose rays fall on the detector (the inverse of the pinhole, undistorted by OpenCV)."""
    uv = np.stack([rng.uniform(0, cam.width - 1, n), rng.uniform(0, cam.height - 1, n)], axis=1)
    K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1.0]])
    xy = cv2.undistortPoints(uv.reshape(-1, 1, 2), K, np.array([cam.k1, cam.k2, cam.p1, cam.p2, cam.k3]),
                             criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)).reshape(-1, 2)
    rays = np.column_stack([xy, np.ones(n)])
    return (rays / np.linalg.norm(rays, axis=1, keepdims=True)) @ np.asarray(R)  # camera → ICRS: Rᵀ·ray


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_wcs_agrees_with_opencv_projection(seed):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    w = camera_wcs(CAM, R)
    d = _dirs_in_view(R, 300, rng)
    truth = _opencv_pixels(R, d)
    x, y = w.world_to_pixel(_icrs(d))
    assert np.max(np.hypot(x - truth[:, 0], y - truth[:, 1])) < 0.01
    # and back: pixel → sky lands on the direction to 0.01 px (about 1 mrad / 2400 px)
    c = w.pixel_to_world(truth[:, 0], truth[:, 1])
    back = np.stack([c.cartesian.x.value, c.cartesian.y.value, c.cartesian.z.value], axis=1)
    ang = np.arccos(np.clip(np.sum(back * d, axis=1), -1, 1))
    assert np.max(ang) * CAM.fx < 0.01


def test_the_principal_point_is_the_boresight_and_the_header_keywords():
    R = Rotation.from_euler("zyx", [200.0, -35.0, 10.0], degrees=True).as_matrix()
    w = camera_wcs(CAM, R)
    bore = _icrs(R[2])  # the camera's +z in ICRS
    assert w.wcs.crpix[0] == CAM.cx + 1.0 and w.wcs.crpix[1] == CAM.cy + 1.0  # FITS pixels are 1-based
    assert w.wcs.crval[0] == pytest.approx(bore.ra.deg[0], abs=1e-9)
    assert w.wcs.crval[1] == pytest.approx(bore.dec.deg[0], abs=1e-9)
    x, y = w.world_to_pixel(bore)
    assert x[0] == pytest.approx(CAM.cx, abs=1e-6) and y[0] == pytest.approx(CAM.cy, abs=1e-6)
    assert tuple(w.pixel_shape) == (CAM.width, CAM.height)
    assert list(w.wcs.ctype) == ["RA---TAN-SIP", "DEC--TAN-SIP"] and w.wcs.radesys == "ICRS"


@pytest.mark.parametrize("d", [(1.0, -2.0, 0.5), (-3.0, -1.0, -2.0), (0.2, 0.7, -0.1), (-1.0, 1e-3, 0.0)])
def test_radec_matches_astropy(d):
    c = _icrs(d)
    ra, dec = _radec(np.array(d))
    assert 0.0 <= ra < 360.0
    assert ra == pytest.approx(c.ra.deg[0], abs=1e-10) and dec == pytest.approx(c.dec.deg[0], abs=1e-10)


def test_radec_at_the_poles():
    assert _radec(np.array([0.0, 0.0, 2.0]))[1] == 90.0
    assert _radec(np.array([0.0, 0.0, -0.5]))[1] == -90.0


def test_fit_sip_recovers_a_known_polynomial():
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-600, 600, 400), rng.uniform(-500, 500, 400)
    # dx = 3e-4 x² − 2e-7 x y² + 1e-12 x³ y², dy = −5e-4 x y + 4e-13 y⁵ (orders 2 to 5, coefficients by hand)
    dx = 3e-4 * x**2 - 2e-7 * x * y**2 + 1e-12 * x**3 * y**2
    dy = -5e-4 * x * y + 4e-13 * y**5
    A, B = _fit_sip(x, y, dx, dy, 5)
    assert A.shape == B.shape == (6, 6)
    ea, eb = np.zeros((6, 6)), np.zeros((6, 6))
    ea[2, 0], ea[1, 2], ea[3, 2] = 3e-4, -2e-7, 1e-12
    eb[1, 1], eb[0, 5] = -5e-4, 4e-13
    scale = np.array([[600.0 ** (p + q) for q in range(6)] for p in range(6)])  # each term's size at the edge
    np.testing.assert_allclose(A * scale, ea * scale, atol=1e-9)
    np.testing.assert_allclose(B * scale, eb * scale, atol=1e-9)


def test_fit_sip_has_no_constant_or_linear_terms():
    # a pure offset and a pure scale are the CRPIX's and the CD's job, not SIP's (orders 0 and 1 stay zero)
    x, y = np.meshgrid(np.linspace(-1, 1, 9), np.linspace(-1, 1, 9))
    x, y = x.ravel(), y.ravel()
    A, B = _fit_sip(x, y, 0.5 * x**2, 0.25 * y**2, 3)
    assert A[0, 0] == A[1, 0] == A[0, 1] == B[0, 0] == B[1, 0] == B[0, 1] == 0.0
    assert A[2, 0] == pytest.approx(0.5, abs=1e-12) and B[0, 2] == pytest.approx(0.25, abs=1e-12)


def test_star_frame_header_cards_and_its_wcs():
    R = Rotation.random(random_state=9).as_matrix()
    cards = star_frame_header(CAM, R, exposure_s=0.25, gain_e_per_dn=3.5, date_obs="2025-01-01T12:00:00.000",
                              seed=2**64 - 1, detector="x" * 50)
    keys = [k for k, _, _ in cards]
    assert "MJD-OBS" not in keys and "WCSAXES" not in keys and keys.count("DATE-OBS") == 1
    h = fits.Header(cards)
    assert h["EXPTIME"] == 0.25 and h["GAIN"] == 3.5 and h["DATE-OBS"] == "2025-01-01T12:00:00.000"
    assert h["BUNIT"] == "adu" and h["PIXCONV"] == "FITS 1-based"
    assert h["RIGSEED"] == str(2**64 - 1)  # beyond a FITS integer: kept as text
    assert h["DETMODEL"] == "x" * 40
    assert star_frame_header(CAM, R, exposure_s=1, gain_e_per_dn=1, date_obs="2025-01-01", seed=2**63 - 1)[-3][1] == 2**63 - 1
    w = WCS(h)
    d = _dirs_in_view(R, 50, np.random.default_rng(9))
    truth = _opencv_pixels(R, d)
    x, y = w.world_to_pixel(_icrs(d))
    assert np.max(np.hypot(x - truth[:, 0], y - truth[:, 1])) < 0.01
    assert math.isclose(h["CRPIX1"], CAM.cx + 1) and math.isclose(h["CRPIX2"], CAM.cy + 1)


def _pixels_at(uv, R, cam):
    """ICRS directions of pixels uv (OpenCV's undistortion of the camera)."""
    K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1.0]])
    xy = cv2.undistortPoints(np.asarray(uv, float).reshape(-1, 1, 2), K, np.array([cam.k1, cam.k2, cam.p1, cam.p2, cam.k3]),
                             criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)).reshape(-1, 2)
    rays = np.column_stack([xy, np.ones(len(xy))])
    return (rays / np.linalg.norm(rays, axis=1, keepdims=True)) @ np.asarray(R)


def test_the_sky_to_pixel_sip_ap_bp_against_opencv():
    """The inverse polynomials AP, BP (what ds9 or SExtractor use; astropy's world_to_pixel iterates on A, B
    instead), evaluated by the SIP definition: detected = CRPIX + (U + AP(U, V), V + BP(U, V)), (U, V) the
    linear TAN pixel offsets. Brown's distortion is a polynomial of the undistorted position: exact to rounding."""
    from numpy.polynomial.polynomial import polyval2d

    R = Rotation.random(random_state=4).as_matrix()
    w = camera_wcs(CAM, R)
    g = np.linspace(0, 1, 15)
    uv = np.stack([a.ravel() for a in np.meshgrid(g * (CAM.width - 1), g * (CAM.height - 1))], axis=1)
    truth = _opencv_pixels(R, _pixels_at(uv, R, CAM))
    c = _icrs(_pixels_at(uv, R, CAM))
    lin = w.wcs_world2pix(np.column_stack([c.ra.deg, c.dec.deg]), 0)  # TAN alone, no SIP (0-based)
    U, V = (lin - (w.wcs.crpix - 1)).T
    det = np.column_stack([U + polyval2d(U, V, w.sip.ap), V + polyval2d(U, V, w.sip.bp)]) + (w.wcs.crpix - 1)
    assert np.max(np.hypot(*(det - truth).T)) < 1e-6  # measured 5e-12 px


def test_the_star_camera_wcs_to_1e_4_px_over_the_detector_and_its_margin():
    """The star sensor's 20° camera: world_to_pixel against OpenCV on a grid from 4 % before to 4 % beyond the
    detector's edges (the fit's samples reach 5 % beyond), corners included (measured 1.4e-5 px)."""
    from rigsim.rig.load import load_star_rig

    cam = load_star_rig().sensor.camera()
    R = Rotation.random(random_state=3).as_matrix()
    w = camera_wcs(cam, R)
    g = np.linspace(-0.04, 1.04, 28)
    uv = np.stack([a.ravel() for a in np.meshgrid(g * (cam.width - 1), g * (cam.height - 1))], axis=1)
    d = _pixels_at(uv, R, cam)
    truth = _opencv_pixels(R, d, cam)
    x, y = w.world_to_pixel(_icrs(d))
    assert np.max(np.hypot(x - truth[:, 0], y - truth[:, 1])) < 1e-4


def test_star_frame_header_takes_its_frame_values_by_keyword_only():
    R = np.eye(3)
    with pytest.raises(TypeError):
        star_frame_header(CAM, R, 0.25, 3.5, "2025-01-01", 1)
    cards = star_frame_header(cam=CAM, R_cam_from_icrs=R, exposure_s=0.25, gain_e_per_dn=3.5, date_obs="2025-01-01", seed=1)
    assert dict((k, v) for k, v, _ in cards)["RIGSEED"] == 1


@pytest.mark.parametrize("seed,value", [(2**63 - 1, 2**63 - 1), (2**63, str(2**63))])
def test_rigseed_is_an_integer_while_a_fits_integer_holds_it(seed, value):
    # FITS integer cards are signed 64-bit: 2^63 - 1 is the largest
    cards = star_frame_header(CAM, np.eye(3), exposure_s=1.0, gain_e_per_dn=1.0, date_obs="2025-01-01", seed=seed)
    v = dict((k, v) for k, v, _ in cards)["RIGSEED"]
    assert v == value and type(v) is type(value)
