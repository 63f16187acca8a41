"""The boresight rig's [effects] rendered (Mitsuba ptracer) against their closed forms.

gaussian_beam: the rendered spot's second moments vs the M² Gaussian-beam radius w(z) (σ² = w²/4 per
axis, plus the pixel's 1/12 px²). prism_glass: the rendered main spot and both Fresnel ghosts vs the
exact vector Snell/Fresnel trace of the glass (positions, power shares). Each test fails with its
effect off (the uniform core's σ² is 1.65 px², not 2.43; no ghost is rendered).
"""

import numpy as np
import pytest

from rigsim.frames import ARCSEC_PER_RAD as AS
from rigsim.optics.gaussian_beam import beam_radius_mm, second_moment_mm2
from rigsim.optics.line_camera import rotation_xyz
from rigsim.rig.load import load_boresight_rig

pytestmark = pytest.mark.render

RIG = load_boresight_rig()


def _with(*names):
    return RIG.model_copy(update={"effects": RIG.effects.only(names)})


def _moments(ph):
    v, u = np.mgrid[: ph.shape[0], : ph.shape[1]]
    t = ph.sum()
    cu, cv = (ph * u).sum() / t, (ph * v).sum() / t
    return cu, cv, ((u - cu) ** 2 * ph).sum() / t, ((v - cv) ** 2 * ph).sum() / t


def test_gaussian_beam_spot_has_the_gaussian_beam_second_moments():
    from rigsim.render.boresight import LoopRenderer

    rig = _with("gaussian_beam")
    b = rig.effects.gaussian_beam
    r = LoopRenderer(rig, 0, 0, spp=256)
    ph, _ = r.render_photons(None, 0.0, seed=5)
    _, _, su, sv = _moments(ph)
    w = beam_radius_mm(b.waist_radius_um * 1e-3, b.wavelength_nm, b.m_squared, b.waist_offset_mm)
    assert w * 1e3 == pytest.approx(30.65, abs=0.01)       # 25 µm waist, z_R = 2.82 mm, z = 2 mm
    expect = second_moment_mm2(w, b.truncation) / r.geom.pitch_mm**2 + 1.0 / 12.0   # + the pixel's box
    # measured 2.440 vs 2.431 px²: the 256² bilinear radiance bitmap widens it by ~0.3 %, sampling ~0.2 %
    assert su == pytest.approx(expect, rel=0.01) and sv == pytest.approx(expect, rel=0.01)
    # the uniform core of the same radius (the ideal frame) is far narrower: R²/4 + 1/12 = 1.65 px²
    assert su > 1.3 * ((r.core_radius_mm / r.geom.pitch_mm) ** 2 / 4 + 1 / 12)


def test_gaussian_beam_centroid_stays_on_the_exact_spot():
    from rigsim.render.boresight import LoopRenderer

    r = LoopRenderer(_with("gaussian_beam"), 0, 1, spp=256, follow=True, window_px=32)
    E = rotation_xyz(*(np.array([4.0, -3.0, 2.0]) / AS))
    fr = r.render(E, 0.003, seed=2, noiseless=True)
    tr = fr.truth
    # the Gaussian truth (400k rays drawn from the same profile) and the exact spot centre
    assert np.abs(fr.photon_centroid() - np.array(tr["pixel_centroid_uv"])).max() < 0.02
    assert np.abs(fr.photon_centroid() - np.array(tr["spot_uv"])).max() < 0.02
    assert tr["gaussian_beam"]["second_moment_px2"] == pytest.approx(2.348, abs=0.001)


@pytest.fixture(scope="module")
def glass_frame():
    from rigsim.render.boresight import LoopRenderer

    r = LoopRenderer(_with("prism_glass"), 0, 0, spp=256)
    E = rotation_xyz(*(np.array([0.2, -1.5, 0.5]) / AS))   # moves the spots ~9 px in u: the ghosts stay in the ROI
    fr = r.render(E, 0.002, seed=4, noiseless=True)
    ph, origin = r.render_photons(E, 0.002, seed=4)
    return r, fr, ph, origin


