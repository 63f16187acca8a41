"""The sun sensor's effects, rendered (rigsim.render.cube_mirror.sun_sensor / sun_batch): each
against its closed form or the exact quadrature, and each test fails with its effect off."""

import math

import numpy as np
import pytest

from rigsim.optics.camera import PinholeBrown
from rigsim.optics.cover_glass import CoverGlass, glass_spots
from rigsim.optics.sun_disk import SIMULATOR_32ARCMIN_RAD as A
from rigsim.optics.sun_disk import spot_truth, window_centroid
from rigsim.optics.sun_radiance import DiskRadiance
from rigsim.render.cube_mirror.sun_batch import SunSpotBatch
from rigsim.render.cube_mirror.sun_sensor import SunSensorScene, SunSpotRenderer
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.realization import realization_from_rig

pytestmark = pytest.mark.render

RIG = load_rig("sun_sensor_2axis_diaphragm")
BIG = PinholeBrown(fx=3000.0, fy=3000.0, cx=1000.0, cy=1000.0, width=2000, height=2000)  # a 28 px sun


def rig_with(*names, **values):
    eff = RIG.effects.only(names)
    for name, upd in values.items():
        eff = eff.model_copy(update={name: getattr(eff, name).model_copy(update=upd)})
    return RIG.model_copy(update={"effects": eff})


def scene_of(rig, spp=1024):
    return SunSensorScene(rig, realization_from_rig(rig), spp=spp)


POSES = [{"X": 0.0, "Y": 0.0}, {"X": math.radians(25.0), "Y": math.radians(-10.0)},
         {"X": math.radians(-45.0), "Y": math.radians(30.0)}, {"X": math.radians(10.0), "Y": math.radians(55.0)}]


# ---- limb darkening --------------------------------------------------------------------------
def test_limb_darkened_profile_is_the_law():
    """Same seed, same sample positions: pixel by pixel, the limb-darkened image over the uniform
    one is D(r) = (1 − u(1 − √(1 − r²)))/(1 − u/3) at the pixel's centre (r in disk radii), to the
    law's curvature over a pixel (< 2e-3 inside r = 0.8); the flux is the same and the centroid on
    axis does not move."""
    u = RIG.effects.limb_darkening.u
    r0 = SunSpotRenderer(BIG, full_angle_rad=A, window_px=40, spp=256)
    r1 = SunSpotRenderer(BIG, full_angle_rad=A, window_px=40, spp=256, radiance=DiskRadiance(u))
    s = np.array([0.0, 0.0, 1.0])
    a, b = r0.render(s, seed=4), r1.render(s, seed=4)
    v, w = np.indices(a.image.shape)
    r = np.hypot(w + a.origin_uv[0] - BIG.cx, v + a.origin_uv[1] - BIG.cy) / (BIG.fx * math.tan(A / 2))
    inside = r < 0.8
    law = (1 - u * (1 - np.sqrt(1 - r[inside] ** 2))) / (1 - u / 3)
    assert np.abs(b.image[inside] / a.image[inside] - law).max() < 2e-3
    assert law.max() - law.min() > 0.2  # the test sees the law: 1.25 at the centre, 1.04 at r = 0.8
    assert b.image.sum() == pytest.approx(a.image.sum(), rel=2e-3)
    assert np.abs(b.centroid() - a.centroid()).max() < 1e-3


@pytest.fixture(scope="module")
def ld_frames():
    s0, s1 = scene_of(RIG), scene_of(rig_with("limb_darkening"))
    return s0, s1, [(s0.render(p, seed=7, noiseless=True), s1.render(p, seed=7, noiseless=True)) for p in POSES]


def test_limb_darkening_moves_the_pixel_centroid_as_the_quadrature(ld_frames):
    """On the rig's 2.5 px spot the continuous centroid does not move (see the optics test), but
    the pixel-binned one does: the limb-darkened disk fills the pixels otherwise. Rendered shift
    (same seed) = exact pixel-binned quadrature shift, to 1.5e-3 px (3× the paired renders' measured
    scatter at 1024 spp, 5e-4 px); the shifts reach 5e-3 px, so the test fails with the effect off."""
    s0, _, frames = ld_frames
    exp, got = [], []
    for f0, f1 in frames:
        w0, w1 = f0.extra["window"], f1.extra["window"]
        s = w0.sun_dir_cam
        t0 = spot_truth(s0.camera, s, s0.full_angle_rad, n=1_000_000)
        t1 = spot_truth(s0.camera, s, s0.full_angle_rad, n=1_000_000, radiance=DiskRadiance(0.6))
        exp.append(np.subtract(t1["pixel_centroid_uv"], t0["pixel_centroid_uv"]))
        got.append(w1.centroid() - w0.centroid())
        eff = f1.truth["effects"]["disk_radiance"]
        assert np.abs(eff["shift_px"]).max() < 2e-4  # the continuous centroid stays (quadrature)
        assert "effects" not in f0.truth
    exp, got = np.array(exp), np.array(got)
    assert np.abs(exp).max() > 3e-3
    assert np.abs(got - exp).max() < 1.5e-3, (got, exp)


