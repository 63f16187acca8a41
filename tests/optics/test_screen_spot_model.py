"""The aiming camera's view of the divergent returned spot (rigsim.optics.screen_spot_model) against
a second method, the renderer's construction (the pencil's disk and the divergence's disk
rasterised on a screen-plane grid, convolved by FFT, sampled back bilinearly at every pixel's
screen point through the nominal homography); its analytic gradient against differences; the fit
on frames drawn from the second image against the image's Cramér–Rao bound, and the moments'
centroid of rigsim.imaging.screen on the same frames."""

import math

import numpy as np
import pytest
from scipy.ndimage import map_coordinates
from scipy.signal import fftconvolve

from rigsim.imaging import NoiseModel
from rigsim.imaging.forward_model import fit_spot_model, model_crlb
from rigsim.imaging.screen import masked_screen_centroid, plane_to_uv, uv_to_plane
from rigsim.optics.aiming import nominal_screen_homography
from rigsim.optics.screen_spot_model import ScreenSpotModel, disk_overlap, disk_overlap_slope
from rigsim.procedures.cube_mirror.model_spots import screen_spot_radii_mm
from rigsim.rig import load_rig

RIG = load_rig("sun_sensor_2axis_diaphragm")
AC = RIG.aiming_camera
DET = AC.detector
H = nominal_screen_homography(AC)
A, R = screen_spot_radii_mm(RIG)


def disk_grid(r, gs, ss=4):
    n = math.ceil(r / gs) + 1
    x = (np.arange(-n, n + 1)[:, None] + ((np.arange(ss) + 0.5) / ss - 0.5)[None, :]).ravel() * gs
    X, Y = np.meshgrid(x, x)
    return (X * X + Y * Y < r * r).astype(float).reshape(2 * n + 1, ss, 2 * n + 1, ss).mean(axis=(1, 3))


def second_method(c_st, origin, shape, gs=0.02):
    """Plateau-1 image of the spot centred at c_st (mm) on the window: the renderer's construction."""
    pen = disk_grid(A, gs)
    ker = disk_grid(R, gs)
    img = fftconvolve(pen, ker / ker.sum(), mode="full") / (A / R) ** 2
    n0 = (img.shape[0] - 1) // 2
    v, u = np.indices(shape)
    st = uv_to_plane(H, np.stack([u.ravel() + origin[0], v.ravel() + origin[1]], 1).astype(float))
    q = (st - c_st) / gs + n0
    return map_coordinates(img, [q[:, 1], q[:, 0]], order=1, cval=0.0).reshape(shape)


def test_the_overlap_is_the_two_disks_and_its_slope_its_derivative():
    d = np.linspace(0.0, 8.0, 4001)
    ov = disk_overlap(d, A, R)
    assert ov[0] == pytest.approx(math.pi * A * A) and ov[-1] == 0.0
    # the lens's area by a midpoint rule over the small disk
    for dd in (4.9, 6.0, 7.1):
        n = 1500
        x = -A + (np.arange(n) + 0.5) * 2 * A / n
        X, Y = np.meshgrid(x, x)
        inside = (X * X + Y * Y < A * A) & ((X - dd) ** 2 + Y * Y < R * R)
        assert disk_overlap(np.array([dd]), A, R)[0] == pytest.approx(inside.sum() * (2 * A / n) ** 2, rel=2e-3)
    num = np.gradient(ov, d)
    smooth = (np.abs(d - (R - A)) > 0.05) & (np.abs(d - (R + A)) > 0.05)  # the slope is a square root at the ends
    smooth[[0, -1]] = False
    assert np.abs(num - disk_overlap_slope(d, A, R))[smooth].max() < 2e-3 * np.abs(num).max()


