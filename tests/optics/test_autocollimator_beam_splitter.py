"""The beam splitter plate (docs/effects-autocollimator.md, ``beam_splitter``): the closed forms
against an exact two-plane Snell trace, and the instrument's reading with the plate after its
factory calibration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rigsim.errors import RigError
from rigsim.frames import ARCSEC_PER_RAD
from rigsim.optics.autocollimator import AutocollimatorOptics, flat_mirror, n_bk7
from rigsim.optics.beam_splitter import (
    BeamSplitter,
    PlatePlacement,
    focus_shift_sagittal,
    focus_shift_tangential,
    fresnel_unpolarised,
    ghost_ratio,
    ghost_separation,
    lateral_shift,
    trace_plate,
)
from rigsim.rig import load_rig
from rigsim.rig.effects_autocollimator import beam_splitter_of

RIG = load_rig("sun_sensor_3axis_autocollimator")
ARCMIN = math.radians(1.0 / 60.0)


def _plate(t=2.0, n=1.5168, deg=45.0):
    th = math.radians(deg)
    return PlatePlacement(np.array([0.0, 0.0, 0.0]), np.array([math.sin(th), 0.0, math.cos(th)]), t, n), th


def _x_at(H, o, z):
    return H[:, 0] + o[:, 0] * (z - H[:, 2]) / o[:, 2]


@pytest.mark.parametrize("t,n,deg", [(2.0, 1.5168, 45.0), (1.0, 1.8, 30.0), (3.0, 1.45, 55.0)])
def test_lateral_shift_and_ghost_separation_match_the_trace(t, n, deg):
    pl, th = _plate(t, n, deg)
    P, d = np.array([[0.0, 0.0, 10.0]]), np.array([[0.0, 0.0, -1.0]])
    H, o, _, ok = trace_plate(P, d, pl)
    assert ok.all() and np.allclose(o, d, atol=1e-15)        # a plane-parallel plate: no deviation
    x_main = _x_at(H, o, -30.0)[0]
    assert x_main == pytest.approx(-lateral_shift(t, n, th), abs=1e-12)
    Hg, og, _, _ = trace_plate(P, d, pl, "ghost")
    assert _x_at(Hg, og, -30.0)[0] - x_main == pytest.approx(ghost_separation(t, n, th), abs=1e-12)
    # the reticle side: the beam reflected by S2 leaves −separation beside the one reflected by S1
    dr = np.array([[-math.sin(2 * th), 0.0, -math.cos(2 * th)]])   # reflected by S1 into +z
    Pr = -10.0 * dr
    Ha, oa, _, _ = trace_plate(Pr, dr, pl, "reflect_s1")
    Hb, ob, _, _ = trace_plate(Pr, dr, pl, "reflect_s2")
    z = 50.0
    xa = Ha[:, 0] + oa[:, 0] * (z - Ha[:, 2]) / oa[:, 2]
    xb = Hb[:, 0] + ob[:, 0] * (z - Hb[:, 2]) / ob[:, 2]
    assert np.allclose(oa, ob, atol=1e-15)
    assert xb[0] - xa[0] == pytest.approx(-ghost_separation(t, n, th), abs=1e-12)


@pytest.mark.parametrize("deg", [0.0, 30.0, 45.0])
def test_astigmatic_focus_shifts_match_the_trace(deg):
    """A point 50 mm in front of the plate: its virtual image through the plate, from two close
    rays in the tangential and in the sagittal plane, moves d(dθ) and d/tan θ along the ray."""
    t, n = 2.0, 1.5168
    pl, th = _plate(t, n, deg)
    src = np.array([0.0, 0.0, 50.0])
    for plane, fs in (((1, 0), focus_shift_tangential), ((0, 1), focus_shift_sagittal)):
        e = 1e-5
        d = np.array([[plane[0] * e, plane[1] * e, -1.0], [-plane[0] * e, -plane[1] * e, -1.0]])
        d /= np.linalg.norm(d, axis=1)[:, None]
        H, o, _, _ = trace_plate(np.repeat(src[None], 2, 0), d, pl)
        s = np.linalg.lstsq(np.stack([o[0], -o[1]], 1), H[1] - H[0], rcond=None)[0]
        X = H[0] + s[0] * o[0]
        assert 50.0 - X[2] == pytest.approx(fs(t, n, th), abs=2e-6), plane
    assert focus_shift_sagittal(t, n, 0.0) == pytest.approx(t * (1 - 1 / n))


def test_ghost_ratio_is_the_two_ghost_paths_traced():
    """Both ghosts land on the same spot (the reticle's S2 image, point-inverted, and the return's
    double internal reflection are displaced the same way); their sum over the main spot is
    R2·(T1²/R1 + R1), with the reflectances at the traced angles."""
    bs = BeamSplitter(r1=0.5, r2=None)
    ci = math.cos(bs.theta)
    F = float(fresnel_unpolarised(ci, bs.n))
    # bare N-BK7 at 45°: (Rs + Rp)/2 = (9.60 % + 0.92 %)/2; the objective's Snell/Fresnel code agrees
    assert F == pytest.approx(0.0526, abs=1e-4)
    from rigsim.optics.autocollimator import _refract

    _, T, _ = _refract(np.array([[math.sin(bs.theta), 0.0, -ci]]), np.array([0.0, 0.0, 1.0]), 1.0 / bs.n)
    assert F == pytest.approx(1.0 - T[0], abs=1e-14)
    R1, T1 = bs.weights(ci, 1)
    R2, T2 = bs.weights(ci, 2)
    main = R1 * T1 * T2
    ghosts = T1 * R2 * T1 * T1 * T2 + R1 * T1 * R2 * R1 * T2   # reticle via S2; return twice inside
    assert ghosts / main == pytest.approx(ghost_ratio(0.5, F), rel=1e-12)
    assert ghost_ratio(0.5, F) == pytest.approx(F)                # a 50/50 coat: exactly R2
    assert ghost_ratio(0.5, 0.005) == pytest.approx(0.005)        # an AR-coated back face
    assert ghost_ratio(F, F) == pytest.approx((1 - F) ** 2 + F * F, rel=1e-12)  # both faces bare


def test_the_plate_in_the_exact_model_shifts_the_spot_by_the_closed_form():
    """With the plate, the axial ray lands d aside; the detector is centred there, so the spot
    (pixels) stays within the tilted plate's coma (~0.16 px) of the ideal's."""
    bs = BeamSplitter()
    o0 = AutocollimatorOptics(RIG.autocollimator)
    o1 = AutocollimatorOptics(RIG.autocollimator, beam_splitter=bs)
    assert o1.detector_xy0[0] == pytest.approx(-lateral_shift(2.0, n_bk7(587.56), math.radians(45.0)))
    assert o0.z_detector - o1.z_detector == pytest.approx(bs.focus_shift_mm)
    m = flat_mirror(o0.distance_mm + o0.objective.z_vertex, (2 * ARCMIN, -1 * ARCMIN), radius_mm=100)
    a, b = o0.spot(m, n_rays=200_000), o1.spot(m, n_rays=200_000)
    shift_mm = o1.uv_to_xy(b.mean_uv) - o0.uv_to_xy(a.mean_uv)
    assert shift_mm[0] == pytest.approx(-bs.lateral_shift_mm, abs=0.2 * o0.pitch_mm)
    assert abs(shift_mm[1]) < 0.2 * o0.pitch_mm
    assert 0.05 < np.hypot(*(b.mean_uv - a.mean_uv)) < 0.3
    # the light: R1·T1·T2 of the ideal's
    assert b.flux_photons / a.flux_photons == pytest.approx(0.5 * 0.5 * (1 - bs.fresnel_at_tilt), rel=0.01)


def test_the_factory_calibration_keeps_the_reading_within_the_instrument():
    """After the calibration with the plate (re-zeroed, y scaled) the reading stays within
    ±0.05″ of the truth over the measuring range; read with the ideal instrument's calibration
    it is off by up to 0.3″ (the re-zeroing and the y scale matter)."""
    o0 = AutocollimatorOptics(RIG.autocollimator)
    o1 = AutocollimatorOptics(RIG.autocollimator, beam_splitter=BeamSplitter())
    cal = o1.calibration(n_rays=100_000)
    o0.calibration(n_rays=100_000)
    assert cal["ref_uv"][0] - o1.cx == pytest.approx(-0.157, abs=0.02)
    worst1 = worst0 = 0.0
    for tx, ty in [(0, 0), (-7, 2), (0, -8), (10, 0), (-10, 0), (6, 6)]:
        m = flat_mirror(o0.distance_mm + o0.objective.z_vertex, (tx * ARCMIN, ty * ARCMIN), radius_mm=100)
        uv = o1.spot(m, n_rays=100_000).mean_uv
        worst1 = max(worst1, np.max(np.abs(o1.reading(uv) - m.tilt_rad())) * ARCSEC_PER_RAD)
        worst0 = max(worst0, np.max(np.abs(o0.reading(uv) - m.tilt_rad())) * ARCSEC_PER_RAD)
    assert worst1 < 0.05, worst1
    assert worst0 > 0.2, worst0


def test_the_effect_builds_the_plate_and_is_off_by_default():
    assert beam_splitter_of(RIG) is None
    fx = RIG.effects.only(["beam_splitter"])
    bs = beam_splitter_of(RIG.model_copy(update={"effects": fx}))
    assert bs == BeamSplitter(2.0, n_bk7(587.56), 45.0, 0.5, None)


@pytest.mark.parametrize("field,value,expect", [
    ("thickness_mm", 0.0, "greater than 0"),
    ("thickness_mm", 12.0, "less than or equal to 10"),
    ("tilt_deg", 80.0, "less than or equal to 60"),
    ("glass_index", 0.9, "greater than 1"),
    ("first_surface_reflectance", 1.0, "less than 1"),
    ("second_surface_reflectance", -0.1, "greater than or equal to 0"),
])
def test_bad_beam_splitter_values_name_field_value_and_range(tmp_path, field, value, expect):
    import re

    from rigsim.rig.load import SCENES_DIR

    text = (SCENES_DIR / "sun_sensor_3axis_autocollimator.toml").read_text()
    head, _, block = text.partition("[effects.beam_splitter]")
    assert block, "the shipped scene lists the effect"
    block = re.sub(rf"^#? ?{field} = .*$", "", block, flags=re.MULTILINE)
    p = tmp_path / "r.toml"
    p.write_text(head + f"[effects.beam_splitter]\n{field} = {value}" + block)
    with pytest.raises(RigError) as ei:
        load_rig(p)
    msg = str(ei.value)
    assert "\n" not in msg, msg
    assert f"effects.beam_splitter.{field}" in msg and str(value) in msg and expect in msg, msg
