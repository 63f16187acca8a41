"""Sun-spot fidelity: the rendered window centroid against an independent exact computation.

Truth here is computed with OpenCV only (cv2.projectPoints over a polar quadrature of the disk,
flux weight cos(theta) per solid angle, each point binned into its pixel), independently of
rigsim's numpy camera model and of its sunflower quadrature. The renderer is compared with the
*pixel-binned* truth -- the first moment a perfect renderer's window would have. The projection
of the disk centre differs from it by the disk-average bias (distortion curvature over the
disk) plus the pixel-sampling bias of a first moment over a sharp-edged spot; both are measured
here and reported.
"""

from __future__ import annotations

import functools
import math
import warnings

import cv2
import numpy as np
import pytest

from rigsim.errors import GeometryWarning
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.sun_disk import SIMULATOR_32ARCMIN_RAD, SUN_FULL_ANGLE_RAD, spot_truth, window_centroid
from rigsim.render.cube_mirror.sun_sensor import SunSpotRenderer

WIDE = PinholeBrown(fx=500.0, fy=502.0, cx=515.3, cy=508.7, width=1024, height=1024,
                     k1=-0.15, k2=0.012, k3=-0.0003, p1=3e-4, p2=-2e-4)
NARROW = PinholeBrown(fx=1000.0, fy=1001.5, cx=511.5, cy=511.5, width=1024, height=1024,
                       k1=-0.05, k2=0.01, k3=0.0, p1=1e-4, p2=5e-5)
REQUIREMENT_PX = 0.01


def _dir(theta_deg, az_deg):
    t, a = math.radians(theta_deg), math.radians(az_deg)
    return np.array([math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), math.cos(t)])


def cv2_truth(cam: PinholeBrown, s, full_angle, n_rings=700, n_az=1400):
    """Independent truth: polar midpoint quadrature of the cone, projected with OpenCV. Each (camera, direction)
    is computed once per module (a million projected points, ~1 s): the window and tight cases share it."""
    return _cv2_truth(cam, tuple(float(x) for x in s), float(full_angle), n_rings, n_az)


