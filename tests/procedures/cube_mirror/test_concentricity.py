"""Seed 000 concentricity search: estimator, operator model, feedback loop, divergent-spot frames."""

import math
import warnings

import numpy as np
import pytest

from rigsim.errors import SearchError
from rigsim.estimation.null_search import numerical_jacobian, offset_model
from rigsim.imaging.screen import hole_spot_offset
from rigsim.procedures.cube_mirror.concentricity import OffsetMeasurer, concentricity_search, null_bias_offset_px
from rigsim.rig import load_rig
from rigsim.rig.turntable import pose_deg_to_rad
from rigsim.truth.cube_mirror.realization import realization_from_rig

RIG = load_rig("sun_sensor_2axis_diaphragm")
REAL = realization_from_rig(RIG)
PX_MM = RIG.aiming_camera.object_pixel_mm


def _exact_jacobian(face_index, reading):
    m = OffsetMeasurer(RIG, REAL, face_index)

    def f(r):
        true = {k: v - REAL.encoder_bias_rad.get(k, 0.0) for k, v in r.items()}
        return m.exact_px(true)

    return numerical_jacobian(f, reading, ["X", "Y"])


@pytest.mark.parametrize("face_index", [0, 1])
def test_operator_model_jacobian_matches_the_true_rig(face_index):
    """The feedback gain comes from nominal geometry only; it must agree with the true rig's
    response (exact trace) to within the geometry's small errors (≪ 1 %)."""
    start = pose_deg_to_rad(RIG.procedure.search_start[face_index])
    Jm = numerical_jacobian(offset_model(RIG, start), start, ["X", "Y"])
    Jt = _exact_jacobian(face_index, start)
    # px per rad: a 1″ face tilt moves the spot 2·650 mm·4.85e-6 = 6.3 µm = 0.42 px
    assert np.max(np.abs(Jm)) == pytest.approx(2 * 650.0 / PX_MM, rel=0.02)
    np.testing.assert_allclose(Jm, Jt, atol=2e-3 * np.max(np.abs(Jt)))


@pytest.mark.parametrize("face_index", [0, 1])
def test_surrogate_search_stops_inside_the_threshold(face_index):
    """Noise-free measurements: the loop stops at the first reading whose offset is below 1 px;
    with 0.001° commands (≈1.5 px of offset per step) it always finds one within 15 frames."""
    rng = np.random.default_rng(3)
    for trial in range(20):
        m = OffsetMeasurer(RIG, REAL, face_index, sigma_px=0.0, rng=rng)
        q = math.radians(RIG.procedure.command_resolution_deg)
        jitter = {a: rng.uniform(-q / 2, q / 2) for a in ("X", "Y")}
        res = concentricity_search(RIG, REAL, face_index, m, {"X": 0.0, "Y": 0.0}, start_offset_rad=jitter)
        assert res.converged, res.message
        assert len(res.steps) <= 6
        final = res.steps[-1]
        assert np.all(np.abs(final.measured) < 1.0)
        # what the operator sees is the exact offset minus the mounting bias (σ3's equivalent)
        np.testing.assert_allclose(final.measured, final.true - m.bias_px, atol=1e-9)
        # every command is a whole number of 0.001° steps from the start
        for s in res.steps:
            for a in ("X", "Y"):
                k = (s.reading_deg[a] - res.steps[0].reading_deg[a]) / RIG.procedure.command_resolution_deg
                assert abs(k - round(k)) < 1e-6


def test_bias_offset_is_twice_the_tilt_times_the_lever_arm():
    b = null_bias_offset_px(RIG, REAL, 0)
    tilt = np.asarray(RIG.aiming_camera.mounting_bias_arcsec[:2]) * math.pi / 180 / 3600
    assert np.linalg.norm(b) * PX_MM == pytest.approx(2 * 650.0 * np.linalg.norm(tilt), rel=1e-3)