# ---- the simulator's non-uniformity ---------------------------------------------------------------
def test_angular_gradient_on_axis_closed_form():
    """A gradient 1 + g r cos φ on the disk, on axis through an undistorted pinhole: the centroid
    moves by f tan(a/2) g/4 along the gradient (the disk's image is the disk scaled)."""
    g, ax = 0.1, np.array([0.6, -0.8, 0.0])
    r0 = SunSpotRenderer(BIG, full_angle_rad=A, window_px=40, spp=256)
    r1 = SunSpotRenderer(BIG, full_angle_rad=A, window_px=40, spp=256, radiance=DiskRadiance(0.0, g))
    s = np.array([0.0, 0.0, 1.0])
    shift = r1.render(s, seed=2, axis=ax).centroid() - r0.render(s, seed=2).centroid()
    assert np.allclose(shift, BIG.fx * math.tan(A / 2) * g / 4 * ax[:2], atol=1e-3)
    with pytest.raises(ValueError, match="axis"):
        r1.render(s, seed=2)


def test_angular_nonuniformity_on_the_rig():
    """The rig's class-A gradient (2 %): per pose, the rendered centroid shift (same seed) is the
    quadrature's, along the gradient turned with the sensor; on axis it is f tan(a/2) g/4."""
    s0, s1 = scene_of(RIG), scene_of(rig_with("simulator_nonuniformity"))
    g = RIG.effects.simulator_nonuniformity.nonuniformity
    shifts = []
    for p in POSES:
        f0, f1 = s0.render(p, seed=3, noiseless=True), s1.render(p, seed=3, noiseless=True)
        w0, w1 = f0.extra["window"], f1.extra["window"]
        ax = s1.gradient_axis_cam(p)
        t0 = spot_truth(s0.camera, w0.sun_dir_cam, s0.full_angle_rad, n=1_000_000)
        t1 = spot_truth(s0.camera, w0.sun_dir_cam, s0.full_angle_rad, n=1_000_000,
                        radiance=DiskRadiance(0.0, g), radiance_axis=ax)
        exp = np.subtract(t1["pixel_centroid_uv"], t0["pixel_centroid_uv"])
        got = w1.centroid() - w0.centroid()
        assert np.abs(got - exp).max() < 5e-4, (p, got, exp)
        assert np.allclose(f1.truth["effects"]["disk_radiance"]["shift_px"],
                           np.subtract(t1["mean_uv"], t0["mean_uv"]), atol=3e-5)
        shifts.append(np.hypot(*np.subtract(t1["mean_uv"], t0["mean_uv"])))
    assert shifts[0] == pytest.approx(s0.camera.fx * math.tan(A / 2) * g / 4, rel=0.02)


def test_batch_draws_the_gradient_with_its_axes():
    """The sweep's tiles (one rotation per tile carrying the gradient's axis) hold the same
    shifted spots as the per-frame renderer, to the sampler's noise."""
    rig = rig_with("simulator_nonuniformity", simulator_nonuniformity={"nonuniformity": 0.3})
    sc = scene_of(rig)
    S = np.array([sc.sun_dir_cam(p) for p in POSES])
    c, _ = sc.camera.project_valid(S)
    origins = np.floor(c + 0.5).astype(int) - 8
    batch = SunSpotBatch(sc.renderer, 16, len(POSES))
    tiles = batch.render(S, origins, seed=1, **sc.batch_inputs(POSES))
    with pytest.raises(ValueError, match="axes"):
        batch.render(S, origins, seed=1)
    for k, p in enumerate(POSES):
        t = spot_truth(sc.camera, S[k], sc.full_angle_rad, n=400_000, radiance=DiskRadiance(0.0, 0.3),
                       radiance_axis=sc.gradient_axis_cam(p))
        u = spot_truth(sc.camera, S[k], sc.full_angle_rad, n=400_000)
        got = window_centroid(tiles[k], origins[k])
        assert np.abs(got - t["pixel_centroid_uv"]).max() < 0.01
        assert np.hypot(*np.subtract(t["mean_uv"], u["mean_uv"])) > 0.08  # the gradient's shift is seen


