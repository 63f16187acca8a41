"""The closed forms behind the boresight effects: Gaussian-beam propagation (M² model) and the prism
glass (Snell, Fresnel, total internal reflection, the wedge's deviation)."""

import math

import numpy as np
import pytest

from rigsim.optics.gaussian_beam import (
    beam_radius_mm,
    gaussian_irradiance,
    rayleigh_range_mm,
    sample_gaussian_disk,
    second_moment_mm2,
)
from rigsim.optics.prism_glass import fresnel_unpolarised, glass_facet, refract, thin_wedge_deviation, wedge_deviation_exact

N_BK7 = 1.51509
AS = math.pi / 180 / 3600


def test_gaussian_beam_radius_follows_the_m2_closed_form():
    w0, lam = 0.025, 632.8
    zr = rayleigh_range_mm(w0, lam, 1.0)
    assert zr == pytest.approx(math.pi * w0**2 / (lam * 1e-6), rel=1e-12)   # 3.10 mm
    assert beam_radius_mm(w0, lam, 1.0, zr) == pytest.approx(math.sqrt(2) * w0, rel=1e-12)
    # M² = 2 halves the Rayleigh range: at the M²=1 beam's z_R the radius is w0·sqrt(5)
    assert beam_radius_mm(w0, lam, 2.0, zr) == pytest.approx(math.sqrt(5) * w0, rel=1e-12)
    assert beam_radius_mm(w0, lam, 1.1, 0.0) == w0


def test_gaussian_samples_have_the_truncated_second_moment():
    rng = np.random.default_rng(1)
    w, cut = 0.03, 3.0
    x, y = sample_gaussian_disk(rng, 400_000, w, cut)
    s2 = second_moment_mm2(w, cut)
    assert s2 == pytest.approx(w**2 / 4, rel=1e-6)      # the 3w cut loses e^-18
    # sampling: relative σ of a variance estimate sqrt(2/n) = 0.22 %
    assert np.var(x) == pytest.approx(s2, rel=0.01) and np.var(y) == pytest.approx(s2, rel=0.01)
    assert np.hypot(x, y).max() <= cut * w
    # a harder cut (1.5 w) removes 1.1 % of the power and shrinks the moment, as the closed form says
    x2, _ = sample_gaussian_disk(rng, 400_000, w, 1.5)
    assert np.var(x2) == pytest.approx(second_moment_mm2(w, 1.5), rel=0.01)
    assert second_moment_mm2(w, 1.5) < 0.95 * w**2 / 4
    img = gaussian_irradiance(64, cut)
    assert img.max() == pytest.approx(1.0, abs=0.01) and img[0, 0] == 0.0


def test_refraction_obeys_snell_and_tir_starts_at_the_critical_angle():
    rng = np.random.default_rng(2)
    n = np.array([0.0, 0.0, 1.0])
    th = rng.uniform(0, 0.49 * math.pi, 200)
    d = np.stack([np.sin(th), np.zeros_like(th), -np.cos(th)], axis=-1)   # towards the surface from +z
    t, tir = refract(d, n, 1.0, N_BK7)
    assert not tir.any()
    np.testing.assert_allclose(np.hypot(t[:, 0], t[:, 1]), np.sin(th) / N_BK7, atol=1e-12)
    # from inside the glass: TIR exactly where sin θ > 1/n (critical angle 41.30° for N-BK7)
    t2, tir2 = refract(d, n, N_BK7, 1.0)
    np.testing.assert_array_equal(tir2, np.sin(th) > 1.0 / N_BK7)
    assert math.degrees(math.asin(1 / N_BK7)) == pytest.approx(41.30, abs=0.01)
    np.testing.assert_allclose(t2[tir2, 2], -d[tir2, 2], atol=1e-12)            # reflected
    ok = ~tir2
    np.testing.assert_allclose(np.hypot(t2[ok, 0], t2[ok, 1]), np.sin(th[ok]) * N_BK7, atol=1e-12)
    assert fresnel_unpolarised(np.cos(th[tir2]), N_BK7, 1.0).min() == 1.0


def test_fresnel_reflectance_closed_forms():
    assert fresnel_unpolarised(1.0, 1.0, N_BK7) == pytest.approx(((N_BK7 - 1) / (N_BK7 + 1)) ** 2, rel=1e-12)  # 4.19 %
    brewster = math.atan(N_BK7)             # p-reflectance vanishes: R = R_s / 2
    ci, ct = math.cos(brewster), math.cos(math.asin(math.sin(brewster) / N_BK7))
    rs = ((ci - N_BK7 * ct) / (ci + N_BK7 * ct)) ** 2
    assert fresnel_unpolarised(ci, 1.0, N_BK7) == pytest.approx(rs / 2, rel=1e-9)


def _in_plane_angle(v):
    return math.atan2(v[0], -v[2])


