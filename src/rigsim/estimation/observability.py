"""Observability from the SVD of the measurement Jacobians (seed 004, eqs 20-22).

The patent: δz = H δx; with H = P Σ Qᵀ (SVD), ‖δz‖ ranges over [σ_min, σ_max]·‖δx‖, so larger
singular values mean that the same parameter error produces a larger change of the measurement:
better observability. rigsim reports two versions:

* ``raw``: singular values of H itself (the patent's definition). They depend on the units of
  the equations: an ADS row is the difference of two AD rows, so raw singular values of AD and
  ADS are not comparable as accuracy measures.
* ``whitened``: singular values of R^(−1/2) H (R the equations' covariance from the centroid noise).
  1/σᵢ is the 1σ error of the least-squares estimate along the i-th right singular vector, in
  the state's units (px): this is the version that predicts accuracy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rigsim.estimation.star_calibration import THETA_NAMES, frame_system

__all__ = ["Observability", "observability"]


@dataclass(frozen=True)
class Observability:
    model: str
    names: tuple[str, ...]
    sv_raw: np.ndarray            # singular values of the stacked H
    sv_whitened: np.ndarray       # singular values of the stacked R^(-1/2) H
    V_whitened: np.ndarray        # right singular vectors (rows), state order = names
    per_frame_sv_raw: np.ndarray  # (K, n) patent eq 21 per frame
    per_frame_sv_whitened: np.ndarray
    n_eq: int

    @property
    def sigma_along_singular_vectors(self) -> np.ndarray:
        return 1.0 / self.sv_whitened

    @property
    def condition_whitened(self) -> float:
        return float(self.sv_whitened[0] / self.sv_whitened[-1])


def observability(frames, theta, *, model: str = "ad", estimate=("u0", "v0"), weighting: str = "propagated",
                  p12=(0.0, 0.0), max_stars: int | None = None) -> Observability:
    est = [THETA_NAMES.index(e) for e in estimate]
    Hs, Ws, pr, pw = [], [], [], []
    for fo in frames:
        if max_stars is not None:
            fo = fo.brightest(max_stars)
        if len(fo) < 4:
            continue
        s = frame_system(fo, theta, model, weighting, p12)
        H = s.H[:, est]
        L = np.linalg.cholesky(s.R)
        Hw = np.linalg.solve(L, H)
        Hs.append(H)
        Ws.append(Hw)
        pr.append(np.linalg.svd(H, compute_uv=False))
        pw.append(np.linalg.svd(Hw, compute_uv=False))
    H = np.concatenate(Hs)
    Hw = np.concatenate(Ws)
    _, sw, Vt = np.linalg.svd(Hw, full_matrices=False)
    return Observability(model, tuple(estimate), np.linalg.svd(H, compute_uv=False), sw, Vt,
                         np.array(pr), np.array(pw), int(H.shape[0]))
