"""Refraction against an independent formula: Saemundsson's R = 1.02′ / tan(h + 10.3/(h + 5.11))
(h in degrees, 1010 hPa, 10 °C), scaled by (P/1010)(283/(273 + T)). The classical formulae differ
from one another and from ERFA's model by a few per cent (their refraction constants: 56–60″ at
10 °C), so 6 % is asked: enough to catch a unit, sign, pressure or direction error."""

from __future__ import annotations

import numpy as np
import pytest

from rigsim.optics.refraction import Site, apparent_directions, standard_pressure_hpa


def _saemundsson_arcmin(h_deg, p_hpa, t_c):
    return 1.02 / np.tan(np.radians(h_deg + 10.3 / (h_deg + 5.11))) * (p_hpa / 1010.0) * (283.0 / (273.0 + t_c))


def _altaz(dirs, site, t):
    import astropy.units as u
    from astropy.coordinates import ICRS, AltAz, CartesianRepresentation, EarthLocation, SkyCoord
    from astropy.time import Time

    loc = EarthLocation.from_geodetic(site.longitude_deg * u.deg, site.latitude_deg * u.deg, site.height_m * u.m)
    c = SkyCoord(CartesianRepresentation(*np.asarray(dirs).T), frame=ICRS())
    return c.transform_to(AltAz(obstime=Time(t), location=loc, pressure=0 * u.hPa))


@pytest.mark.parametrize("alt", [20.0, 40.0, 70.0])
def test_stars_are_lifted_by_the_refraction_and_nothing_else(alt):
    import astropy.units as u
    from astropy.coordinates import ICRS, AltAz, EarthLocation, SkyCoord
    from astropy.time import Time

    site = Site(52.0, 5.0, 0.0, pressure_hpa=1010.0, temperature_c=10.0, relative_humidity=0.0, wavelength_um=0.574)
    t = "2019-07-29T20:47:26"
    loc = EarthLocation.from_geodetic(5.0 * u.deg, 52.0 * u.deg, 0 * u.m)
    # a star at the chosen altitude (no air), then seen through the air
    az = np.array([30.0, 150.0, 270.0])
    star = SkyCoord(az=az * u.deg, alt=np.full(3, alt) * u.deg,
                    frame=AltAz(obstime=Time(t), location=loc, pressure=0 * u.hPa)).transform_to(ICRS())
    d = star.cartesian.xyz.value.T
    seen = _altaz(apparent_directions(d, site, t), site, t)
    lift = (seen.alt.deg - alt) * 60.0
    assert np.allclose(lift, _saemundsson_arcmin(alt, 1010.0, 10.0), rtol=0.06, atol=0.01)
    assert np.allclose(seen.az.deg, az, atol=1e-6)  # straight up, towards the zenith


def test_thin_air_refracts_less_and_the_standard_atmosphere_is_the_isa():
    assert standard_pressure_hpa(0.0) == pytest.approx(1013.25)
    assert standard_pressure_hpa(2000.0) == pytest.approx(794.95, abs=0.1)  # ISA table
    d = np.array([[0.3, 0.4, np.sqrt(1 - 0.25)]])
    lo = apparent_directions(d, Site(30.0, 0.0, 4000.0), "2020-01-01T00:00:00")
    hi = apparent_directions(d, Site(30.0, 0.0, 0.0), "2020-01-01T00:00:00")
    assert np.arccos(np.clip(lo[0] @ d[0], -1, 1)) < np.arccos(np.clip(hi[0] @ d[0], -1, 1))
    assert apparent_directions(np.zeros((0, 3)), Site(0, 0), "2020-01-01T00:00:00").shape == (0, 3)
