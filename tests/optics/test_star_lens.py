"""The star sensor's traced lens against closed forms: the glasses' catalogue indices, the paraxial
focal length (thick-lens lensmaker formula and an ABCD matrix product), the defocus blur of the axial
PSF and the paraxial lateral colour."""

from __future__ import annotations

import numpy as np
import pytest

from rigsim.optics.star_lens import StarLens, abbe_number, refractive_index
from rigsim.optics.star_psf import bv_temperature_k, photon_spectrum_weights, psf_table

F, EPD, REF, PITCH = 43.3, 20.0, 600.0, 15.0   # the default rig's [sensor]


@pytest.fixture(scope="module")
def lens():
    return StarLens(focal_length_mm=F, epd_mm=EPD, ref_nm=REF, defocus_mm=-0.1)   # as the rig's traced_psf


@pytest.mark.parametrize("glass, nd, vd", [("N-SK16", 1.62041, 60.32), ("F2", 1.62004, 36.37),
                                            ("SK2", 1.60738, 56.65), ("F5", 1.60342, 38.03)])
def test_glasses_give_the_catalogue_index_and_abbe_number(glass, nd, vd):
    # Schott catalogue n_d (5 decimals) and V_d (2 decimals)
    assert float(refractive_index(glass, 587.5618)) == pytest.approx(nd, abs=6e-6)
    assert abbe_number(glass) == pytest.approx(vd, abs=6e-3)


def test_a_thick_singlet_has_the_lensmaker_focal_length_at_every_wavelength():
    single = StarLens(((60.0, 6.0, "N-SK16"), (-90.0, 0.0, "air")), stop=0, focal_length_mm=50.0, epd_mm=5.0,
                      ref_nm=REF)
    c1, c2 = single.surfaces[0].c, single.surfaces[1].c
    t = single.surfaces[0].t
    for lam in (450.0, 600.0, 850.0):
        n = float(refractive_index("N-SK16", lam))
        f = 1.0 / ((n - 1.0) * (c1 - c2 + (n - 1.0) * t * c1 * c2 / n))
        assert single.efl(lam) == pytest.approx(f, rel=1e-12)
    assert single.efl(REF) == pytest.approx(50.0, rel=1e-12)


def _abcd_efl(lens, lam):
    """An independent system matrix: refraction [[1, 0], [−(n'−n)c/n', n/n']], transfer [[1, t], [0, 1]]."""
    M = np.eye(2)
    n = 1.0
    for i, s in enumerate(lens.surfaces):
        n2 = float(refractive_index(s.medium, lam))
        M = np.array([[1.0, 0.0], [-(n2 - n) * s.c / n2, n / n2]]) @ M
        if i < len(lens.surfaces) - 1:
            M = np.array([[1.0, s.t], [0.0, 1.0]]) @ M
        n = n2
    return -1.0 / M[1, 0]


def test_the_lens_focal_length_is_the_rigs_and_agrees_with_abcd_and_a_real_near_axis_ray(lens):
    assert lens.focal_length_mm == pytest.approx(F, rel=1e-12)
    for lam in (450.0, REF, 850.0):
        assert lens.efl(lam) == pytest.approx(_abcd_efl(lens, lam), rel=1e-12)
        y = 1e-4   # a real ray 0.1 µm off the axis: f = y / sin U' to O((y/f)²)
        _, d, ok = lens.trace_rays([0.0, 0.0, 1.0], np.array([[0.0, y]]), lam)
        assert ok.all()
        assert y / -d[0, 1] == pytest.approx(lens.efl(lam), rel=1e-7)


