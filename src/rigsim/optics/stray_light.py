"""A stray-light gradient across a camera's field: light from a bright source outside the field
(the sunlit Earth's limb, the Sun near its exclusion angle) scattered by the baffle and the
optics onto the detector.

Modelled, not rendered: the scattered surface brightness falls off exponentially with the angle
from the field edge nearest the source, i.e. linearly in magnitudes per square arcsecond:
``μ(s) = μ_edge + k · s`` with s the angular distance (degrees) from that edge. docs/effects.md
gives the default values.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["stray_light_mag_map", "surface_brightness_photons"]


def stray_light_mag_map(shape_hw: tuple[int, int], pixel_deg: float, *, direction_deg: float,
                        edge_mag_per_arcsec2: float, falloff_mag_per_deg: float,
                        rows: tuple[int, int] | None = None, cols: tuple[int, int] | None = None) -> np.ndarray:
    """Surface brightness (mag/arcsec²) of the stray light at each pixel of the window ``rows`` ×
    ``cols`` (default the whole detector of ``shape_hw``). ``direction_deg``: direction towards
    the source in the image, from +u towards +v."""
    H, W = int(shape_hw[0]), int(shape_hw[1])
    r0, r1 = (0, H) if rows is None else (int(rows[0]), int(rows[1]))
    c0, c1 = (0, W) if cols is None else (int(cols[0]), int(cols[1]))
    c, s = math.cos(math.radians(direction_deg)), math.sin(math.radians(direction_deg))
    cu, cv = (W - 1) / 2.0, (H - 1) / 2.0
    p_edge = max((u - cu) * c + (v - cv) * s for u in (-0.5, W - 0.5) for v in (-0.5, H - 0.5))
    u = np.arange(c0, c1, dtype=np.float64)[None, :] - cu
    v = np.arange(r0, r1, dtype=np.float64)[:, None] - cv
    dist_deg = (p_edge - (u * c + v * s)) * float(pixel_deg)
    return float(edge_mag_per_arcsec2) + float(falloff_mag_per_deg) * dist_deg


def surface_brightness_photons(mag_per_arcsec2, photons_of_mag, pixel_arcsec: float) -> np.ndarray:
    """Photons per pixel from a surface brightness: ``photons_of_mag(μ)`` (photons of a source of
    magnitude μ over the exposure) times the pixel's area in arcsec²."""
    return np.asarray(photons_of_mag(np.asarray(mag_per_arcsec2, dtype=np.float64))) * float(pixel_arcsec) ** 2