def test_spatial_nonuniformity_scales_the_spot():
    """kind = "spatial": the pinhole at p (mount frame) sits at R(pose) p across the beam; the spot's
    photons are scaled by 1 + g (p⊥·ĝ)/(aperture/2), computed here from the rig's own frames."""
    rig = rig_with("simulator_nonuniformity", simulator_nonuniformity={"kind": "spatial", "nonuniformity": 0.1,
                                                                       "pinhole_in_mount_mm": [0.0, 0.0, 80.0]})
    s0, s1 = scene_of(RIG, spp=64), scene_of(rig, spp=64)
    real = realization_from_rig(RIG)
    d = real.d_sun_rot / np.linalg.norm(real.d_sun_rot)
    a = np.eye(3)[int(np.argmin(np.abs(d)))]
    a = (a - (a @ d) * d) / np.linalg.norm(a - (a @ d) * d)
    scales = []
    for p in POSES:
        pr = real.turntable.R_rot_from_mount(p) @ np.array([0.0, 0.0, 80.0])
        exp = 1 + 0.1 * (pr @ a) / (rig.sun_simulator.aperture_mm / 2)
        f0, f1 = s0.render(p, seed=5, noiseless=True), s1.render(p, seed=5, noiseless=True)
        w0, w1 = f0.extra["window"], f1.extra["window"]
        assert w1.image.sum() / w0.image.sum() == pytest.approx(exp, rel=1e-12)
        assert np.abs(w1.centroid() - w0.centroid()).max() < 1e-9
        scales.append(exp)
    assert max(scales) - min(scales) > 0.02  # the poses move the pinhole across the gradient


# ---- the cover glass's ghost ----------------------------------------------------------------------
CAM = RIG.sun_sensor.camera()
GLASS = CoverGlass(0.5, 1.458, RIG.sun_sensor.focal_length_mm)


def _dir(deg, az=0.93):
    th = math.radians(deg)
    return np.array([math.sin(th) * math.cos(az), math.sin(th) * math.sin(az), math.cos(th)])


def test_ghost_flux_and_offset():
    """20° off axis the ghost stands apart (offset 2 t tan θ′ ≈ 22 px): its flux over the direct
    spot's is the Fresnel ratio (T_s²R_s² + T_p²R_p²)/(T_s² + T_p²) and its centroid is the
    quadrature's; the direct spot keeps the no-glass pixels times (T_s² + T_p²)/2."""
    s = _dir(20.0)
    r0 = SunSpotRenderer(CAM, full_angle_rad=A, window_px=64, spp=1024)
    r1 = SunSpotRenderer(CAM, full_angle_rad=A, window_px=64, spp=1024, ghost=GLASS)
    w0 = SunSpotBatch(r0, 64, 1).render(s[None], np.array([r0.window_origin_for(CAM.project_valid(s[None])[0][0])]), seed=6)[0]
    w1 = r1.render(s, seed=6)
    t = glass_spots(CAM, GLASS, s, A, n=200_000)
    v, u = np.indices(w1.image.shape)
    u, v = u + w1.origin_uv[0], v + w1.origin_uv[1]
    near_ghost = np.hypot(u - t["ghost_uv"][0], v - t["ghost_uv"][1]) < 6
    ghost, direct = np.where(near_ghost, w1.image, 0.0), np.where(near_ghost, 0.0, w1.image)
    assert ghost.sum() / direct.sum() == pytest.approx(t["ghost_flux"] / t["direct_flux"], rel=0.01)
    assert t["ghost_flux"] / t["direct_flux"] == pytest.approx(GLASS.ghost_ratio(math.radians(20.0)), rel=1e-3)
    assert np.abs(window_centroid(ghost, w1.origin_uv) - t["ghost_uv"]).max() < 0.02
    assert np.hypot(*np.subtract(t["ghost_uv"], t["direct_uv"])) > 15
    assert direct.sum() / w0.sum() == pytest.approx(t["direct_flux"], rel=2e-4)


def test_ghost_over_the_spot_moves_its_centroid():
    """Near the axis the ghost lies on the spot: the centroid moves by the ghost's flux share times
    its offset (quadrature), about a thousandth of a pixel at 2°; rendered = quadrature to 3e-4 px."""
    for deg in (1.5, 3.0):
        s = _dir(deg)
        r0 = SunSpotRenderer(CAM, full_angle_rad=A, window_px=32, spp=1024)
        r1 = SunSpotRenderer(CAM, full_angle_rad=A, window_px=32, spp=1024, ghost=GLASS)
        o = np.array([r0.window_origin_for(CAM.project_valid(s[None])[0][0])])
        w0 = SunSpotBatch(r0, 32, 1).render(s[None], o, seed=8)[0]
        w1 = r1.render(s, seed=8)
        t = glass_spots(CAM, GLASS, s, A, n=400_000)
        exp = np.subtract(t["both_uv"], t["direct_uv"])
        got = w1.centroid() - window_centroid(w0, o[0])
        assert np.hypot(*exp) > 1e-3
        assert np.abs(got - exp).max() < 3e-4, (deg, got, exp)


