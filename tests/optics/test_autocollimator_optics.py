"""The autocollimator's exact numpy model (rigsim.optics.autocollimator) against closed forms.

* Snell/Fresnel primitives: Snell's law, unit length, normal-incidence reflectance;
* the objective: paraxial back focal distance f − t/n of a plano-convex lens, found by tracing a
  thin collimated pencil;
* the whole instrument, small tilt t: spot offset = f·tan(2t)/pitch through a small aperture
  (paraxial), and through the full 50 mm aperture it is *not* (spherical aberration + focus);
* the reading: the calibrated reading and the inversion of the exact model recover the tilt to
  far below the instrument's 0.1″;
* the rig layout: the face at its null pose and the plane mirror at the zero pose read zero, and
  turntable rotations about X' and Y' move the reading with the right sign;
* bad geometry flags from the trace.
"""

import math

import numpy as np
import pytest

from rigsim.frames import ARCSEC_PER_RAD, RAD_PER_ARCSEC
from rigsim.optics.autocollimator import (
    AutocollimatorOptics,
    PlanoConvexObjective,
    _refract,
    flat_mirror,
    n_bk7,
    retilt,
)
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.autocollimator import autocollimator_layout, mirror_target
from rigsim.truth.cube_mirror.realization import realization_from_rig

RIG = load_rig("sun_sensor_3axis_autocollimator")
AC = RIG.autocollimator
REAL = realization_from_rig(RIG)


@pytest.fixture(scope="module")
def optics():
    return AutocollimatorOptics(AC)


def test_n_bk7_matches_the_catalogue():
    assert n_bk7(587.56) == pytest.approx(1.5168, abs=5e-5)   # Schott n_d
    assert n_bk7(486.13) == pytest.approx(1.5224, abs=5e-5)   # n_F
    assert n_bk7(656.27) == pytest.approx(1.5143, abs=5e-5)   # n_C


