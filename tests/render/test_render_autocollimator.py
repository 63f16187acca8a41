"""Seed-001 autocollimator rendered by Mitsuba against the exact numpy model.

Acceptance (issue 3 §5): with a noise-free detector and enough spp, the rendered spot's centroid
matches the exact reflection through the objective (rigsim.optics.autocollimator: Snell trace,
pixel-binned over the same window) to ≤ 0.02 px, for tilts across the measuring range.
Also: no recompiles after the warm-up, the window maps exactly onto detector pixels, radiometry,
the scene dict uses built-in plugins only and survives an XML round trip, bad geometry becomes
warnings and sidecar flags, frames are reproducible from their seed.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from rigsim.errors import GeometryWarning
from rigsim.frames import ARCSEC_PER_RAD
from rigsim.render.backend import ensure_variant
from rigsim.render.cube_mirror.autocollimator import AutocollimatorRenderer, build_autocollimator_scene_dict
from rigsim.render.frame import read_frame
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.realization import realization_from_rig

ensure_variant()
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

RIG = load_rig("sun_sensor_3axis_autocollimator")
REAL = realization_from_rig(RIG)
ARCMIN = math.radians(1.0 / 60.0)
SPP = 576   # stratified (24²): ~0.6M light paths per frame; measured 0.0035 px rms, 0.0077 px at most over the
            # four tilts below × 3 seeds (1024 spp: 0.0029 / 0.0047 px; 256 spp: 0.006 / 0.012 px, too near TOL_PX)
TOL_PX = 0.02
LOW_SPP = 256  # for tests that check bookkeeping, not accuracy


def _pose(ref, dy_arcmin=0.0, dx_arcmin=0.0):
    """Outer axis Y' by ``dy`` (spot moves along u), middle axis X' by ``dx`` (along v)."""
    p = dict(ref)
    p["Y"] += dy_arcmin * ARCMIN
    p["X"] += dx_arcmin * ARCMIN
    return p


@pytest.fixture(scope="module")
def face_renderer(tmp_path_factory):
    r = AutocollimatorRenderer(RIG, REAL, "face", spp=SPP, sampler="stratified",
                               mesh_dir=tmp_path_factory.mktemp("meshes"))
    r.warm_up()
    return r


def _check(r, pose, seed, allowed=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore" if allowed else "error", GeometryWarning)
        w = r.render_window(pose, seed=seed)
    tr = w.truth
    assert w.rendered and not any(v for k, v in w.flags.items() if k not in allowed), w.flags
    # like with like: Mitsuba's ray-optics window against the pixel-binned exact trace
    err = w.centroid_geometric() - tr.pixel_centroid_uv
    # the diffraction blur (a centrosymmetric kernel) moves neither the centroid nor the flux ...
    u0, v0 = w.origin_uv
    h, wd = w.image.shape
    if u0 >= 0 and v0 >= 0 and u0 + wd <= r.optics.width and v0 + h <= r.optics.height:
        np.testing.assert_allclose(w.centroid(), w.centroid_geometric(), atol=1e-6)
        assert w.image.sum() == pytest.approx(w.image_geometric.sum(), rel=1e-9)
    else:
        # ... unless its faint tail crosses the detector's edge, where the light is lost (at 7.8′
        # along v the spot is 42 px from the edge; its kernel reaches 16 + 39 px: 1.6e-5 of the
        # flux is lost, the centroid moves 0.0007 px): the move is at most the lost fraction times
        # the lever, the window's size
        lost = 1.0 - w.image.sum() / w.image_geometric.sum()
        assert 0.0 <= lost < 1e-4, lost
        assert np.max(np.abs(w.centroid() - w.centroid_geometric())) <= lost * max(h, wd) + 1e-6
    return w, err


# tilts across the measuring range (±10.6′ along u, ±8.5′ along v for this detector)
@pytest.mark.parametrize("dy,dx", [(0.0, 0.0), (7.5, 0.0), (-3.0, 6.0), (-9.0, -7.0)])
def test_spot_matches_exact_trace(face_renderer, dy, dx):
    r = face_renderer
    pose = _pose(r.layout.reference_pose_rad, dy, dx)
    w, err = _check(r, pose, seed=11)
    assert np.max(np.abs(err)) <= TOL_PX, err
    # the spot is where the exact model says, far from where the paraxial model says
    if abs(dy) > 5:
        assert abs(w.truth.paraxial_uv[0] - w.truth.mean_uv[0]) > 0.2
    # radiometry: photons in the window = the traced flux (4 Fresnel transmissions, face clip)
    assert w.image.sum() == pytest.approx(w.truth.flux_photons, rel=0.01)
    # the reading implied by the rendered centroid is within a few 0.01″ of the truth's
    rd = (r.optics.reading(w.centroid()) - r.optics.reading(w.truth.mean_uv)) * ARCSEC_PER_RAD
    assert np.max(np.abs(rd)) < 0.05


def test_plane_mirror_step_a(tmp_path):
    r = AutocollimatorRenderer(RIG, REAL, "plane_mirror", spp=SPP, sampler="stratified", mesh_dir=tmp_path)
    ref = r.layout.reference_pose_rad
    for dy, dx in ((0.0, 0.0), (2.0, -1.5)):
        # the 50 mm mirror is as wide as the beam: beyond ~40″ the return beam walks off the stop
        w, err = _check(r, _pose(ref, dy, dx), seed=5, allowed=("return_vignetted",))
        assert np.max(np.abs(err)) <= TOL_PX, err
        assert w.flags["return_vignetted"] == (dy != 0.0)
    # step A: at the all-zero reading pose the plane mirror reads zero
    tr = r.truth(ref)
    np.testing.assert_allclose(r.optics.reading(tr.mean_uv) * ARCSEC_PER_RAD, 0.0, atol=0.005)


def test_pose_updates_do_not_recompile(face_renderer):
    r = face_renderer
    ref = r.layout.reference_pose_rad
    dr.kernel_history_clear()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for k, (dy, dx) in enumerate(((1.0, 2.0), (-4.0, 0.5))):
            r.render_window(_pose(ref, dy, dx), seed=20 + k)
        hist = [h for h in dr.kernel_history() if h["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert hist, "no kernels launched?"
    fresh = [h for h in hist if not h.get("cache_hit")]
    assert not fresh, f"{len(fresh)} of {len(hist)} kernels compiled after the warm-up"


def test_window_maps_exactly_onto_detector_pixels(face_renderer):
    """The same spot rendered through windows at different origins lands on the same detector
    pixels: the per-pixel images agree to Monte-Carlo noise and so do the centroids."""
    r = face_renderer
    pose = _pose(r.layout.reference_pose_rad, 2.0, -3.0)
    tr = r.truth(pose)
    a = r.render_window(pose, seed=31)
    r_origin = a.origin_geometric
    # shift the window by (+3, -2) px (camera moved, film untouched)
    b = r.render_window(pose, seed=32, window_origin=(r_origin[0] + 3, r_origin[1] - 2))
    assert b.origin_geometric == (r_origin[0] + 3, r_origin[1] - 2)
    img = b.image_geometric
    W = r.window_px
    big = np.zeros((W + 4, W + 4))
    big[2:2 + W, 0:W] += a.image_geometric      # origin (u0, v0) at big[2, 0]
    other = np.zeros_like(big)
    other[0:W, 3:3 + W] += img                  # origin (u0 + 3, v0 - 2)
    core = (slice(2, W), slice(3, W))           # pixels inside both windows
    peak = a.image_geometric.max()
    np.testing.assert_allclose(big[core], other[core], atol=0.06 * peak)
    exact = r.optics.binned_image(tr.bundle, (r_origin[0], r_origin[1], W, W))
    np.testing.assert_allclose(a.image_geometric, exact, atol=0.06 * peak)
    np.testing.assert_allclose(b.centroid_geometric(), a.centroid_geometric(), atol=0.015)


def test_scene_dict_is_builtin_millimetres_and_exports_to_xml(tmp_path):
    d = build_autocollimator_scene_dict(RIG, REAL, _pose_ref(), "face", spp=64, mesh_dir=tmp_path)
    types = set()

    def walk(x):
        if isinstance(x, dict):
            if "type" in x:
                types.add(x["type"])
            for v in x.values():
                walk(v)
    walk(d)
    assert not any(t.startswith("rigsim") for t in types), types
    assert {"ptracer", "perspective", "spot", "dielectric", "conductor", "shapegroup", "instance"} <= types
    # millimetres, origin at the objective: the mirror sits distance_mm + 2.5 mm away
    M = np.array(d["mirror"]["to_world"].matrix)
    assert M[2, 3] == pytest.approx(RIG.autocollimator.distance_mm + 2.5, abs=1e-3)
    # XML export (what `rigsim scene export` does) renders identically, also through the CLI
    xml = tmp_path / "ac.xml"
    mi.parser.write_file(mi.parser.parse_dict(mi.parser.ParserConfig(mi.variant()), d), str(xml))
    a = np.array(mi.render(mi.load_dict(d), seed=3))
    b = np.array(mi.render(mi.load_file(str(xml)), seed=3))
    assert a.sum() > 0
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5 * a.max())


def _pose_ref():
    from rigsim.truth.cube_mirror.autocollimator import autocollimator_layout
    return autocollimator_layout(RIG, REAL, "face").reference_pose_rad


def test_frame_sidecar_and_reproducibility(face_renderer, tmp_path):
    r = face_renderer
    pose = _pose(r.layout.reference_pose_rad, -2.0, 1.0)
    f1 = r.render_frame(pose, seed=7, spp=LOW_SPP)
    f2 = r.render_frame(pose, seed=7, spp=LOW_SPP)
    assert f1.dn.shape == (RIG.autocollimator.resolution_px[1], RIG.autocollimator.resolution_px[0])
    assert f1.dn.dtype == np.uint16
    # same seed -> same photon image up to float32 summation order (ptracer splats with atomic
    # adds: ~1e-7 relative); the detector model then gives the same DN for the same photons.
    # (Not bit-identical DN frames: numpy's Poisson draws a value-dependent number of uniforms, so a
    # 1e-7 change in one pixel reshuffles the noise of the following pixels -- reported upstream.)
    np.testing.assert_allclose(f1.photons, f2.photons, rtol=1e-5, atol=1e-6 * f1.photons.max())
    from rigsim.detector import apply_detector
    cfg = RIG.autocollimator.detector
    np.testing.assert_array_equal(apply_detector(f1.photons, cfg, seed=7).dn, f1.dn)
    png, js = r.write(tmp_path / "ac_0001", f1)
    dn, side = read_frame(tmp_path / "ac_0001")
    np.testing.assert_array_equal(dn, f1.dn)
    t = side["truth"]
    for k in ("spot_mean_uv", "spot_pixel_centroid_uv", "true_tilt_arcsec", "reading_arcsec", "paraxial_uv",
              "layout", "reference_uv"):
        assert k in t, k
    assert side["seed"] == 7 and side["render"]["spp"] == LOW_SPP and side["render"]["variant"] == r.variant
    assert side["pose"]["true_rad"]["X"] == pytest.approx(pose["X"])
    assert side["flags"]["saturated"] is False and side["flags"]["spot_cut_by_edge"] is False
    # the instrument's reading of the true spot: its calibration (full-aperture flat mirror) is
    # ~0.1 % off for a 25 mm face (spherical aberration weights the pupil differently): a scale
    # error, zero at null, ~0.1″ at 2′ — recorded in the sidecar, not hidden
    tt = np.array(t["true_tilt_arcsec"])
    err = np.array(t["reading_arcsec"]) - tt
    np.testing.assert_allclose(t["reading_error_arcsec"], err, atol=1e-9)
    assert np.all(np.abs(err) < 2e-3 * np.abs(tt) + 0.01) and np.max(np.abs(err)) > 0.01
    # the frame's spot is where the truth says (noisy detector: ~0.02 px)
    win = f1.extra["window"]
    u0, v0 = win.origin_uv
    h, w = win.image.shape
    sub = f1.detector.dn[v0:v0 + h, u0:u0 + w].astype(float) - RIG.autocollimator.detector.offset_dn
    v, u = np.indices(sub.shape)
    c = np.array([(sub * u).sum(), (sub * v).sum()]) / sub.sum() + [u0, v0]
    np.testing.assert_allclose(c, t["spot_pixel_centroid_uv"], atol=0.2)


def test_saturation_is_flagged(face_renderer):
    r = face_renderer
    with pytest.warns(GeometryWarning, match="saturated"):
        f = r.render_frame(r.layout.reference_pose_rad, seed=3, noiseless=True, source_photons=1e9, spp=LOW_SPP)
    assert f.sidecar["flags"]["saturated"] is True and f.sidecar["flags"]["saturated_pixels"] > 0
    ok = r.render_frame(r.layout.reference_pose_rad, seed=3, noiseless=True, spp=LOW_SPP)
    assert ok.sidecar["flags"]["saturated"] is False
    # default brightness: peak at 20-90 % of the ADC range
    peak = ok.detector.expected_dn.max() / RIG.autocollimator.detector.max_dn
    assert 0.2 < peak < 0.9


def test_beam_missing_the_face_is_flagged(face_renderer):
    r = face_renderer
    pose = _pose(r.layout.reference_pose_rad, 0.0, 0.0)
    pose["Z"] += math.radians(90.0)  # inner axis a quarter turn: the face looks sideways
    with pytest.warns(GeometryWarning, match="misses the mirror"):
        f = r.render_frame(pose, seed=1, noiseless=True)
    fl = f.sidecar["flags"]
    assert fl["beam_misses_face"] and fl["spot_off_detector"] and not f.extra["window"].rendered
    assert f.photons.sum() == 0.0
    # a large tilt instead: the face is hit but the return beam misses the objective
    pose = _pose(r.layout.reference_pose_rad, 0.0, 0.0)
    pose["X"] += math.radians(8.0)
    with pytest.warns(GeometryWarning) as rec:
        w = r.render_window(pose, seed=1)
    msgs = " | ".join(str(x.message) for x in rec)
    assert "misses the objective" in msgs and "off the detector" in msgs, msgs
    assert w.flags["return_vignetted"] and w.flags["spot_off_detector"] and not w.flags["beam_misses_face"]


def test_spot_out_of_range_is_flagged(face_renderer):
    r = face_renderer
    ref = r.layout.reference_pose_rad
    half = r.optics.measuring_range_rad()[0]
    with pytest.warns(GeometryWarning, match="off the detector"):
        w = r.render_window(_pose(ref, 1.3 * half / ARCMIN, 0.0), seed=1, spp=LOW_SPP)
    assert w.flags["spot_off_detector"] and not w.rendered
    # spot centre 2 px inside the +u edge: cut by the edge, rendered, flagged
    t = r.optics.reading(np.array([r.optics.width - 2.5, r.optics.cy]))
    pose = dict(ref)
    pose["Y"] += t[0]
    with pytest.warns(GeometryWarning, match="cut by the detector edge"):
        w = r.render_window(pose, seed=2, spp=LOW_SPP)
    assert w.flags["spot_cut_by_edge"] and w.rendered
    # nothing beyond the edge is rendered: window columns past u = W - 1 are exactly zero
    for img, org in ((w.image_geometric, w.origin_geometric), (w.image, w.origin_uv)):
        beyond = np.arange(img.shape[1]) + org[0] > r.optics.width - 1
        assert beyond.any() and np.all(img[:, beyond] == 0.0) and img.sum() > 0
    assert w.image_geometric.sum() == pytest.approx(w.truth.flux_on_detector, rel=0.03)
    assert w.image.sum() < w.image_geometric.sum()  # the diffraction halo beyond the edge is lost too


def test_bad_arguments_rejected():
    with pytest.raises(ValueError, match="spp"):
        build_autocollimator_scene_dict(RIG, REAL, _pose_ref(), spp=0)
    with pytest.raises(ValueError, match="target"):
        build_autocollimator_scene_dict(RIG, REAL, _pose_ref(), "prism", spp=16)
    with pytest.raises(ValueError, match="perfect square"):
        AutocollimatorRenderer(RIG, REAL, spp=1000, sampler="stratified")


# ------------------------------------------------------------------------------ slow (CI: -m slow)
SWEEP = [(0.0, 0.0), (0.2, -0.1), (1.5, 1.0), (4.0, -2.0), (-6.0, 5.0), (9.5, 0.0), (-9.5, 0.0), (0.0, 7.8),
         (0.0, -7.8), (7.0, 6.5), (-7.0, -6.5), (8.0, -6.0)]


@pytest.mark.slow
@pytest.mark.parametrize("face", ["+Z", "+Y"])
def test_fidelity_sweep_both_faces(tmp_path, face):
    """12 tilts over the whole measuring range (corners included), 4096 spp, both measured faces."""
    r = AutocollimatorRenderer(RIG, REAL, "face", face, spp=4096, sampler="stratified", mesh_dir=tmp_path)
    errs = []
    for k, (dy, dx) in enumerate(SWEEP):
        w, err = _check(r, _pose(r.layout.reference_pose_rad, dy, dx), seed=1000 + k)
        errs.append(err)
    errs = np.array(errs)
    assert np.max(np.abs(errs)) <= TOL_PX / 2, errs
    assert np.sqrt(np.mean(np.sum(errs ** 2, axis=1))) <= 0.005, errs


@pytest.mark.slow
def test_ghosts_do_not_move_the_spot(tmp_path):
    """With Fresnel reflections kept (uncoated lens) the ghosts stay out of the spot's window."""
    r = AutocollimatorRenderer(RIG, REAL, "face", spp=4096, sampler="stratified", lens_ghosts=True,
                               mesh_dir=tmp_path)
    for k, (dy, dx) in enumerate([(0.0, 0.0), (0.3, 0.2), (-9.0, 0.0)]):
        w, err = _check(r, _pose(r.layout.reference_pose_rad, dy, dx), seed=2000 + k)
        assert np.max(np.abs(err)) <= TOL_PX, err


