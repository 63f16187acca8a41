"""Many sun spots in one Mitsuba launch (rigsim.render.cube_mirror.sun_batch): each tile is the
per-frame renderer's window, to Monte-Carlo noise, and its centroid is the exact disk image's."""

import math

import numpy as np
import pytest

from rigsim.optics.sun_disk import spot_truth, window_centroid
from rigsim.render.cube_mirror.sun_batch import SunSpotBatch, spot_tile_px, tile_groups, tile_px_for
from rigsim.render.cube_mirror.sun_sensor import SunSensorScene
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.realization import realization_from_rig

RIG = load_rig("sun_sensor_2axis_diaphragm")
POSES_DEG = [(0.0, 0.0), (35.0, -20.0), (-60.0, 0.0), (0.0, 60.0), (45.0, 40.0), (-50.0, -40.0), (10.0, 5.0)]


@pytest.fixture(scope="module")
def rendered():
    sc = SunSensorScene(RIG, realization_from_rig(RIG), spp=1024)
    S = np.array([sc.sun_dir_cam({"X": math.radians(x), "Y": math.radians(y)}) for x, y in POSES_DEG])
    c, ok = sc.camera.project_valid(S)
    assert ok.all() and sc.camera.on_detector(c, margin_px=3.0).all()
    tile = tile_px_for(sc.camera, S, sc.full_angle_rad)
    origins = np.floor(c + 0.5).astype(int) - tile // 2
    batch = SunSpotBatch(sc.renderer, tile, 4)  # two launches: 4 tiles, then 3 (+1 idle)
    return sc, S, origins, tile, batch, batch.render(S, origins, seed=5)


@pytest.mark.render
def test_tiles_hold_the_exact_disk_image(rendered):
    """First moment of each tile vs the pixel-binned quadrature truth: ≤ 0.01 px per spot and
    ≤ 0.004 px rms, the per-frame renderer's own tolerances at 1024 spp (test_render_sunspot)."""
    sc, S, origins, tile, batch, tiles = rendered
    assert tiles.shape == (len(S), tile, tile) and batch.n_tiles == 4
    errs = []
    for s, o, img in zip(S, origins, tiles):
        assert img[0].sum() == img[-1].sum() == img[:, 0].sum() == img[:, -1].sum() == 0.0  # the spot fits
        t = spot_truth(sc.camera, s, sc.full_angle_rad, n=400_000)
        errs.append(window_centroid(img, o) - np.array(t["pixel_centroid_uv"]))
        # flux: spot_photons × <cos θ> (the flux response), to the ldsampler's noise
        assert img.sum() == pytest.approx(sc.spot_photons * t["relative_flux"], rel=2e-3)
    errs = np.array(errs)
    assert np.abs(errs).max() <= 0.01, errs
    assert np.sqrt(np.mean(errs**2)) <= 0.004


@pytest.mark.render
def test_tiles_hold_a_disk_of_the_rig_files_32_arcmin(rendered):
    """The size and shape of every tile's spot against the image derived from the rig file's numbers alone
    (tests/render/sun_image_truth.py: the file's 32′, OpenCV's projection, an independent quadrature): a
    disk 1 % wider (1.6 % in variance on axis) fails; 1024 spp hold the moments to 0.3 %."""
    from sun_image_truth import assert_same_disk, binned_disk_image, rig_file_sun

    sc, S, origins, tile, _, tiles = rendered
    sun = rig_file_sun("sun_sensor_2axis_diaphragm")
    for s, o, img in zip(S, origins, tiles):
        assert_same_disk(img, binned_disk_image(sun, s, o, img.shape))


@pytest.mark.render
def test_a_tile_is_the_per_frame_window(rendered):
    """The same pixels as SunSpotRenderer's window around the same spot, to the sampler's noise:
    only the random numbers differ."""
    sc, S, origins, tile, _, tiles = rendered
    for k in (0, 3, 5):
        win = sc.renderer.render(S[k], seed=9)
        a = sc.renderer.window_px // 2 - tile // 2
        assert tuple(np.asarray(win.origin_uv) + a) == tuple(origins[k])
        ref = win.image[a:a + tile, a:a + tile]
        assert win.image.sum() == pytest.approx(ref.sum(), rel=1e-12)  # nothing outside the tile
        assert np.abs(tiles[k] - ref).max() <= 0.01 * ref.max()
        np.testing.assert_allclose(window_centroid(tiles[k], origins[k]), win.centroid(), atol=0.006)


@pytest.mark.render
def test_batch_is_reproducible_and_seeded(rendered):
    _, S, origins, _, batch, tiles = rendered
    again = batch.render(S, origins, seed=5)
    np.testing.assert_allclose(again, tiles, rtol=1e-6, atol=1e-6 * tiles.max())  # thread order: ~1e-7
    other = batch.render(S, origins, seed=6)
    assert np.abs(other - tiles).max() > 1e-4 * tiles.max()


def test_tile_size_follows_the_largest_spot():
    cam = RIG.sun_sensor.camera()
    a = math.radians(RIG.sun_simulator.collimation_full_angle_arcmin / 60.0)
    on_axis = tile_px_for(cam, np.array([[0.0, 0.0, 1.0]]), a)
    off = tile_px_for(cam, np.array([[0.0, 0.0, 1.0], [math.sin(1.0), 0.0, math.cos(1.0)]]), a)
    d = 2 * math.tan(a / 2) * cam.fx  # on-axis diameter
    assert on_axis % 2 == 0 and d + 2 <= on_axis <= d + 6
    assert off >= on_axis


def test_tile_groups_render_fewest_pixels():
    sizes = np.array([6] * 47 + [8] * 246 + [10] * 118 + [12] * 94 + [14] * 57 + [16] * 11 + [18])  # the default sweep
    groups = tile_groups(sizes)
    assert [t for t, _ in groups] == [8, 12, 18]
    assert sorted(np.concatenate([i for _, i in groups]).tolist()) == list(range(len(sizes)))
    assert all((sizes[i] <= t).all() for t, i in groups)
    pixels = sum(t * t * len(i) for t, i in groups)
    assert pixels < 0.45 * 18 * 18 * len(sizes)  # one 18-px tile for all: 2.6× more pixels
    (t, i), = tile_groups(np.array([8, 8]))
    assert t == 8 and i.tolist() == [0, 1]


def test_a_spot_outside_the_camera_model_gets_no_tile():
    cam = RIG.sun_sensor.camera()
    a = math.radians(RIG.sun_simulator.collimation_full_angle_arcmin / 60.0)
    sizes = spot_tile_px(cam, np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]), a)
    assert sizes[0] >= 4 and sizes[1] == sizes[2] == 0
    (t, i), = tile_groups(sizes)
    assert t == sizes[0] and i.tolist() == [0]
    assert tile_groups(np.zeros(3, dtype=int)) == []
