"""Atmospheric refraction for frames taken from the ground: the directions in which the catalogue's
stars are seen from a site at a time, expressed back in ICRS so that a camera's attitude and
intrinsics are fitted to what the atmosphere lets it see.

astropy does the work (ERFA's refraction model in its AltAz frame, with pressure, temperature,
humidity and wavelength): each star goes ICRS → AltAz with the air (refracted) → ICRS through the
same AltAz frame without air. Everything else of the transformation (precession, nutation,
aberration, the Earth's rotation) goes there and back and cancels; only the refraction remains: a
lift towards the zenith of about 58″ · cot(altitude) near 1000 hPa. On an 11° field at 40° altitude
it squeezes the field by ~30″ along the vertical, a fraction of a pixel that a single focal length
cannot absorb.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Site", "apparent_directions", "standard_pressure_hpa"]


@dataclass(frozen=True)
class Site:
    """Where and in what air the frames were taken."""

    latitude_deg: float
    longitude_deg: float
    height_m: float = 0.0
    pressure_hpa: float | None = None   # None: the standard atmosphere at ``height_m``
    temperature_c: float = 10.0
    relative_humidity: float = 0.5
    wavelength_um: float = 0.65         # the band's effective wavelength (a silicon sensor, no filter)

    @property
    def pressure(self) -> float:
        return standard_pressure_hpa(self.height_m) if self.pressure_hpa is None else float(self.pressure_hpa)


def standard_pressure_hpa(height_m: float) -> float:
    """The International Standard Atmosphere's pressure at a height (troposphere)."""
    return 1013.25 * (1.0 - 2.25577e-5 * float(height_m)) ** 5.25588


def apparent_directions(dirs_icrs: np.ndarray, site: Site, time_utc) -> np.ndarray:
    """Unit vectors (N, 3): where the stars of ICRS directions ``dirs_icrs`` are seen from ``site`` at
    ``time_utc`` (an ISO string or an astropy Time), as ICRS directions (see the module docstring)."""
    import astropy.units as u
    from astropy.coordinates import ICRS, AltAz, CartesianRepresentation, EarthLocation, SkyCoord
    from astropy.time import Time

    d = np.asarray(dirs_icrs, float)
    if d.size == 0:
        return d.reshape(0, 3)
    t = time_utc if isinstance(time_utc, Time) else Time(str(time_utc), scale="utc")
    loc = EarthLocation.from_geodetic(site.longitude_deg * u.deg, site.latitude_deg * u.deg, site.height_m * u.m)
    c = SkyCoord(CartesianRepresentation(d[:, 0], d[:, 1], d[:, 2]), frame=ICRS())
    air = AltAz(obstime=t, location=loc, pressure=site.pressure * u.hPa, temperature=site.temperature_c * u.deg_C,
                relative_humidity=site.relative_humidity, obswl=site.wavelength_um * u.micron)
    seen = c.transform_to(air)
    vac = AltAz(obstime=t, location=loc, pressure=0 * u.hPa)
    back = SkyCoord(az=seen.az, alt=seen.alt, frame=vac).transform_to(ICRS())
    v = back.cartesian.xyz.value.T
    return v / np.linalg.norm(v, axis=1, keepdims=True)