def test_prism_glass_ghosts_match_snell_and_fresnel(glass_frame):
    _, fr, ph, origin = glass_frame
    tr = fr.truth["prism_glass"]
    R = ((1.51509 - 1) / (1.51509 + 1)) ** 2
    assert tr["ghost1"]["fraction"] == pytest.approx(R, rel=1e-3)
    assert tr["main"]["fraction"] == pytest.approx((1 - R) ** 2, rel=1e-3)
    # the ghosts sit 2ε = 6″ either side of the main spot: 6″ × F / pitch = 17.45 px, stretched by up to
    # 1/cos² = 1.012 in the 6.3° off-axis field (measured 17.67 px)
    for g in ("ghost1", "ghost2"):
        sep = np.subtract(tr[g]["uv"], tr["main"]["uv"])
        assert np.hypot(*sep) == pytest.approx(6.0 / AS * 6000.0 / 0.010 * 1.006, rel=0.007)
    total = ph.sum()
    for path in ("main", "ghost1", "ghost2"):
        uv = np.array(tr[path]["uv"]) - np.array(origin)
        iu, iv = (round(x) for x in uv)
        box = ph[iv - 5: iv + 6, iu - 5: iu + 6]
        vv, uu = np.mgrid[iv - 5: iv + 6, iu - 5: iu + 6]
        # share of the power: measured within 0.3 % (ghosts) and 0.2 % (main) of the Fresnel values
        assert box.sum() / total == pytest.approx(tr[path]["fraction"], rel=0.03), path
        # position vs the Snell trace: main within 0.02 px; the ghosts' Monte-Carlo noise is ~0.01 px and
        # Mitsuba's float32 normal of the tilted entrance face (rounding ~3e-8 rad, ×2n for the second
        # ghost's inner reflection) moves them by up to ~0.04 px (measured 0.03)
        tol = 0.02 if path == "main" else 0.05
        assert (box * uu).sum() / box.sum() == pytest.approx(uv[0], abs=tol), path
        assert (box * vv).sum() / box.sum() == pytest.approx(uv[1], abs=tol), path


def test_prism_glass_main_spot_and_all_paths_centroid(glass_frame):
    fr = glass_frame[1]
    tr = fr.truth
    # the photon centroid of the whole ROI is the power-weighted mean of the three paths (the higher-order
    # ghosts carry 0.2 %): measured within 0.01 px
    assert np.abs(fr.photon_centroid() - np.array(tr["prism_glass"]["all_paths_centroid_uv"])).max() < 0.03
    # the ghosts pull it off the main spot by ~−0.06 px in v (ghost1, the brighter, lies at −v)
    pull = fr.photon_centroid()[1] - tr["spot_uv"][1]
    assert -0.09 < pull < -0.03
    # the main spot moves under the rotation as the exact Snell trace says: it is the truth's spot
    assert tr["spot_uv"] == pytest.approx(tr["prism_glass"]["main"]["uv"], abs=1e-12)


def _aberrated(**upd):
    eff = RIG.effects.only(["objective_aberrations"])
    eff = eff.model_copy(update={"objective_aberrations": eff.objective_aberrations.model_copy(update=upd)})
    return RIG.model_copy(update={"effects": eff})


@pytest.mark.parametrize("j", [0, 1])
def test_objective_coma_moves_the_spot_by_the_seidel_centroid_shift(j):
    from rigsim.render.boresight import LoopRenderer

    r = LoopRenderer(_aberrated(astigmatism_waves=0.0), 0, j, spp=256)
    fr = r.render(None, 0.0, seed=6, noiseless=True)
    ab = fr.truth["objective_aberrations"]
    # 0.25 λ of coma at f/10, doubled by the loop: 0.63 px towards the optical axis (tangential)
    assert np.hypot(*ab["centroid_shift_px"]) == pytest.approx(0.633, abs=0.001)
    shift = fr.photon_centroid() - np.array(fr.truth["pixel_centroid_uv"])
    # rendered vs closed form: measured within 0.002 px (Monte-Carlo noise ~0.002 px)
    np.testing.assert_allclose(shift, ab["centroid_shift_px"], atol=0.008)


def test_objective_astigmatism_stretches_the_spot_tangentially():
    from rigsim.render.boresight import LoopRenderer

    r = LoopRenderer(_aberrated(coma_waves=0.0), 0, 0, spp=256)
    ph, _ = r.render_photons(None, 0.0, seed=7)
    ab = r.aberration_truth()
    v, u = np.mgrid[: ph.shape[0], : ph.shape[1]]
    t = np.array(ab["tangential_uv"])
    w = ph / ph.sum()
    cu, cv = (w * u).sum(), (w * v).sum()
    pt = (u - cu) * t[0] + (v - cv) * t[1]
    ps = -(u - cu) * t[1] + (v - cv) * t[0]
    # the core and the pixel are isotropic: tangential − sagittal variance is astigmatism's alone,
    # 4(F/a)²W222² = 0.400 px² (measured 0.3997); the centroid does not move
    assert (w * pt**2).sum() - (w * ps**2).sum() == pytest.approx(ab["astigmatism_tangential_variance_px2"], rel=0.03)
    assert ab["astigmatism_tangential_variance_px2"] == pytest.approx(0.400, abs=0.001)
    assert abs((w * pt).sum()) < 1e-9
