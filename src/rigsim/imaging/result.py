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
    """Per-pixel noise of a frame in DN (EMVA 1288 linear camera, as `rigsim.detector`).

        variance_DN = K * max(expected_DN - offset_dn, 0) + (K * read_noise_e)**2 + extra_variance_dn2

    K = ``gain_dn_per_e`` (system gain, DN per electron). ``expected_DN`` includes the background
    (sky and dark signal, assumed Poisson) and the ``offset_dn`` black level (noise-free).
    ``extra_variance_dn2`` adds e.g. ADC quantisation (1/12 DN^2). ``quantum_dn``: the step
    between the values a frame can hold (1 DN; 16 DN for 12-bit codes written into 16-bit words).
    """

    gain_dn_per_e: float = 1.0
    read_noise_e: float = 0.0
    offset_dn: float = 0.0
    extra_variance_dn2: float = 0.0
    quantum_dn: float = 1.0

    def __post_init__(self) -> None:
        for name, lo_ok in (("gain_dn_per_e", lambda x: x > 0), ("read_noise_e", lambda x: x >= 0),
                            ("offset_dn", lambda x: True), ("extra_variance_dn2", lambda x: x >= 0),
                            ("quantum_dn", lambda x: x > 0)):
            val = getattr(self, name)
            if not (isinstance(val, (int, float, np.floating, np.integer)) and np.isfinite(val) and lo_ok(val)):
                rng = "> 0" if name in ("gain_dn_per_e", "quantum_dn") else (">= 0" if name != "offset_dn" else "finite")
                raise ValueError(f"NoiseModel.{name} must be {rng}, got {val!r}")

    @classmethod
    def from_detector(cls, cfg) -> "NoiseModel":
        """From any object with ``gain_dn_per_e``, ``read_noise_e`` and ``offset_dn`` (e.g.
        `rigsim.detector.DetectorConfig`), in the frame's DN: a detector that writes its codes
        MSB-aligned (``code_step_dn`` frame DN per code) has its gain and offset scaled by the step,
        and the quantisation variance step²/12 (1/12 DN² without one)."""
        step = float(getattr(cfg, "code_step_dn", 1))
        return cls(
            gain_dn_per_e=float(cfg.gain_dn_per_e) * step,
            read_noise_e=float(cfg.read_noise_e),
            offset_dn=float(getattr(cfg, "offset_dn", 0.0)) * step,
            extra_variance_dn2=step * step / 12.0,
            quantum_dn=step,
        )

    @property
    def read_noise_dn(self) -> float:
        return self.read_noise_e * self.gain_dn_per_e

    @property
    def min_variance_dn2(self) -> float:
        """Variance floor used for weights: (half an electron)^2 in DN^2."""
        return (0.5 * self.gain_dn_per_e) ** 2

    def variance(self, expected_dn: np.ndarray) -> np.ndarray:
        """Variance (DN^2) of pixels whose expected value is ``expected_dn``."""
        k = self.gain_dn_per_e
        return k * np.maximum(expected_dn - self.offset_dn, 0.0) + self.read_noise_dn**2 + self.extra_variance_dn2


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