@functools.lru_cache(maxsize=None)
def _cv2_truth(cam: PinholeBrown, s, full_angle, n_rings, n_az):
    s = np.asarray(s) / np.linalg.norm(s)
    helper = np.array([0.0, 1.0, 0.0]) if abs(s[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(helper, s)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(s, e1)
    c_max = 1.0 - math.cos(full_angle / 2)
    t = (np.arange(n_rings) + 0.5) / n_rings * c_max          # 1 - cos(phi), equal solid angle
    cos_phi = 1.0 - t
    sin_phi = np.sqrt(1.0 - cos_phi ** 2)
    psi = (np.arange(n_az) + 0.5) / n_az * 2 * math.pi
    cp, az = np.meshgrid(cos_phi, psi, indexing="ij")
    sp, _ = np.meshgrid(sin_phi, psi, indexing="ij")
    cp, sp, az = cp.ravel(), sp.ravel(), az.ravel()
    d = (cp[:, None] * s + (sp * np.cos(az))[:, None] * e1 + (sp * np.sin(az))[:, None] * e2)
    uv, _ = cv2.projectPoints(d.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.camera_matrix(),
                              cam.dist_coeffs())
    uv = uv.reshape(-1, 2)
    w = d[:, 2]
    centre, _ = cv2.projectPoints(s.reshape(1, 1, 3), np.zeros(3), np.zeros(3), cam.camera_matrix(),
                                  cam.dist_coeffs())
    return {
        "centre": centre.reshape(2),
        "mean": (w[:, None] * uv).sum(0) / w.sum(),
        "pixel": (w[:, None] * np.floor(uv + 0.5)).sum(0) / w.sum(),
        "rel_flux": w.mean(),
    }


@pytest.fixture(scope="module")
def wide_sun():
    return SunSpotRenderer(WIDE, full_angle_rad=SUN_FULL_ANGLE_RAD, window_px=32, spp=1024,
                           spot_photons=1e6)


FIELD = [(0, 0), (15, 30), (30, 120), (45, 0), (45, 200), (52, 300),
         (60, 45), (60, 135), (60, 225), (60, 315)]


@pytest.mark.parametrize("tight", [False, True], ids=["window", "tight"])
def test_sun_spot_centroid_matches_exact_projection_across_field(wide_sun, tight):
    errs, centre_dev = [], []
    for k, (th, az) in enumerate(FIELD):
        s = _dir(th, az)
        win = wide_sun.render(s, seed=k, tight=tight)
        assert not any(win.flags[f] for f in ("spot_off_detector", "spot_cut_by_edge",
                                              "spot_exceeds_window", "spot_outside_model"))
        truth = cv2_truth(WIDE, s, SUN_FULL_ANGLE_RAD)
        c = win.centroid()
        errs.append(c - truth["pixel"])
        centre_dev.append(c - truth["centre"])
        # photometry: total photons = spot_photons * <cos theta> over the disk
        assert win.image.sum() == pytest.approx(1e6 * truth["rel_flux"], rel=2e-3)
    errs = np.array(errs)
    assert np.max(np.abs(errs)) <= REQUIREMENT_PX, errs
    # measured: ~0.001 px rms at 1024 spp (ldsampler); 4x margin
    assert np.sqrt(np.mean(errs ** 2)) <= 0.004, errs
    # against the centre's projection the deviation is the (known) bias, a few 0.001 px here
    assert np.max(np.abs(centre_dev)) < 0.02


@pytest.mark.parametrize("cam,field", [
    (NARROW, [(0, 0), (10, 60), (20, 250), (25, 45)]),
], ids=["narrow"])
@pytest.mark.parametrize("tight", [False, True], ids=["window", "tight"])
def test_simulator_32arcmin_spot_narrow_camera(cam, field, tight):
    r = SunSpotRenderer(cam, full_angle_rad=SIMULATOR_32ARCMIN_RAD, window_px=32, spp=1024)
    for k, (th, az) in enumerate(field):
        s = _dir(th, az)
        c = r.render(s, seed=100 + k, tight=tight).centroid()
        truth = cv2_truth(cam, s, SIMULATOR_32ARCMIN_RAD)
        assert np.max(np.abs(c - truth["pixel"])) <= REQUIREMENT_PX


def test_numpy_truth_agrees_with_cv2_truth():
    for th, az in [(0, 0), (40, 70), (60, 225)]:
        s = _dir(th, az)
        mine = spot_truth(WIDE, s, SUN_FULL_ANGLE_RAD, n=1_000_000)
        ref = cv2_truth(WIDE, s, SUN_FULL_ANGLE_RAD)
        np.testing.assert_allclose(mine["center_uv"], ref["centre"], atol=1e-9)
        np.testing.assert_allclose(mine["mean_uv"], ref["mean"], atol=2e-5)
        # binning of two different quadratures: agree to ~1e-4 px
        np.testing.assert_allclose(mine["pixel_centroid_uv"], ref["pixel"], atol=5e-4)


def test_disk_bias_matches_second_order_theory():
    """mean - centre = (rho^2/8) * Laplacian of the projection  +  (rho^2/4) J grad(ln w).

    Independent check of the quadrature: derivatives by central differences of cv2.projectPoints
    in the tangent plane of the sun direction.
    """
    rho = SUN_FULL_ANGLE_RAD / 2
    for th, az in [(30, 20), (55, 45), (60, 315)]:
        s = _dir(th, az)
        helper = np.array([0.0, 1.0, 0.0])
        e1 = np.cross(helper, s); e1 /= np.linalg.norm(e1)
        e2 = np.cross(s, e1)
        h = 2e-3

        def proj(a, b):
            d = s + a * e1 + b * e2
            d /= np.linalg.norm(d)
            uv, _ = cv2.projectPoints(d.reshape(1, 1, 3), np.zeros(3), np.zeros(3),
                                      WIDE.camera_matrix(), WIDE.dist_coeffs())
            return uv.reshape(2), d[2]

        p0, w0 = proj(0, 0)
        pa, wa = proj(h, 0); pA, wA = proj(-h, 0)
        pb, wb = proj(0, h); pB, wB = proj(0, -h)
        lap = (pa + pA + pb + pB - 4 * p0) / h ** 2
        J = np.stack([(pa - pA) / (2 * h), (pb - pB) / (2 * h)], axis=1)
        glw = np.array([(np.log(wa) - np.log(wA)) / (2 * h), (np.log(wb) - np.log(wB)) / (2 * h)])
        # gnomonic tangent-plane coords stretch the disk slightly; second order is enough here
        pred = rho ** 2 / 8 * lap + rho ** 2 / 4 * J @ glw
        got = np.array(spot_truth(WIDE, s, SUN_FULL_ANGLE_RAD, n=1_000_000)["disk_bias_px"])
        np.testing.assert_allclose(got, pred, atol=3e-4 + 0.05 * np.max(np.abs(pred)))


def test_window_maps_exactly_to_full_frame():
    """A whole-detector Mitsuba render and the composited window agree pixel by pixel."""
    cam = PinholeBrown(fx=180.0, fy=181.0, cx=95.2, cy=70.6, width=192, height=144,
                        k1=-0.1, k2=0.01, p1=2e-4, p2=-1e-4)
    r = SunSpotRenderer(cam, full_angle_rad=math.radians(2.0), window_px=16, spp=1024)
    s = _dir(25, 140)
    frame, win = r.render_frame(s, seed=3)
    full = r.render_full(s, seed=4, spp=256)
    assert frame.shape == full.shape == (144, 192)
    u0, v0 = win.origin_uv
    assert frame[v0:v0 + 16, u0:u0 + 16].sum() == pytest.approx(frame.sum())
    np.testing.assert_allclose(full.sum(), frame.sum(), rtol=5e-3)
    # same pixels lit, same values to MC noise (edge pixels at 256 spp: ~1/sqrt(256) of a pixel)
    assert np.max(np.abs(full - frame)) < 0.1 * frame.max()
    c_full = np.array([(full * np.arange(192)[None, :]).sum(), (full * np.arange(144)[:, None]).sum()])
    c_full /= full.sum()
    np.testing.assert_allclose(c_full, win.centroid(), atol=5e-3)


def test_pose_updates_do_not_recompile(wide_sun):
    import drjit as dr

    wide_sun.render(_dir(10, 10), seed=0)            # warm-up (compiles or loads from cache)
    dr.kernel_history_clear()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for k, (th, az) in enumerate([(20, 30), (40, 200), (55, 315)]):
            wide_sun.render(_dir(th, az), seed=50 + k)
        hist = [h for h in dr.kernel_history() if h["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert hist, "expected kernel launches"
    fresh = [h for h in hist if not h.get("cache_hit")]
    assert not fresh, f"{len(fresh)} kernels were compiled after warm-up"


def test_same_seed_same_window(wide_sun):
    s = _dir(33, 77)
    a = wide_sun.render(s, seed=9).image
    b = wide_sun.render(s, seed=9).image
    c = wide_sun.render(s, seed=10).image
    np.testing.assert_array_equal(a, b)
    assert np.any(a != c)


def test_tight_render_is_the_window_with_fewer_paths(wide_sun):
    """``tight=True`` renders only the spot's tile at the same spp per pixel: the same window (origin,
    flags, pixels) to the sampler's noise, exactly 0 outside the tile, where the window is 0 too."""
    from rigsim.render.cube_mirror.sun_batch import spot_tile_px

    for k, (th, az) in enumerate([(0, 0), (30, 120), (52, 300), (60, 45)]):
        s = _dir(th, az)
        ref, got = wide_sun.render(s, seed=20 + k), wide_sun.render(s, seed=40 + k, tight=True)
        assert got.origin_uv == ref.origin_uv and got.flags == ref.flags and got.image.shape == ref.image.shape
        t = int(spot_tile_px(WIDE, s[None], SUN_FULL_ANGLE_RAD)[0])
        a = 16 - t // 2
        assert 4 <= t < 32 and ref.image.sum() == pytest.approx(ref.image[a:a + t, a:a + t].sum(), rel=1e-12)
        assert got.settings["tile_px"] == t and "tile_px" not in ref.settings
        outside = np.ones((32, 32), bool)
        outside[a:a + t, a:a + t] = False
        assert np.all(got.image[outside] == 0.0) and np.all(ref.image[outside] == 0.0)
        assert np.abs(got.image - ref.image).max() <= 0.01 * ref.image.max()  # as a sweep tile (test_render_sun_batch)
        assert got.image.sum() == pytest.approx(ref.image.sum(), rel=2e-3)
        np.testing.assert_allclose(got.centroid(), ref.centroid(), atol=0.006)


def test_tight_render_of_a_spot_overflowing_the_window_is_the_window():
    r = SunSpotRenderer(NARROW, full_angle_rad=math.radians(2.0), window_px=38, spp=16)
    s = _dir(25, 45)
    with pytest.warns(GeometryWarning, match="does not fit"):
        a = r.render(s, seed=3)
    with pytest.warns(GeometryWarning, match="does not fit"):
        b = r.render(s, seed=3, tight=True)
    assert a.flags["spot_exceeds_window"] and b.flags == a.flags
    np.testing.assert_array_equal(a.image, b.image)


def test_tight_render_statistics_over_seeds(wide_sun):
    """The tight tile's pixels have the window's expectation: over 16 seeds each, the per-pixel means
    agree within 4 standard errors (from the two samples' own scatter) and the mean centroids to 1e-3 px."""
    s = _dir(40, 70)
    full = np.array([wide_sun.render(s, seed=1000 + k).image for k in range(16)])
    tight = np.array([wide_sun.render(s, seed=2000 + k, tight=True).image for k in range(16)])
    lit = full.mean(0) > 0
    se = np.sqrt((full.var(0, ddof=1) + tight.var(0, ddof=1)) / 16)[lit]
    diff = np.abs(full.mean(0) - tight.mean(0))[lit]
    assert np.all(diff <= 4 * se + 1e-9 * full.max())
    c_full = np.mean([window_centroid(im) for im in full], axis=0)
    c_tight = np.mean([window_centroid(im) for im in tight], axis=0)
    np.testing.assert_allclose(c_tight, c_full, atol=1e-3)


def test_off_detector_and_edge_cut_are_flagged(wide_sun):
    with pytest.warns(GeometryWarning, match="off the detector|outside"):
        w = wide_sun.render(_dir(60, 0), seed=0)    # 60 deg along +x lands at u ~ 1078 > 1023
    assert w.flags["spot_off_detector"] and w.image.sum() == 0
    with pytest.warns(GeometryWarning, match="outside the camera model"):
        w = wide_sun.render(_dir(70, 45), seed=0)   # beyond the lens model's fold (64.7 deg)
    assert w.flags["spot_outside_model"]
    with pytest.warns(GeometryWarning, match="behind|outside"):
        w = wide_sun.render(_dir(120, 0), seed=0)
    assert w.flags["spot_off_detector"]
    # find a direction whose spot straddles the right edge (u = 1023.5)
    s = None
    for th in np.linspace(45, 60, 301):
        uv, _ = WIDE.project_valid(_dir(th, 0)[None])
        if abs(uv[0, 0] - 1023.5) < 0.3:
            s = _dir(th, 0)
            break
    assert s is not None
    with pytest.warns(GeometryWarning, match="cut by the detector edge"):
        w = wide_sun.render(s, seed=0)
    assert w.flags["spot_cut_by_edge"] and not w.flags["spot_off_detector"]
    u0 = w.origin_uv[0]
    off = np.arange(32) + u0 > 1023
    assert off.any() and np.all(w.image[:, off] == 0.0)   # pixels beyond the detector get nothing
    assert w.image.sum() > 0
    with pytest.warns(GeometryWarning, match="cut by the detector edge"):
        wt = wide_sun.render(s, seed=1, tight=True)
    assert wt.flags == w.flags and wt.origin_uv == w.origin_uv and np.all(wt.image[:, off] == 0.0)
    assert wt.image.sum() == pytest.approx(w.image.sum(), rel=2e-3)


def test_window_too_small_is_rejected_or_flagged():
    with pytest.raises(ValueError, match="window_px"):
        SunSpotRenderer(NARROW, full_angle_rad=math.radians(2.0), window_px=16)


@pytest.mark.slow
def test_sun_spot_dense_field_sweep(wide_sun):
    """80 seeded random directions over the whole usable field of the wide lens.

    Skipped by default; runs with ``-m slow`` or ``RIGSIM_SLOW=1`` (tests/conftest.py).
    """
    rng = np.random.default_rng(2024)
    errs = []
    while len(errs) < 80:
        th, az = math.degrees(math.acos(rng.uniform(math.cos(math.radians(62)), 1.0))), \
            rng.uniform(0, 360)
        s = _dir(th, az)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", GeometryWarning)
            win = wide_sun.render(s, seed=len(errs))
        if any(win.flags[f] for f in ("spot_off_detector", "spot_cut_by_edge",
                                      "spot_exceeds_window", "spot_outside_model")):
            continue
        errs.append(win.centroid() - cv2_truth(WIDE, s, SUN_FULL_ANGLE_RAD, 400, 800)["pixel"])
    errs = np.array(errs)
    assert np.max(np.abs(errs)) <= REQUIREMENT_PX
    assert np.sqrt(np.mean(errs ** 2)) <= 0.004


def test_ldsampler_spp_must_be_power_of_four():
    with pytest.raises(ValueError, match="power of 4"):
        SunSpotRenderer(NARROW, spp=512)