def test_axial_psf_blur_is_the_defocus_closed_form(lens):
    z_par = lens.z[-1] + lens.bfl(REF)
    dz = 0.1
    # a thin annulus (2 % of the pupil): its ring at the paraxial focus + dz has radius ρ·(D/2)·dz/f
    # (spherical aberration ∝ ρ³ and the sine condition ∝ ρ² stay below 1e-3 of it)
    rho = 0.02
    phi = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    ring = rho * EPD / 2 * np.stack([np.cos(phi), np.sin(phi)], axis=1)   # on the entrance-pupil plane
    h, ok = lens.trace([0.0, 0.0, 1.0], ring, REF, image_z=z_par + dz)
    assert ok.all()
    np.testing.assert_allclose(np.hypot(*h.T), rho * EPD / 2 * dz / F, rtol=2e-3)
    # the full pupil on the defocused detector: a disk of diameter D·dz/f has rms radius D·dz/(2√2 f).
    # The traced spot adds the aberrations: by Minkowski's inequality its rms radius differs from the
    # disk's by at most the rms radius of the spot at best focus (what the defocus is added to)
    pupil = lens.pupil_grid(96)
    h_det, ok = lens.trace([0.0, 0.0, 1.0], pupil, REF)
    h_best, ok2 = lens.trace([0.0, 0.0, 1.0], pupil, REF, image_z=lens.best_focus_z)
    rms = np.sqrt(np.mean(np.sum(h_det[ok] ** 2, axis=1)))
    eps = np.sqrt(np.mean(np.sum(h_best[ok2] ** 2, axis=1)))
    disk = EPD * dz / (2 * np.sqrt(2) * F)
    assert abs(rms - disk) <= eps + 1e-4
    assert eps < 0.5 * disk                         # the design is defocus-dominated on axis
    # and the PSF table's axial PSF (pixels) carries the same second moment, to its bin width
    T = psf_table(lens, tan_max_x=0.0, tan_max_y=0.0, wavelengths_nm=[REF], pixel_pitch_um=PITCH, nodes=2,
                  pupil_rays=96, oversample=8)
    P = T.psf[0, 0, 0]
    c = (np.arange(P.shape[0]) + 0.5) / T.oversample - T.radius_px
    r2 = (P.sum(axis=0) @ c**2) + (P.sum(axis=1) @ c**2)
    sig_diff = 0.42 * REF * 1e-3 * F / EPD / PITCH
    want = (rms * 1e3 / PITCH) ** 2 + 2 * sig_diff**2 + 2 * (1 / T.oversample) ** 2 / 12 * 2
    assert np.sqrt(r2) == pytest.approx(np.sqrt(want), rel=0.02)
    assert np.abs(T.centroid[0, 0, 0]).max() < 1e-9   # the axial PSF is centred on the chief ray


def test_lateral_colour_is_the_paraxial_chromatic_difference_of_the_chief_ray(lens):
    th = np.radians(0.5)
    d = np.array([0.0, np.sin(th), np.cos(th)])
    real = {lam: lens.chief_ray(d, lam)[0, 1] for lam in (450.0, 850.0)}
    par = {lam: lens.paraxial_image_height(np.tan(th), lam) for lam in (450.0, 850.0)}
    assert real[450.0] - real[850.0] == pytest.approx(par[450.0] - par[850.0], rel=1e-2)
    assert abs(par[450.0] - par[850.0]) > 1e-6     # the lens has lateral colour to measure


def test_star_colours_give_blackbody_temperatures_and_photon_spectra():
    assert bv_temperature_k(0.65) == pytest.approx(5770.0, rel=0.03)   # the Sun: B−V 0.65, 5772 K
    assert bv_temperature_k(0.0) == pytest.approx(9600.0, rel=0.06)    # Vega: B−V 0.00, ≈ 9600 K
    assert bv_temperature_k(-0.2) > 12000 and bv_temperature_k(1.5) < 4000
    lam = np.array([500.0, 800.0])
    w = photon_spectrum_weights([1e12, 3000.0], lam)
    # Rayleigh–Jeans limit: photons per nm ∝ λ⁻³ (trapezoid weights are equal at the two ends)
    assert w[0, 0] / w[0, 1] == pytest.approx((500.0 / 800.0) ** -3, rel=1e-6)
    assert w[1, 1] > w[1, 0]                      # a cool star gives more red photons
    np.testing.assert_allclose(w.sum(axis=1), 1.0)
