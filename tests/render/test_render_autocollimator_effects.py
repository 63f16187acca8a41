"""The autocollimator's [effects] rendered (docs/effects-autocollimator.md): the projected reticle,
the cube face's reflectance, the objective's ghosts. Each test fails with its effect off."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from rigsim.errors import GeometryWarning
from rigsim.imaging.reticle import measure_reticle
from rigsim.imaging.spot import measure_spot
from rigsim.render.backend import ensure_variant
from rigsim.render.cube_mirror.autocollimator import AutocollimatorRenderer, autocollimator_scene, fresnel_normal
from rigsim.rig import load_rig

ensure_variant()

RIG = load_rig("sun_sensor_3axis_autocollimator")
ARCMIN = math.radians(1.0 / 60.0)
ROI = 59  # autocollimator_roi_px(RIG, "face")


def _with(names, **updates):
    fx = RIG.effects.only(names)
    for name, upd in updates.items():
        fx = fx.model_copy(update={name: getattr(fx, name).model_copy(update=upd)})
    return RIG.model_copy(update={"effects": fx})


def _pose(ref, dy_arcmin=0.0, dx_arcmin=0.0):
    p = dict(ref)
    p["Y"] += dy_arcmin * ARCMIN
    p["X"] += dx_arcmin * ARCMIN
    return p


# ------------------------------------------------------------------------------ reticle
def test_reticle_image_centre_and_shape(tmp_path):
    """The rendered cross-hair: its centre (two line fits on the DN frame) is the exact model's
    image of the reticle centre (≈ 2·f·tilt from the axis), its shape the nominal drawing, point-
    inverted, at magnification 1."""
    rig = _with(["reticle"])
    # independent sampler: the stratified one at 256 spp correlates the line choice with the
    # position on it (a 0.08 px bias of the image centroid, gone at 1024 spp)
    r = AutocollimatorRenderer(rig, None, "face", spp=256, sampler="independent", mesh_dir=tmp_path)
    assert r.window_px > 100  # the window holds the 94 px cross
    d = r.effects.reticle
    for k, (dy, dx) in enumerate([(3.0, -2.0), (-6.0, 4.0)]):
        with warnings.catch_warnings():
            warnings.simplefilter("error", GeometryWarning)
            fr = r.render_frame(_pose(r.layout.reference_pose_rad, dy, dx), seed=20 + k, noiseless=True)
        w = fr.extra["window"]
        tr = w.truth
        # closed form: the reticle centre's image moves by f·tan(2·tilt) (paraxial, ≤ 0.3 px off
        # the exact trace at 6′)
        assert np.max(np.abs(tr.mean_uv - tr.paraxial_uv)) < 0.5
        sm = measure_spot(fr.dn, RIG.autocollimator.detector, roi_px=ROI)
        rm = measure_reticle(fr.dn, sm, ROI)
        assert rm is not None and rm.ok, "the frame shows no reticle"
        # Monte-Carlo scatter of the rendered line centres at 256 independent spp: ~0.03 px
        assert np.max(np.abs(rm.uv - tr.mean_uv)) < 0.1, rm.uv - tr.mean_uv
        # shape: Mitsuba's ray-optics image against the nominal drawing convolved with the exact
        # model's (numpy trace) geometric image of one reticle point (the singlet's spherical
        # aberration spreads each point over ~10 px), point-inverted, magnification 1
        pred = _drawing_through_optics(r, d, tr)
        u0, v0 = w.origin_geometric
        h, wd = w.image_geometric.shape
        g = w.image_geometric
        P = pred(u0, v0, wd, h)
        assert g.sum() == pytest.approx(P.sum(), rel=0.01)
        # Monte-Carlo noise ~5 % per lit pixel at 256 spp: L1 distance ~4 %; a point source, an
        # unblurred drawing or a shifted one are > 50 % away
        assert np.abs(g - P).sum() / P.sum() < 0.08


def _drawing_through_optics(r, d, tr):
    """The nominal drawing ⊗ the exact model's pixel-binned image of the reticle centre (photons):
    a function of the window (u0, v0, w, h)."""
    from scipy.signal import fftconvolve

    spot = r.optics.binned_image(tr.bundle, tr.window)
    spot = spot / spot.sum()
    K = 2 * math.ceil(d.half_extent_mm / r.optics.pitch_mm) + 5
    frac = d.image_fraction((K // 2, K // 2), r.optics.pitch_mm, (0, 0, K, K))
    level = tr.flux_photons * r.optics.pitch_mm ** 2 / d.areas.sum()
    conv = fftconvolve(spot, frac, mode="full") * level
    su, sv = tr.window[0] - K // 2, tr.window[1] - K // 2  # detector pixel of conv[0, 0]

    def window(u0, v0, w, h):
        out = np.zeros((h, w))
        a0, b0 = max(u0, su), max(v0, sv)
        a1, b1 = min(u0 + w, su + conv.shape[1]), min(v0 + h, sv + conv.shape[0])
        out[b0 - v0:b1 - v0, a0 - u0:a1 - u0] = conv[b0 - sv:b1 - sv, a0 - su:a1 - su]
        return out

    return window


def test_reticle_off_is_a_spot(tmp_path):
    r = AutocollimatorRenderer(RIG, None, "face", spp=64, mesh_dir=tmp_path)
    assert r.effects.reticle is None and r.window_px == 32
    fr = r.render_frame(r.layout.reference_pose_rad, seed=1, noiseless=True)
    sm = measure_spot(fr.dn, RIG.autocollimator.detector, roi_px=ROI)
    assert sm.ok and measure_reticle(fr.dn, sm, ROI) is None


# ------------------------------------------------------------------------------ face reflectance
def test_face_reflectance_fresnel_and_coating(tmp_path):
    """Uncoated N-BK7 cube: the front face returns R = ((n−1)/(n+1))², the opposite face
    (parallel) T²·R more onto the same spot; a coated face returns its reflectance."""
    ideal = AutocollimatorRenderer(RIG, None, "face", spp=256, mesh_dir=tmp_path)
    pose = _pose(ideal.layout.reference_pose_rad, 0.4, -0.3)
    w0 = ideal.render_window(pose, seed=5)
    unc = AutocollimatorRenderer(_with(["face_reflectance"]), None, "face", spp=256, mesh_dir=tmp_path)
    assert unc.source_photons == ideal.source_photons  # the lamp is set as for a perfect face
    w1 = unc.render_window(pose, seed=5)
    R = fresnel_normal(RIG.effects.face_reflectance.glass_index)
    assert R == pytest.approx(0.0422, abs=5e-5)
    expected = R + (1.0 - R) ** 2 * R
    # Monte-Carlo: ~1e5 returned paths (stratified), < 0.5 %
    assert w1.image.sum() / w0.image.sum() == pytest.approx(expected, rel=0.01)
    # the two returns coincide (parallel faces): the spot does not move
    # (Mitsuba picks reflection or transmission by the Fresnel weight: 1/12 of the paths return,
    # ~0.03 px Monte-Carlo σ of the centroid at 256 spp)
    assert np.max(np.abs(w1.centroid() - w0.centroid())) < 0.1
    coated = AutocollimatorRenderer(_with(["face_reflectance"], face_reflectance={"coating": "protected_al"}),
                                    None, "face", spp=256, mesh_dir=tmp_path)
    w2 = coated.render_window(pose, seed=5)
    # same paths, each weighted by the reflectance
    assert w2.image.sum() / w0.image.sum() == pytest.approx(0.90, rel=1e-5)
    # the plane mirror of step A is not the cube: unchanged
    pm = AutocollimatorRenderer(_with(["face_reflectance"]), None, "plane_mirror", spp=64, mesh_dir=tmp_path)
    assert pm.effects.face_bsdf is None


# ------------------------------------------------------------------------------ ghosts
def _fixed_ghost_photons(rig, tmp_path, spp):
    """Photons the objective's Fresnel reflections put on the detector
    with no mirror in the scene (the fixed ghosts), rendered."""
    import mitsuba as mi

    r = AutocollimatorRenderer(rig, None, "face", spp=16, mesh_dir=tmp_path)
    o = r.optics
    sc = autocollimator_scene(rig, None, r.layout.reference_pose_rad, "face", spp=spp, mesh_dir=tmp_path,
                              window_px=1280, window_origin=(0, -128), optics=o, layout=r.layout,
                              source_photons=r.source_photons, sampler="independent")
    d = dict(sc.scene_dict)
    del d["mirror"], d["mirror_group"]
    img = np.asarray(mi.render(mi.load_dict(d), spp=spp, seed=3))
    return float(img.sum()) * sc.photons_per_unit, r


def test_fixed_ghosts_match_paraxial_trace(tmp_path):
    """The two fixed ghosts (source → flat surface → detector; source → flat → convex surface from
    inside → flat → detector) against the paraxial trace: a point source of intensity I gives on
    the axis E = I·Π(reflectances, transmittances)/B², B the ABCD system's B element from the
    reticle to the detector plane; both ghosts are far wider than the detector (uniform over it)."""
    rig = _with(["ghosts"])
    got, r = _fixed_ghost_photons(rig, tmp_path, spp=4)
    o, ob = r.optics, r.optics.objective
    n, Rc, t = ob.n, ob.radius_mm, ob.z_vertex - ob.z_flat
    D = ob.z_flat - o.z_source
    back = o.z_source - o.z_detector  # the detector lies 5 µm behind the reticle
    Rs = RIG.effects.ghosts.surface_reflectance

    def P(d, nn):
        return np.array([[1.0, d / nn], [0.0, 1.0]])

    mirror_in_glass = np.array([[1.0, 0.0], [-2.0 * n / Rc, 1.0]])  # the convex face seen from inside: concave
    B_convex = (P(D + back, 1) @ P(t, n) @ mirror_in_glass @ P(t, n) @ P(D, 1))[0, 1]
    B_flat = 2.0 * D + back
    omega = 2.0 * math.pi * (1.0 - math.cos(o.cone_half_angle_rad))
    intensity = r.source_photons / omega
    area = o.width * o.height * o.pitch_mm ** 2  # the window covers the whole detector
    T = 1.0 - Rs
    expected = intensity * area * (Rs / B_flat ** 2 + T * T * Rs / B_convex ** 2)
    # ~1250 ghost paths reach the detector at 4 spp: 2.8 % Monte-Carlo σ, the bound 2.5σ (measured +3.5 %; at 8 spp,
    # ~2500 paths, +1.0 %: 4 spp saves 5 s)
    assert got == pytest.approx(expected, rel=0.07), (got, expected)


def test_no_ghost_light_without_the_effect(tmp_path):
    got, _ = _fixed_ghost_photons(RIG, tmp_path, spp=1)
    assert got == 0.0


# ------------------------------------------------------------------------------ all off
def test_disabled_effects_leave_the_scene_unchanged(tmp_path):
    """Effects configured but switched off build exactly the ideal scene."""
    fx = RIG.effects.model_copy(update={
        "reticle": RIG.effects.reticle.model_copy(update={"pattern": "cross_ring", "line_width_um": 30.0}),
        "face_reflectance": RIG.effects.face_reflectance.model_copy(update={"coating": "enhanced_al"}),
        "ghosts": RIG.effects.ghosts.model_copy(update={"surface_reflectance": 0.01}),
        "beam_splitter": RIG.effects.beam_splitter.model_copy(update={"thickness_mm": 3.0})})
    assert fx.enabled == ()
    a = AutocollimatorRenderer(RIG, None, "face", spp=16, mesh_dir=tmp_path)
    b = AutocollimatorRenderer(RIG.model_copy(update={"effects": fx}), None, "face", spp=16, mesh_dir=tmp_path)
    assert repr(a.scene_info.scene_dict) == repr(b.scene_info.scene_dict)
    assert a.window_px == b.window_px and a.source_photons == b.source_photons
    fa = a.render_frame(a.layout.reference_pose_rad, seed=4)
    fb = b.render_frame(b.layout.reference_pose_rad, seed=4)
    assert np.array_equal(fa.dn, fb.dn)
    assert "effects" not in fa.sidecar["truth"]


def test_a_live_reticle_emitter_leaves_other_scenes_renders_unchanged(tmp_path):
    """Mitsuba's vcalls over emitters trace every live emitter instance of the process, the Python
    reticle included: a sun-sensor frame (a path tracer asking every emitter for pdf_direction) must
    render, and render the same pixels, while a reticle renderer is alive."""
    from rigsim.render.cube_mirror.sun_sensor import SunSensorScene

    pose = {"X": 0.2, "Y": -0.1}
    before = SunSensorScene(RIG, spp=16).render(pose, seed=3, truth_points=2000).dn
    r = AutocollimatorRenderer(_with(["reticle"]), None, "face", spp=16, mesh_dir=tmp_path)
    fr = r.render_frame(r.layout.reference_pose_rad, seed=1, noiseless=True)
    assert fr.dn.max() > RIG.autocollimator.detector.offset_dn + 100  # the reticle is there
    during = SunSensorScene(RIG, spp=16).render(pose, seed=3, truth_points=2000).dn
    np.testing.assert_array_equal(during, before)
    del r