def test_unreachable_start_is_reported_not_guessed():
    rig = RIG.model_copy(update={"procedure": RIG.procedure.model_copy(
        update={"search_start_deg": [{"X": 150.0, "Y": 0.0}, {"X": 91.4, "Y": -0.07}]})})
    m = OffsetMeasurer(rig, REAL, 0)
    with pytest.raises(SearchError, match=r"face \+Z"):
        concentricity_search(rig, REAL, 0, m, {"X": 0.0, "Y": 0.0})


# ---------------------------------------------------------------- estimator on analytic frames

def _analytic_frames(renderer, offset_mm):
    """Exact images (no Mitsuba): the divergent spot = disk ⊛ divergence − hole, plus the glow."""
    from rigsim.truth.cube_mirror.diaphragm import rasterise_screen_disk

    g = renderer.geometry
    pencil = rasterise_screen_disk(g, offset_mm, g.hole_radius_mm, value=1.0)
    spot = renderer.diverge(pencil) * renderer._gain * 1000.0
    hole = rasterise_screen_disk(g, (0.0, 0.0), g.hole_radius_mm, value=1000.0)
    return hole, spot


@pytest.fixture(scope="module")
def conc_renderer():
    from rigsim.render.cube_mirror.aiming import ConcentricityRenderer

    return ConcentricityRenderer(RIG, REAL, 0)


@pytest.mark.render
def test_offset_estimator_is_unbiased_at_the_null_and_scaled_off_it(conc_renderer):
    """At concentricity the estimator reads 0 (to 0.02 px); off the null it reads the offset
    scaled by the light lost into the hole (a few %: harmless for a null search)."""
    for off_px in ([0.0, 0.0], [0.5, -0.3], [20.0, 0.0], [0.0, -30.0]):
        off_mm = np.asarray(off_px) * PX_MM
        hole, spot = _analytic_frames(conc_renderer, off_mm)
        r = hole_spot_offset(hole, spot + hole, conc_renderer.geometry.H_screen_to_uv,
                             object_pixel_mm=PX_MM, offset_dn=0.0)
        err = r["offset_px"] - np.asarray(off_px)
        assert np.all(np.abs(err) <= 0.02 + 0.06 * np.abs(off_px)), (off_px, r["offset_px"])


@pytest.mark.render
def test_rendered_divergent_spot_matches_the_exact_image(conc_renderer):
    """Mitsuba pencil + convolution vs the exact pencil through the same convolution: the spot
    centre agrees to ≤ 0.02 px (0.3 µm on the screen) at the null and 40″ off it."""
    from rigsim.imaging.screen import masked_screen_centroid

    null = conc_renderer.geometry.layout.null_pose_rad
    for dx, dy, seed in ((0.0, 0.0, 1), (40.0, -25.0, 2)):
        pose = dict(null)
        pose["X"] += math.radians(dx / 3600)
        pose["Y"] += math.radians(dy / 3600)
        tr = conc_renderer.truth(pose)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rendered = conc_renderer.spot_photons(pose, seed)
        _, exact = _analytic_frames(conc_renderer, tr.offset_mm)
        c_r, _ = masked_screen_centroid(rendered, conc_renderer.geometry, 0.1)
        c_e, _ = masked_screen_centroid(exact, conc_renderer.geometry, 0.1)
        assert np.all(np.abs(c_r - c_e) / PX_MM < 0.02), (dx, dy, (c_r - c_e) * 1e3)
        # the plateau is the requested brightness (half the full well, in photons)
        assert np.percentile(rendered, 99.5) == pytest.approx(conc_renderer.spot_photons_per_px, rel=0.05)