@pytest.mark.slow
def test_exported_xml_renders_with_the_mitsuba_command(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    d = build_autocollimator_scene_dict(RIG, REAL, _pose_ref(), "face", spp=256, mesh_dir=tmp_path)
    xml = tmp_path / "ac.xml"
    mi.parser.write_file(mi.parser.parse_dict(mi.parser.ParserConfig(mi.variant()), d), str(xml))
    exe = Path(sys.executable).with_name("mitsuba")
    out = tmp_path / "ac.exr"
    res = subprocess.run([str(exe), "-m", mi.variant(), "-o", str(out), str(xml)], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    cli = np.array(mi.Bitmap(str(out)), dtype=np.float64)
    cli = cli[..., 0] if cli.ndim == 3 else cli
    ref = np.array(mi.render(mi.load_dict(d), seed=0), dtype=np.float64)[..., 0]
    assert np.all(np.isfinite(cli)) and cli.sum() > 0
    # different sample streams: compare the images' totals and centroids
    assert cli.sum() == pytest.approx(ref.sum(), rel=0.02)
    v, u = np.indices(cli.shape)
    cc = np.array([(cli * u).sum(), (cli * v).sum()]) / cli.sum()
    cr = np.array([(ref * u).sum(), (ref * v).sum()]) / ref.sum()
    np.testing.assert_allclose(cc, cr, atol=0.03)