@pytest.mark.parametrize("inc_arcsec", [0.0, 40.0, -300.0, 3600.0])
@pytest.mark.parametrize("wedge_arcsec", [3.0, 60.0, 1800.0])
def test_main_return_matches_the_closed_form_wedge_deviation(inc_arcsec, wedge_arcsec):
    """Vector Snell trace of the wedge (in the x–z plane) vs the scalar closed form."""
    eps, inc = wedge_arcsec * AS, inc_arcsec * AS
    mirror = np.array([0.0, 0.0, -1.0])                     # faces the ray coming along +z
    front = np.array([-math.sin(eps), 0.0, -math.cos(eps)])  # tilted by ε about y
    from rigsim.optics.prism_glass import GlassFacet

    g = GlassFacet(front, mirror, [0, 0, 0.0], [0, 0, 10.0], N_BK7)
    d = np.array([[math.sin(inc), 0.0, math.cos(inc)]])
    out = g.paths(np.array([[0.0, 0.0, -5.0]]), d)["main"][1][0]
    ideal = d[0] - 2 * (d[0] @ mirror) * mirror
    dev = _in_plane_angle(out) - _in_plane_angle(ideal)
    assert dev == pytest.approx(wedge_deviation_exact(inc, eps, N_BK7), abs=1e-12)
    if inc_arcsec == 0.0 and wedge_arcsec < 100:   # thin wedge: 2(n−1)ε to first order
        assert abs(dev) == pytest.approx(thin_wedge_deviation(eps, N_BK7), rel=1e-3)


def test_aligned_glass_facet_autocollimates_and_places_the_ghosts():
    u = np.array([0.1, -0.08, 1.0])
    u /= np.linalg.norm(u)
    eps = 3.0 * AS
    g = glass_facet(u, u * 1000.0, n=N_BK7, thickness_mm=10.0, wedge_rad=eps, wedge_azimuth_rad=0.3)
    paths = g.paths(np.zeros((1, 3)), u[None])
    main, g1, g2 = (paths[k][1][0] for k in ("main", "ghost1", "ghost2"))
    assert np.linalg.norm(main + u) < 1e-12     # retraces the beam
    # the first ghost is the entrance face's reflection: 2ε from the main return (exact)
    assert np.linalg.norm(g1 + u) == pytest.approx(2 * eps, rel=1e-6)
    # the second ghost leaves at 2ε on the other side (first order: the inner reflection tilts by 2nε, leaving divides by n)
    assert np.linalg.norm(g2 + u) == pytest.approx(2 * eps, rel=1e-3)
    assert (g1 + u) @ (g2 + u) < -0.99 * np.linalg.norm(g1 + u) * np.linalg.norm(g2 + u)   # opposite sides of it
    R = g.reflectance()
    assert R == pytest.approx(0.041943, abs=1e-6)   # ((n−1)/(n+1))²
    assert paths["main"][2][0] == pytest.approx((1 - R) ** 2, rel=1e-9)
    assert paths["ghost1"][2][0] == pytest.approx(R, rel=1e-9)
    assert paths["ghost2"][2][0] == pytest.approx((1 - R) ** 2 * R, rel=1e-6)


def test_seidel_closed_forms_match_a_monte_carlo_over_the_pupil():
    from rigsim.optics.objective_aberrations import (
        centroid_shift_mm,
        loop_transverse_aberration_mm,
        sample_pupil,
        tangential_variance_mm2,
    )

    rng = np.random.default_rng(3)
    lam = 632.8e-6
    C, A, fa = 0.25 * lam, 0.25 * lam, 20.0
    for fill in (1.0, 0.4):
        x, y = sample_pupil(rng, 1_000_000, fill)
        es, et = loop_transverse_aberration_mm(x, y, coma_mm=C, astig_mm=0.0, f_over_a=fa)
        shift = centroid_shift_mm(coma_mm=C, f_over_a=fa, fill=fill)    # −6.33 µm at full fill: 0.63 px
        assert et.mean() == pytest.approx(shift, rel=0.005)
        assert abs(es.mean()) < 1e-3 * abs(shift)                        # no sagittal shift
        es, et = loop_transverse_aberration_mm(x, y, coma_mm=0.0, astig_mm=A, f_over_a=fa)
        assert et.var() == pytest.approx(tangential_variance_mm2(astig_mm=A, f_over_a=fa, fill=fill), rel=0.005)
        assert es.var() == 0.0 and abs(et.mean()) < 5 * et.std() / 1000.0   # unbiased (5 σ of the mean)
    # coma scales as fill²: the laser filling 40 % of the pupil moves the spot 6.25× less
    full = centroid_shift_mm(coma_mm=C, f_over_a=fa, fill=1.0)
    assert full * 1e3 == pytest.approx(-6.328, abs=0.001)
    assert centroid_shift_mm(coma_mm=C, f_over_a=fa, fill=0.4) / full == pytest.approx(0.16, rel=1e-12)
