"""Result types shared by the imaging package: quality flags, centroids, noise model.

Pixel convention (project-wide): pixel (0, 0)'s *centre* is at (u, v) = (0.0, 0.0); u runs along
columns (+u right), v along rows (+v down); arrays are indexed ``img[v, u]``; positions are
returned as (u, v). All positions and their uncertainties are in pixels; fluxes and backgrounds
are in the units of the input array (DN unless stated otherwise).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Flag", "NoiseModel", "Centroid", "CentroidBatch"]


class Flag(enum.IntFlag):
    """Quality flags. A position is usable when ``INVALID`` is not set; any other flag is a
    warning that the position may be less accurate than its ``sigma`` says."""

    OK = 0
    SATURATED = 1  #: at least one pixel of the spot at or above the saturation level
    EDGE = 2  #: the spot is cut by the frame (or ROI) edge, or lies within ~2 sigma of it
    FAINT = 4  #: estimated flux / sigma_flux below the method's ``min_snr``
    BLENDED = 8  #: a second significant peak in the ROI / a neighbour closer than the ROI size
    NAN = 16  #: non-finite (or |value| > 1e30) pixels were present and ignored
    EMPTY = 32  #: no signal: nothing above the threshold, zero or negative flux
    NOT_CONVERGED = 64  #: an iterative method stopped at its iteration limit
    POOR_FIT = 128  #: model fit with reduced chi-square far above 1 (wrong PSF, blend, artefact)
    INVALID = 256  #: no position could be computed; u and v are NaN


@dataclass(frozen=True)
class NoiseModel:
    """Per-pixel noise of a bias-subtracted frame in DN.

    variance_DN = max(expected_DN, 0) / gain_e_per_dn + (read_noise_e / gain_e_per_dn)**2

    ``expected_DN`` includes the background (sky/dark), which is assumed to be Poisson. Subtract
    any electronic offset (bias) before using a NoiseModel.
    """

    gain_e_per_dn: float = 1.0
    read_noise_e: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.gain_e_per_dn) and self.gain_e_per_dn > 0):
            raise ValueError(f"NoiseModel.gain_e_per_dn must be finite and > 0, got {self.gain_e_per_dn!r}")
        if not (np.isfinite(self.read_noise_e) and self.read_noise_e >= 0):
            raise ValueError(f"NoiseModel.read_noise_e must be finite and >= 0, got {self.read_noise_e!r}")

    @property
    def read_noise_dn(self) -> float:
        return self.read_noise_e / self.gain_e_per_dn

    def variance(self, expected_dn: np.ndarray) -> np.ndarray:
        """Variance (DN^2) of pixels whose expected value is ``expected_dn``."""
        return np.maximum(expected_dn, 0.0) / self.gain_e_per_dn + self.read_noise_dn**2


@dataclass(frozen=True)
class Centroid:
    """One spot position (u, v) in px with 1-sigma uncertainties, flux, background and flags."""

    u: float
    v: float
    sigma_u: float
    sigma_v: float
    flux: float
    background: float
    flags: Flag
    method: str = ""

    @property
    def uv(self) -> np.ndarray:
        return np.array([self.u, self.v])

    @property
    def valid(self) -> bool:
        return not (self.flags & Flag.INVALID)


@dataclass(frozen=True)
class CentroidBatch:
    """Positions of N spots as arrays of shape (N,); ``CentroidBatch[i]`` gives a `Centroid`."""

    u: np.ndarray
    v: np.ndarray
    sigma_u: np.ndarray
    sigma_v: np.ndarray
    flux: np.ndarray
    background: np.ndarray
    flags: np.ndarray  # int array of Flag bits
    method: str = ""
    extra: dict = field(default_factory=dict)  # method-specific arrays (e.g. sigma_px, chi2_red, n_iter)

    def __len__(self) -> int:
        return int(self.u.shape[0])

    def __getitem__(self, i: int) -> Centroid:
        return Centroid(
            u=float(self.u[i]),
            v=float(self.v[i]),
            sigma_u=float(self.sigma_u[i]),
            sigma_v=float(self.sigma_v[i]),
            flux=float(self.flux[i]),
            background=float(self.background[i]),
            flags=Flag(int(self.flags[i])),
            method=self.method,
        )

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    @property
    def uv(self) -> np.ndarray:
        """(N, 2) array of (u, v)."""
        return np.stack([self.u, self.v], axis=-1)

    @property
    def valid(self) -> np.ndarray:
        return (self.flags & Flag.INVALID) == 0

    def has(self, flag: Flag) -> np.ndarray:
        """Boolean (N,) array: which spots carry ``flag``."""
        return (self.flags & int(flag)) != 0

    def shifted(self, du: np.ndarray, dv: np.ndarray) -> "CentroidBatch":
        """Same batch with positions offset by (du, dv) (e.g. ROI origin -> frame coordinates)."""
        return CentroidBatch(
            u=self.u + du,
            v=self.v + dv,
            sigma_u=self.sigma_u,
            sigma_v=self.sigma_v,
            flux=self.flux,
            background=self.background,
            flags=self.flags,
            method=self.method,
            extra=self.extra,
        )