def test_the_model_image_is_the_renderers_construction_and_its_gradient_its_derivative():
    """Near the rim (a 120 × 120 window across it, the hole elsewhere): every pixel to 5e-4 of the
    plateau. The analytic gradient equals central differences to 1e-6."""
    c = np.array([0.3, -0.4])
    uvc = plane_to_uv(H, c)
    rim_uv = plane_to_uv(H, c + np.array([R, 0.0]))
    origin = (int(rim_uv[0]) - 60, int(rim_uv[1]) - 60)
    m = ScreenSpotModel(H, origin, (120, 120), A, R)
    ref = second_method(c, origin, (120, 120))
    img = m(*uvc)
    assert 0.0 < img.min() < 0.2 and img.max() > 0.8  # the window spans the rim
    assert np.abs(img - ref).max() < 5e-4
    p, du, dv = m.gradient(*uvc)
    h = 1e-3
    assert np.abs(du - (m(uvc[0] + h, uvc[1]) - m(uvc[0] - h, uvc[1])) / (2 * h)).max() < 1e-6
    assert np.abs(dv - (m(uvc[0], uvc[1] + h) - m(uvc[0], uvc[1] - h)) / (2 * h)).max() < 1e-6


def test_the_hole_takes_its_light():
    m = ScreenSpotModel(H, (700, 500), (200, 200), A, R, hole_centre_st=(0.0, 0.0), hole_radius_mm=A)
    hole_uv = plane_to_uv(H, np.zeros(2))
    img = m(*hole_uv)
    i, j = int(round(hole_uv[1])) - 500, int(round(hole_uv[0])) - 700
    assert img[i, j] == 0.0 and img[0, 0] == pytest.approx(1.0)
    # the pixels the hole covers, on the screen: its area
    area = np.sum(m.hole_coverage * np.abs(np.linalg.det(m._jac(*hole_uv))))
    assert area == pytest.approx(math.pi * A * A, rel=2e-3)


@pytest.mark.slow
def test_the_fit_attains_the_crlb_and_the_moments_carry_the_holes_bias():
    """60 spot frames (plateau at half the full well) drawn from the second method's image with the
    hole's glow, fitted without the hole's pixels: rms error per axis within 1.15× the bound (60
    draws: 9 % sampling error of the rms). The moments' centroid of the spot − hole frame is pulled
    away from the hole by the light lost into it: (a/R)² of the spot's offset from the hole."""
    c = np.array([0.37, -0.52])
    uvc = plane_to_uv(H, c)
    ang = np.linspace(0.0, 2 * math.pi, 256, endpoint=False)
    rim = plane_to_uv(H, c + (A + R) * np.stack([np.cos(ang), np.sin(ang)], 1))
    o = (int(rim[:, 0].min()) - 4, int(rim[:, 1].min()) - 4)
    shape = (int(rim[:, 1].max()) + 5 - o[1], int(rim[:, 0].max()) + 5 - o[0])
    m = ScreenSpotModel(H, o, shape, A, R, hole_centre_st=(0.0, 0.0), hole_radius_mm=A)
    ref = second_method(c, o, shape, gs=0.01) * m.keep
    K = DET.gain_dn_per_e
    plateau_e = 0.5 * DET.full_well_e
    bg_e = DET.dark_current_e_per_s * DET.exposure_s
    noise = NoiseModel.from_detector(DET)
    mask = m.hole_coverage == 0
    bound = np.sqrt(np.diag(model_crlb(m, *uvc, K * plateau_e, K * bg_e + DET.offset_dn, noise, mask=mask))[:2])
    glow = m.hole_coverage * plateau_e
    rng = np.random.default_rng(7)
    Hd, Wd = AC.resolution_px[1], AC.resolution_px[0]
    err, mom = [], []
    for _ in range(60):
        def draw(mu):
            return np.round(K * (rng.poisson(mu) + rng.normal(0.0, DET.read_noise_e, mu.shape)) + DET.offset_dn)
        spot, hole = draw(plateau_e * ref + bg_e + glow), draw(bg_e + glow)
        diff = np.zeros((Hd, Wd))
        diff[o[1]:o[1] + shape[0], o[0]:o[0] + shape[1]] = spot - hole
        sc, _ = masked_screen_centroid(diff, H, 0.1)
        start = plane_to_uv(H, sc)
        f = fit_spot_model(spot, m, noise, *start, mask=mask)
        assert f.ok and f.chi2_dof < 1.1
        err.append([f.u, f.v] - uvc)
        mom.append(sc - c)
    err, mom = np.array(err), np.array(mom)
    ratio = np.sqrt(np.mean(err**2, axis=0)) / bound
    assert np.all(ratio < 1.15), ratio
    loss = (A / R) ** 2
    assert np.mean(mom, axis=0) == pytest.approx(c * loss / (1 - loss), rel=0.15)
