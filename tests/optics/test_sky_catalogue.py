"""Hipparcos 2 parsing, proper motion against astropy, magnitude → photons."""

import numpy as np
import pytest

from rigsim.optics.sky import load_hipparcos, photon_rate, propagate, radec_to_unit


def test_parse_counts_and_first_record():
    cat = load_hipparcos()
    assert len(cat) == 117955  # I/311 ReadMe: 117,955 entries
    # first line of hip2.dat: HIP 1, RA 0.0000159148 rad, Dec 0.0190068680 rad, Plx 4.55, pm -4.55/-1.19, Hp 9.2043
    assert cat.hip[0] == 1
    assert cat.ra_rad[0] == pytest.approx(0.0000159148, abs=1e-12)
    assert cat.dec_rad[0] == pytest.approx(0.0190068680, abs=1e-12)
    assert (cat.parallax_mas[0], cat.pmra_masyr[0], cat.pmdec_masyr[0]) == (4.55, -4.55, -1.19)
    assert cat.hp_mag[0] == pytest.approx(9.2043)
    # Sirius (HIP 32349) is the brightest star: Hp ≈ -1.09
    i = int(np.argmin(cat.hp_mag))
    assert cat.hip[i] == 32349 and cat.hp_mag[i] == pytest.approx(-1.0876, abs=1e-4)


def test_proper_motion_matches_astropy():
    """Zero-radial-velocity space motion vs astropy's apply_space_motion: < 0.05 mas over 33.75 yr
    (the two differ only by light-time/time-scale details far below Hipparcos' ~1 mas errors)."""
    pytest.importorskip("astropy")
    import astropy.units as u
    from astropy.coordinates import SkyCoord
    from astropy.time import Time

    cat = load_hipparcos()
    hips = [87937, 24186, 57939, 32349, 1]  # Barnard's star (10.4″/yr), Kapteyn's, Groombridge 1830, Sirius, HIP 1
    idx = np.array([int(np.flatnonzero(cat.hip == h)[0]) for h in hips])
    ours = propagate(cat.ra_rad[idx], cat.dec_rad[idx], cat.pmra_masyr[idx], cat.pmdec_masyr[idx], 2025.0 - 1991.25)
    c = SkyCoord(ra=cat.ra_rad[idx] * u.rad, dec=cat.dec_rad[idx] * u.rad, pm_ra_cosdec=cat.pmra_masyr[idx] * u.mas / u.yr,
                 pm_dec=cat.pmdec_masyr[idx] * u.mas / u.yr, distance=(1000.0 / np.abs(cat.parallax_mas[idx])) * u.pc,
                 radial_velocity=0 * u.km / u.s, obstime=Time(1991.25, format="jyear", scale="tt"), frame="icrs")
    c2 = c.apply_space_motion(new_obstime=Time(2025.0, format="jyear", scale="tt"))
    theirs = radec_to_unit(c2.ra.rad, c2.dec.rad)
    ang_mas = np.degrees(np.arccos(np.clip(np.sum(ours * theirs, 1), -1, 1))) * 3.6e6
    assert np.all(ang_mas < 0.05), ang_mas
    moved = np.degrees(np.arccos(np.clip(np.sum(ours * radec_to_unit(cat.ra_rad[idx], cat.dec_rad[idx]), 1), -1, 1))) * 3600
    assert moved[0] == pytest.approx(10.39 * 33.75, rel=0.01)  # Barnard's star moved ≈ 350″


def test_photons_scale_with_magnitude():
    assert photon_rate(0.0, 1.5e6) == pytest.approx(1.5e6)
    assert photon_rate(5.0, 1.5e6) == pytest.approx(1.5e6 / 100.0)  # 5 mag = factor 100 by definition