@pytest.mark.render
def test_binned_pencil_film_gives_the_full_resolution_spot(conc_renderer):
    """The pencil is traced onto a film of 4 × 4 camera pixels per pixel: the exact pencil image
    averaged over those blocks, through the same convolution, has the full-resolution image's spot
    centre to ≤ 0.005 px (measured 0.003 px, 0.05 µm: the 60 µm film pixel under the ~6 mm
    divergence disk) and its plateau to 2e-4; no pixel moves by 0.3 % of the plateau."""
    from rigsim.imaging.screen import masked_screen_centroid
    from rigsim.truth.cube_mirror.diaphragm import rasterise_screen_disk

    g = conc_renderer.geometry
    b = conc_renderer.pencil.spot_film_binning
    assert b == 4
    for off_px in ([0.0, 0.0], [13.3, -21.7]):
        pencil = rasterise_screen_disk(g, np.asarray(off_px) * PX_MM, g.hole_radius_mm, value=1.0)
        binned = pencil.reshape(pencil.shape[0] // b, b, pencil.shape[1] // b, b).mean(axis=(1, 3))
        full, coarse = conc_renderer.diverge(pencil), conc_renderer.diverge(binned, b)
        c_f, _ = masked_screen_centroid(full, g, 0.1)
        c_c, _ = masked_screen_centroid(coarse, g, 0.1)
        assert np.all(np.abs(c_c - c_f) / PX_MM < 0.005), (c_c - c_f) * 1e3
        top = np.percentile(full, 99.5)
        assert np.percentile(coarse, 99.5) == pytest.approx(top, rel=2e-4)
        assert np.max(np.abs(coarse - full)) < 0.003 * top


@pytest.mark.render
def test_rendered_search_converges_on_the_default_rig(conc_renderer):
    """Rendered frames with detector noise: face +Z nulls below 1 px from Table 1's first row, and the
    exact residual offset is what the operator's threshold and bias allow."""
    m = OffsetMeasurer(RIG, REAL, 0, renderer=conc_renderer, seed=11)
    res = concentricity_search(RIG, REAL, 0, m, {"X": 0.0, "Y": 0.0})
    assert res.converged, res.message
    assert 2 <= len(res.steps) <= 6
    last = res.steps[-1]
    assert np.all(np.abs(last.measured) < 1.0)
    # measured = exact − bias + image error; the image error near the null is ≲ 0.1 px
    assert np.all(np.abs(last.measured - (last.true - m.bias_px)) < 0.1)
    # the first frame is ~33 px off, as Table 1's first row is tens of px off
    assert 10 < np.max(np.abs(res.steps[0].true)) < 60


def test_the_operator_homography_is_the_nominal_one():
    """The measurer maps the image onto the screen with the homography of the nominal aiming-camera
    spec; the rendered scene's camera (placed at the true hole) has the same one to 1e-12."""
    from rigsim.optics.aiming import nominal_screen_homography
    from rigsim.truth.cube_mirror.diaphragm import diaphragm_geometry

    for fi in (0, 1):
        g = diaphragm_geometry(RIG, REAL, fi)
        np.testing.assert_allclose(nominal_screen_homography(RIG.aiming_camera), g.H_screen_to_uv, rtol=1e-12,
                                   atol=1e-12)
    tilted = RIG.aiming_camera.model_copy(update={"view_angle_deg": 40.0})
    assert not np.allclose(nominal_screen_homography(tilted), g.H_screen_to_uv, rtol=1e-6)


# The aiming camera with 1/16 of the pixels over the same field (400 × 300 px of 60 µm, as the file chain's): the
# pencil's sample chunks depend on the spp and the film binning only (chunk_count(spp·b²)), so the worker tests below
# split the same chunks between the processes for ~1/13 of the render.
COARSE = RIG.model_copy(update={"aiming_camera": RIG.aiming_camera.model_copy(
    update={"resolution_px": [400, 300], "pixel_pitch_um": 60.0})})
COARSE_REAL = realization_from_rig(COARSE)


@pytest.mark.render
def test_aiming_frames_are_bit_identical_for_one_and_two_workers():
    """The pencil's fixed sample chunks, rendered in this process alone or with a worker process
    (and with Dr.Jit at 1 or 2 threads), give the same uint16 frames for the same seed (the coarse camera)."""
    import drjit as dr

    from rigsim.render.cube_mirror.aiming import ConcentricityRenderer
    from rigsim.truth.cube_mirror.diaphragm import diaphragm_geometry

    pose = dict(diaphragm_geometry(COARSE, COARSE_REAL, 0).layout.null_pose_rad)
    pose["X"] += math.radians(-60.0 / 3600)
    frames = {}
    prev = dr.thread_count()
    try:
        for workers, threads in ((1, 1), (2, 2), (1, 2)):
            dr.set_thread_count(threads)
            r = ConcentricityRenderer(COARSE, COARSE_REAL, 0, workers=workers)
            assert r.workers == workers
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                frames[workers, threads] = [r.render(pose, seed=s) for s in (3, 4)]
            r.close()
    finally:
        dr.set_thread_count(prev)
    ref = frames[1, 1]
    for key, frs in frames.items():
        for a, b in zip(ref, frs, strict=True):
            assert np.array_equal(a.spot_photons, b.spot_photons), key
            assert np.array_equal(a.hole.dn, b.hole.dn) and np.array_equal(a.spot.dn, b.spot.dn), key
    # different seeds do differ (the chunks are not all one stream)
    assert not np.array_equal(ref[0].spot_photons, ref[1].spot_photons)


def test_a_dead_aiming_worker_leaves_the_frame_unchanged():
    """The worker process is killed before a frame: the renderer warns once, renders that chunk itself and
    returns the frame one process gives for the seed (the coarse camera)."""
    from rigsim.render.cube_mirror.aiming import ConcentricityRenderer
    from rigsim.truth.cube_mirror.diaphragm import diaphragm_geometry

    pose = dict(diaphragm_geometry(COARSE, COARSE_REAL, 0).layout.null_pose_rad)
    pose["X"] += math.radians(-60.0 / 3600)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = ConcentricityRenderer(COARSE, COARSE_REAL, 0, workers=1).render(pose, seed=3)
    r = ConcentricityRenderer(COARSE, COARSE_REAL, 0, workers=2)
    r.render(pose, seed=9)  # the worker is up
    for proc in list(r._chunks._pool._processes.values()):
        proc.kill()
        proc.join()
    with pytest.warns(RuntimeWarning, match="worker process failed"):
        got = r.render(pose, seed=3)
    assert r._chunks._pool is None
    assert np.array_equal(ref.spot_photons, got.spot_photons) and np.array_equal(ref.spot.dn, got.spot.dn)


@pytest.mark.render
def test_the_pencil_film_binning_divides_any_camera():
    """The binned pencil film must tile the camera: 4×4 where it divides both sides, else 2×2 or none
    (a 732 × 562 camera, as a random rig drew, takes 2×2), and its frame renders with the spot."""
    from rigsim.render.cube_mirror.aiming import ConcentricityRenderer
    from rigsim.truth.cube_mirror.diaphragm import diaphragm_geometry

    cam = RIG.aiming_camera.model_copy(update={"resolution_px": [732, 562]})
    rig = RIG.model_copy(update={"aiming_camera": cam})
    real = realization_from_rig(rig)
    with pytest.raises(ValueError, match="must divide"):
        ConcentricityRenderer(rig, real, 0, spp=1, film_binning=4)
    r = ConcentricityRenderer(rig, real, 0, spp=1)
    try:
        assert r.pencil.spot_film_binning == 2
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fr = r.render(dict(diaphragm_geometry(rig, real, 0).layout.null_pose_rad), seed=1)
        assert fr.spot.dn.shape == (562, 732) and fr.spot_photons.sum() > 0
        assert fr.spot.dn.sum(dtype=float) > fr.hole.dn.sum(dtype=float)             # the spot is on the screen
    finally:
        r.close()