def test_ghost_in_the_rig_frame_and_the_sweep_tiles():
    """Through the rig: the frame's truth records the ghost (offset, Fresnel ratio), and the
    sweep's batch renders the whole readout window (the ghost lies outside a spot's tight tile)."""
    sc = scene_of(rig_with("cover_glass_ghost"), spp=256)
    f = sc.render(POSES[1], seed=2, noiseless=True)
    g = f.truth["effects"]["cover_glass_ghost"]
    s = f.extra["window"].sun_dir_cam
    assert np.allclose(g["offset_px"], GLASS.offset_px(s, CAM.fx, CAM.fy))
    assert g["ghost_ratio"] == pytest.approx(GLASS.ghost_ratio(CoverGlass.theta(s)))
    batch = SunSpotBatch(sc.renderer, 8, 2)
    assert batch.tile_px == 8 and batch.out_px == sc.renderer.window_px
    c, _ = CAM.project_valid(s[None])
    tiles = batch.render(np.array([s, s]), np.floor(c + 0.5).astype(int).repeat(2, 0) - 4, seed=1)
    W = sc.renderer.window_px
    assert tiles.shape == (2, W, W)
    assert window_centroid(tiles[0], np.floor(c[0] + 0.5).astype(int) - W // 2) == pytest.approx(
        f.extra["window"].centroid(), abs=0.02)


# ---- the thick pinhole's vignetting ------------------------------------------------------------
def test_vignetting_brightness_and_shift():
    """The rig's pinhole (D = 0.1 mm in a 25 µm mask): the spot's flux over the thin pinhole's (same
    seed) is V(θ) = (2/π)(acos k − k√(1 − k²)), k = t tan θ / D, to 2e-4 (0.50 at 58°); the centroid
    moves towards the axis as the exact pixel-binned quadrature, to 5e-5 px (0.0095 px at 58°)."""
    from rigsim.optics.pinhole import ThickPinhole

    v = RIG.effects.vignetting
    ph = ThickPinhole(v.pinhole_diameter_mm, v.mask_thickness_mm)
    r0 = SunSpotRenderer(CAM, full_angle_rad=A, window_px=32, spp=1024)
    r1 = SunSpotRenderer(CAM, full_angle_rad=A, window_px=32, spp=1024, pinhole=ph)
    shifts = []
    for deg in (30.0, 50.0, 58.0):
        s = _dir(deg, az=0.64)
        o = np.array([r0.window_origin_for(CAM.project_valid(s[None])[0][0])])
        w0 = SunSpotBatch(r0, 32, 1).render(s[None], o, seed=3)[0]
        w1 = r1.render(s, seed=3)
        assert w1.image.sum() / w0.sum() == pytest.approx(float(ph.throughput(math.radians(deg))), rel=2e-4)
        t0 = spot_truth(CAM, s, A, n=1_000_000)
        t1 = spot_truth(CAM, s, A, n=1_000_000, direction_weight=ph.direction_weight)
        exp = np.subtract(t1["pixel_centroid_uv"], t0["pixel_centroid_uv"])
        got = w1.centroid() - window_centroid(w0, o[0])
        assert np.abs(got - exp).max() < 5e-5, (deg, got, exp)
        shifts.append(np.hypot(*exp))
    assert shifts[-1] > 5e-3


def test_vignetting_through_the_rig_and_the_sweep():
    """Through the rig: the sidecar records the throughput and the shift; the sweep's tiles carry
    the same fall-off as the per-frame window."""
    sc0, sc = scene_of(RIG, spp=256), scene_of(rig_with("vignetting"), spp=256)
    p = POSES[3]
    f0, f = sc0.render(p, seed=2, noiseless=True), sc.render(p, seed=2, noiseless=True)
    v = f.truth["effects"]["vignetting"]
    ratio = f.extra["window"].image.sum() / f0.extra["window"].image.sum()
    assert ratio == pytest.approx(v["throughput"], rel=2e-3) and v["throughput"] < 0.6
    S = np.array([sc.sun_dir_cam(q) for q in POSES])
    c, _ = CAM.project_valid(S)
    tiles = SunSpotBatch(sc.renderer, 12, len(POSES)).render(S, np.floor(c + 0.5).astype(int) - 6, seed=4)
    ideal = SunSpotBatch(sc0.renderer, 12, len(POSES)).render(S, np.floor(c + 0.5).astype(int) - 6, seed=4)
    assert tiles[3].sum() == pytest.approx(f.extra["window"].image.sum(), rel=3e-3)
    for k, s in enumerate(S):  # every tile of a launch, not only the first
        assert tiles[k].sum() / ideal[k].sum() == pytest.approx(
            sc.renderer.effects_truth(s, 400_000)["vignetting"]["throughput"], rel=2e-3)