def test_refraction_obeys_snell_and_fresnel():
    rng = np.random.default_rng(1)
    d = rng.normal(size=(200, 3))
    d[:, 2] = -np.abs(d[:, 2]) - 0.5
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n = np.array([0.0, 0.0, 1.0])  # faces the incident side
    for eta in (1 / 1.5168, 1.5168):
        t, T, ok = _refract(d, n, eta)
        s_i = np.linalg.norm(np.cross(d, n), axis=1)
        s_t = np.linalg.norm(np.cross(t[ok], n), axis=1)
        np.testing.assert_allclose(np.linalg.norm(t[ok], axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(eta * s_i[ok], s_t, atol=1e-12)
        assert np.all((T[ok] > 0) & (T[ok] <= 1))
    _, T0, _ = _refract(np.array([[0.0, 0.0, -1.0]]), n, 1 / 1.5168)
    assert T0[0] == pytest.approx(1 - ((1.5168 - 1) / (1.5168 + 1)) ** 2, abs=1e-12)


def test_objective_paraxial_back_focus():
    """A thin collimated pencil entering the convex side focuses at f − t/n behind the flat."""
    obj = PlanoConvexObjective(550.0, 50.0, 5.0)
    assert obj.radius_mm == pytest.approx(550.0 * (obj.n - 1.0))
    opt = AutocollimatorOptics(AC, focus="paraxial")
    h = np.linspace(0.01, 0.1, 5)
    H = np.column_stack([h, np.zeros_like(h), np.full_like(h, 100.0)])
    r = np.tile([0.0, 0.0, -1.0], (len(h), 1))
    # trace to the detector plane, then solve where each ray crosses the axis
    ob = opt.objective
    C = np.array([0.0, 0.0, ob.z_centre])
    oc = H - C
    b = (oc * r).sum(1)
    c = (oc * oc).sum(1) - ob.radius_mm ** 2
    P = H + (-b - np.sqrt(b * b - c))[:, None] * r
    d1, _, _ = _refract(r, (P - C) / ob.radius_mm, 1 / ob.n)
    P2 = P + ((ob.z_flat - P[:, 2]) / d1[:, 2])[:, None] * d1
    d2, _, _ = _refract(d1, np.array([0.0, 0.0, 1.0]), ob.n)
    z_cross = P2[:, 2] - P2[:, 0] / d2[:, 0] * d2[:, 2]
    bfd = ob.z_flat - z_cross
    np.testing.assert_allclose(bfd, 550.0 - 5.0 / ob.n, rtol=2e-7)


def test_small_aperture_offset_is_f_tan_2t():
    """Paraxial closed form: a 2 mm stop, the reticle at the paraxial focus, tilt t → the spot
    moves by f·tan(2t)/pitch (the 5 µm reticle–detector offset changes the scale by 1e-5)."""
    small = AC.model_copy(update={"aperture_mm": 2.0})
    opt = AutocollimatorOptics(small, focus="paraxial")
    z = opt.distance_mm + opt.objective.z_vertex
    for t_as in (5.0, 20.0, 60.0):
        t = t_as * RAD_PER_ARCSEC
        for tilt in ((t, 0.0), (0.0, -t)):
            sp = opt.spot(flat_mirror(z, tilt, 40.0), n_rays=20_000)
            expect = AC.focal_length_mm * math.tan(2 * t) / (AC.pixel_pitch_um * 1e-3)
            off = sp.mean_uv - [opt.cx, opt.cy]
            got = off[0] if tilt[0] else -off[1]
            assert got == pytest.approx(expect, rel=3e-5)
            assert abs(off[1] if tilt[0] else off[0]) < 1e-6


def test_full_aperture_is_not_paraxial(optics):
    """Through the 50 mm singlet the spot offset is 0.1-0.2 % short of f·tan(2t)/pitch: the
    paraxial model is not the truth (this is why the truth is an exact trace)."""
    z = optics.distance_mm + optics.objective.z_vertex
    t = 300.0 * RAD_PER_ARCSEC
    sp = optics.spot(flat_mirror(z, (t, 0.0), 100.0), n_rays=200_000)
    expect = AC.focal_length_mm * math.tan(2 * t) / (AC.pixel_pitch_um * 1e-3)
    ratio = (sp.mean_uv[0] - optics.cx) / expect
    assert 0.997 < ratio < 0.9995
    assert abs(sp.paraxial_uv[0] - optics.cx - expect) < 1e-9 * expect


def test_null_spot_is_centred_and_focused(optics):
    z = optics.distance_mm + optics.objective.z_vertex
    sp = optics.spot(flat_mirror(z, (0.0, 0.0), 100.0), n_rays=400_000, window_px=32)
    np.testing.assert_allclose(sp.mean_uv, [optics.cx, optics.cy], atol=1e-3)
    assert sp.rms_radius_px < 5.0  # best-collimation focus: a few pixels (spherical aberration)
    assert not any(sp.flags.values())
    # photons: the stop takes the 1 % overfill of the reticle's cone (1/1.01² pass), then four
    # Fresnel transmissions of ~(1 - ((n-1)/(n+1))²) each; nothing else is lost
    n = optics.objective.n
    assert sp.bundle.frac_stop_out == pytest.approx(1 / 1.01 ** 2, rel=2e-3)
    T = 1 - ((n - 1) / (n + 1)) ** 2
    assert sp.flux_photons == pytest.approx(sp.bundle.frac_stop_out * T ** 4, rel=2e-4)


@pytest.mark.parametrize("tilt_as", [(0.5, 0.0), (30.0, -12.0), (-250.0, 400.0), (600.0, 0.0)])
def test_calibrated_reading_recovers_the_tilt(optics, tilt_as):
    z = optics.distance_mm + optics.objective.z_vertex
    t = np.array(tilt_as) * RAD_PER_ARCSEC
    sp = optics.spot(flat_mirror(z, t, 100.0), n_rays=400_000)
    err = (optics.reading(sp.mean_uv) - t) * ARCSEC_PER_RAD
    assert np.max(np.abs(err)) < 0.01       # ≪ the instrument's 0.1″
    par = (optics.reading_paraxial(sp.mean_uv) - t) * ARCSEC_PER_RAD
    if max(abs(x) for x in tilt_as) > 200:
        assert np.max(np.abs(par)) > 0.2      # the paraxial scale is off by ~0.17 %


def test_calibration_stays_where_the_light_comes_back():
    """A fast, small objective far from its mirror (f 150 mm, Ø15 mm at 1 m): the detector spans
    ±45′ of tilt, but beyond ~29′ no light returns (2·t·1000 mm > the 7.5 mm beam radius + the
    objective's). The calibration is fitted over the returning range (½·atan(a/4/D) = 6.45′), where
    every return is partly vignetted: the cut pupil of an aberrated beam bends the spot-vs-tilt curve,
    and the reading recovers the tilt to within the instrument's 0.1″ resolution (measured: −0.06″
    at 10–20″, +0.013″ at 240″, −0.009″ at the range's end), not to the unvignetted 0.01″."""
    ac = AC.model_copy(update={"focal_length_mm": 150.0, "aperture_mm": 15.0, "resolution_px": (896, 640),
                               "pixel_pitch_um": 8.79, "distance_mm": 1000.0})
    o = AutocollimatorOptics(ac)
    assert math.degrees(o.measuring_range_rad()[0]) * 60 == pytest.approx(45.1, abs=0.1)
    D = o.distance_mm
    assert o.calibration_range_rad() == pytest.approx(0.5 * math.atan(0.25 * o.objective.clear_aperture_mm / D))
    assert o.calibration()["range_rad"] == o.calibration_range_rad()
    z = D + o.objective.z_vertex
    for tilt_as in [(20.0, 0.0), (-150.0, 240.0), (0.0, -380.0)]:
        t = np.array(tilt_as) * RAD_PER_ARCSEC
        sp = o.spot(flat_mirror(z, t, 100.0), n_rays=400_000)
        assert np.max(np.abs((o.reading(sp.mean_uv) - t) * ARCSEC_PER_RAD)) < ac.resolution_arcsec


def test_tilt_from_spot_inverts_the_exact_model_for_a_cube_face(optics):
    lay = autocollimator_layout(RIG, REAL, "face", objective_vertex_z_mm=optics.objective.z_vertex)
    m0 = mirror_target(RIG, REAL, lay, lay.reference_pose_rad)
    t = np.array([210.0, -95.0]) * RAD_PER_ARCSEC
    m = retilt(m0, t)
    np.testing.assert_allclose(m.tilt_rad(), t, atol=1e-15)
    sp = optics.spot(m, n_rays=400_000)
    back = optics.tilt_from_spot(sp.mean_uv, m0, n_rays=400_000)
    assert np.max(np.abs(back - t)) * ARCSEC_PER_RAD < 1e-3


def test_layout_nulls_and_signs(optics):
    for target in ("face", "plane_mirror"):
        lay = autocollimator_layout(RIG, REAL, target, objective_vertex_z_mm=optics.objective.z_vertex)
        m = mirror_target(RIG, REAL, lay, lay.reference_pose_rad)
        assert np.max(np.abs(m.tilt_rad())) < 1e-10
        np.testing.assert_allclose(m.centre, [0.0, 0.0, AC.distance_mm + 2.5], atol=1e-9)
        np.testing.assert_allclose(lay.R_rot_from_A.T @ lay.R_rot_from_A, np.eye(3), atol=1e-14)
        assert np.linalg.det(lay.R_rot_from_A) == pytest.approx(1.0)
        d = 100.0 * RAD_PER_ARCSEC
        for axis, k in (("Y", 0), ("X", 1)):
            pose = dict(lay.reference_pose_rad)
            pose[axis] += d
            tl = mirror_target(RIG, REAL, lay, pose).tilt_rad()
            # Y' turns the normal towards +X' = +x_A; X' turns it towards −Y' = +y_A
            assert tl[k] == pytest.approx(d, rel=2e-3)
            assert abs(tl[1 - k]) < 0.01 * d
    # the step-A axis is the campaign's noise-free reference direction (plane-mirror normal at the
    # pose where every axis reads zero: 4″/−6″ tilt, encoder biases and axis misalignments)
    from rigsim.procedures.cube_mirror.campaign import Noise, reference_direction
    lay = autocollimator_layout(RIG, REAL, "plane_mirror")
    d_ref = reference_direction(RIG, REAL, Noise(), np.random.default_rng(0))
    np.testing.assert_allclose(lay.axis_rot, d_ref, atol=1e-15)
    assert 5.0 < np.degrees(np.arccos(lay.axis_rot[2])) * 3600 < 15.0


def test_bad_geometry_flags(optics):
    lay = autocollimator_layout(RIG, REAL, "face", objective_vertex_z_mm=optics.objective.z_vertex)
    m0 = mirror_target(RIG, REAL, lay, lay.reference_pose_rad)
    # the beam misses the face: the face moved 60 mm sideways
    from dataclasses import replace
    away = replace(m0, centre=m0.centre + [60.0, 0.0, 0.0])
    sp = optics.spot(away, n_rays=50_000)
    assert sp.flags["beam_misses_face"] and sp.flags["spot_off_detector"] and not sp.valid
    # part of the face outside the beam: 20 mm sideways
    part = optics.spot(replace(m0, centre=m0.centre + [20.0, 0.0, 0.0]), n_rays=50_000)
    assert part.flags["beam_partly_misses_face"] and not part.flags["beam_misses_face"]
    assert 0.3 < part.bundle.mirror_fill_fraction < 0.8
    assert not optics.spot(m0, n_rays=50_000).flags["beam_partly_misses_face"]
    # out of the measuring range: the spot beyond the detector's +u edge, then cut by it
    half_x = optics.measuring_range_rad()[0]
    off = optics.spot(retilt(m0, (1.2 * half_x, 0.0)), n_rays=50_000)
    assert off.flags["spot_off_detector"] and off.valid
    # spot centre 2 px inside the edge (u = W - 2.5): the ~9 px spot is cut
    target_u = optics.width - 2.5
    t = optics.reading(np.array([target_u, optics.cy]))
    cut = optics.spot(retilt(m0, t), n_rays=50_000, window_px=32)
    assert cut.flags["spot_cut_by_edge"] and not cut.flags["spot_off_detector"]
    assert 0.2 < cut.flux_on_detector / cut.flux_photons < 0.9
    # the plane mirror (as wide as the beam) at 10′: the return beam walks off the objective
    pm = flat_mirror(optics.distance_mm + 2.5, (600 * RAD_PER_ARCSEC, 0.0), 25.0)
    assert optics.spot(pm, n_rays=50_000).flags["return_vignetted"]
    # a window too small for the spot
    small = optics.spot(m0, n_rays=50_000, window_px=6)
    assert small.flags["spot_exceeds_window"]


def test_binned_image_is_consistent_with_the_binned_centroid(optics):
    z = optics.distance_mm + optics.objective.z_vertex
    sp = optics.spot(flat_mirror(z, (40 * RAD_PER_ARCSEC, -70 * RAD_PER_ARCSEC), 12.0), n_rays=100_000,
                     window_px=24)
    img = optics.binned_image(sp.bundle, sp.window)
    v, u = np.indices(img.shape)
    c = np.array([(img * u).sum(), (img * v).sum()]) / img.sum() + sp.window[:2]
    np.testing.assert_allclose(c, sp.pixel_centroid_uv, atol=1e-9)
    assert img.sum() == pytest.approx(sp.flux_on_detector, rel=1e-12)


def _pixel_integrated(fun, half_px, sub=16):
    """Independent pixel integration of a PSF given as a function of (x, y) in pixels."""
    o = (np.arange(sub) + 0.5) / sub - 0.5
    k = np.arange(-half_px, half_px + 1)
    X = (k[None, :, None, None] + o[None, None, None, :])
    Y = (k[:, None, None, None] + o[None, None, :, None])
    return fun(X, Y).mean(axis=(2, 3))


def test_diffraction_kernel_square_face_and_disk(optics):
    """Kernel = pixel-integrated Fraunhofer PSF: sinc² for the 25 mm cube face, Airy for the
    full 50 mm stop (a large flat mirror), against closed forms integrated independently."""
    from scipy.special import j1
    lam = optics.objective.wavelength_nm * 1e-6
    f, p = optics.efl_mm, optics.pitch_mm
    z = optics.distance_mm + optics.objective.z_vertex
    h = 16
    # square 25 mm face, edges along x_A / y_A
    sq = flat_mirror(z, (0.0, 0.0), 1.0)
    from dataclasses import replace
    sq = replace(sq, shape="square", half_size_mm=12.5, e1=np.array([1.0, 0, 0]), e2=np.array([0, -1.0, 0]))
    K = optics.diffraction_kernel(sq, half_px=h)
    x0 = lam * f / 25.0 / p   # first zero, px
    ref = _pixel_integrated(lambda X, Y: np.sinc(X / x0) ** 2 * np.sinc(Y / x0) ** 2, h)
    ref /= ref.sum()
    assert np.max(np.abs(K - ref)) < 2e-3 * K.max()
    # disk: the stop (Ø50 mm) with a mirror larger than the beam
    K = optics.diffraction_kernel(flat_mirror(z, (0.0, 0.0), 60.0), half_px=h)
    D = optics.objective.clear_aperture_mm

    def airy(X, Y):
        rho = np.pi * D * np.hypot(X, Y) * p / (lam * f)
        rho = np.where(rho == 0, 1e-12, rho)
        return (2 * j1(rho) / rho) ** 2
    ref = _pixel_integrated(airy, h)
    ref /= ref.sum()
    assert np.max(np.abs(K - ref)) < 5e-3 * K.max()
    v, u = np.indices(K.shape)
    assert abs((K * u).sum() - h) < 1e-12 and abs((K * v).sum() - h) < 1e-12


def test_bad_parameters_are_rejected():
    with pytest.raises(ValueError, match="focus"):
        AutocollimatorOptics(AC, focus="sharp")
    with pytest.raises(ValueError, match="source_offset_mm"):
        AutocollimatorOptics(AC, source_offset_mm=0.0)
    with pytest.raises(ValueError, match="thickness"):
        PlanoConvexObjective(50.0, 50.0, 1.0)
    with pytest.raises(ValueError, match="target"):
        autocollimator_layout(RIG, REAL, "prism")


def test_the_factory_calibration_is_shared_through_the_cache_folder_and_rebuilt_when_it_does_not_fit(tmp_path, monkeypatch):
    """Another process (a dataset worker, a later run) reads the calibration from the cache folder, float for float;
    a file that does not fit (a number spoiled, another instrument) is not used."""
    import json

    from rigsim.optics import autocollimator as mod

    monkeypatch.setenv("RIGSIM_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(mod, "_CALIBRATIONS", {})
    n = 20_000
    cold = AutocollimatorOptics(AC).calibration(n_rays=n)
    (f,) = (tmp_path / "autocollimator-calibration").iterdir()

    def refuse(self, n_rays):
        raise AssertionError("computed although the cache holds it")

    monkeypatch.setattr(mod, "_CALIBRATIONS", {})
    with monkeypatch.context() as m:
        m.setattr(mod.AutocollimatorOptics, "_factory_calibration", refuse)
        assert AutocollimatorOptics(AC).calibration(n_rays=n) == cold
    doc = json.loads(f.read_text())
    for spoil in ({"F_mm": -doc["value"]["F_mm"]}, {"c": float("nan")}, {"n_rays": n + 1}):
        f.write_text(json.dumps({**doc, "value": {**doc["value"], **spoil}}))
        monkeypatch.setattr(mod, "_CALIBRATIONS", {})
        assert AutocollimatorOptics(AC).calibration(n_rays=n) == cold         # computed again: the same numbers
    longer = AutocollimatorOptics(AC.model_copy(update={"focal_length_mm": 1.5 * AC.focal_length_mm})).calibration(n_rays=n)
    assert longer["F_mm"] == pytest.approx(1.5 * cold["F_mm"], rel=2e-3)
    assert len(list((tmp_path / "autocollimator-calibration").iterdir())) == 2
