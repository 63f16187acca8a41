"""The stray-light gradient: its brightest edge, its slope per pixel, its direction, its windows."""

from __future__ import annotations

import numpy as np

from rigsim.optics.sky import star_photons
from rigsim.optics.stray_light import stray_light_mag_map, surface_brightness_photons

PIX_DEG = 0.0198  # 15 µm at f = 43.3 mm


def test_gradient_starts_at_the_edge_towards_the_source_and_falls_linearly_in_magnitudes():
    m = stray_light_mag_map((100, 200), PIX_DEG, direction_deg=0.0, edge_mag_per_arcsec2=18.0,
                            falloff_mag_per_deg=0.3)
    # the source lies towards +u: the last column is half a pixel from the bright edge
    np.testing.assert_allclose(m[:, -1], 18.0 + 0.3 * 0.5 * PIX_DEG)
    np.testing.assert_allclose(np.diff(m, axis=1), -0.3 * PIX_DEG)
    np.testing.assert_allclose(np.diff(m, axis=0), 0.0, atol=1e-12)


def test_diagonal_source_and_windows():
    full = stray_light_mag_map((64, 64), PIX_DEG, direction_deg=225.0, edge_mag_per_arcsec2=17.0,
                               falloff_mag_per_deg=1.0)
    assert full[0, 0] == full.min()                                   # towards −u, −v: the top-left corner
    np.testing.assert_allclose(full[0, 0], 17.0 + np.sqrt(0.5) * PIX_DEG)  # its centre is √½ px inside the corner
    win = stray_light_mag_map((64, 64), PIX_DEG, direction_deg=225.0, edge_mag_per_arcsec2=17.0,
                              falloff_mag_per_deg=1.0, rows=(10, 30), cols=(5, 60))
    np.testing.assert_allclose(win, full[10:30, 5:60], rtol=0, atol=1e-12)


def test_photons_per_pixel_follow_the_sky_background_formula():
    kw = {"zero_point_photons_per_s_cm2": 1.5e6, "aperture_area_cm2": 3.1416, "transmission": 0.7, "exposure_s": 0.1}
    pix_arcsec = PIX_DEG * 3600.0
    ph = surface_brightness_photons(np.array([18.0, 20.5]), lambda m: star_photons(m, **kw), pix_arcsec)
    assert np.isclose(ph[0] / ph[1], 10 ** (0.4 * 2.5))                 # 2.5 mag = 10×
    np.testing.assert_allclose(ph[0], 1.5e6 * 10 ** (-0.4 * 18.0) * 3.1416 * 0.7 * 0.1 * pix_arcsec**2, rtol=1e-12)
