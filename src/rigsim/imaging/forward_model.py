"""Forward-model centroiding: fit a model image of the spot to the pixels by maximum likelihood.

A spot model is any callable ``model(u, v) -> (h, w)`` giving the unit-flux, pixel-integrated
image of a spot whose reference point (what the camera model projects) lies at frame position
(u, v), on the grid of the window being fitted. The expected DN of pixel k is
``mu_k = F * p_k(u, v) + B``; its variance is the detector's noise model at ``mu_k``. The fit
maximises the likelihood by iteratively reweighted Gauss–Newton (the weights follow the model,
which makes it the maximum-likelihood estimator of a shifted-Poisson pixel and the usual
quasi-likelihood one of a Poisson + Gaussian pixel). docs/forward-model.md has the reasoning.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from rigsim.imaging.result import NoiseModel

__all__ = ["ModelFit", "fit_spot_model", "model_crlb", "model_derivatives"]

SpotModel = Callable[[float, float], np.ndarray]
UNKNOWNS = ("u", "v", "flux", "background")


@dataclass(frozen=True)
class ModelFit:
    """The fitted spot: position (px, frame), flux (DN summed over the model) and background (DN per
    pixel), their covariance (4×4 in UNKNOWNS' order: the inverse Fisher information at the fit),
    and the fit's own judgement (χ² of the pixels against the noise model, its degrees of freedom)."""

    u: float
    v: float
    flux_dn: float
    background_dn: float
    cov: np.ndarray
    chi2: float
    dof: int
    iterations: int
    converged: bool
    effects: tuple[str, ...] = field(default=())
    problem: str | None = None

    @property
    def sigma_u(self) -> float:
        return float(math.sqrt(self.cov[0, 0])) if np.isfinite(self.cov[0, 0]) else math.nan

    @property
    def sigma_v(self) -> float:
        return float(math.sqrt(self.cov[1, 1])) if np.isfinite(self.cov[1, 1]) else math.nan

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def ok(self) -> bool:
        return self.problem is None


def model_derivatives(model: SpotModel, u: float, v: float, step_px: float = 1e-3):
    """(p, dp/du, dp/dv) by central differences; a model with a ``gradient(u, v)`` method gives its
    own."""
    grad = getattr(model, "gradient", None)
    if grad is not None:
        return grad(u, v)
    p = np.asarray(model(u, v), dtype=float)
    du = (np.asarray(model(u + step_px, v)) - np.asarray(model(u - step_px, v))) / (2 * step_px)
    dv = (np.asarray(model(u, v + step_px)) - np.asarray(model(u, v - step_px))) / (2 * step_px)
    return p, du, dv


def _weighted_squares(model, keep, y, w, u, v) -> float:
    """Σ w·(y − F·p − B)² at (u, v), with F and B solved for these weights."""
    p = np.asarray(model(u, v), dtype=float)[keep]
    A = np.stack([p, np.ones_like(p)])
    fb = np.linalg.solve((A * w) @ A.T, (A * w) @ y)
    r = y - fb @ A
    return float(np.sum(w * r * r))


def _fisher(p, du, dv, flux, var):
    J = np.stack([flux * du.ravel(), flux * dv.ravel(), p.ravel(), np.ones(p.size)])
    return (J / var.ravel()) @ J.T, J


def model_crlb(model: SpotModel, u: float, v: float, flux_dn: float, background_dn: float, noise: NoiseModel,
               *, mask: np.ndarray | None = None) -> np.ndarray:
    """The Cramér–Rao bound (4×4 covariance, UNKNOWNS' order) of a spot ``model`` at (u, v) with
    ``flux_dn`` and ``background_dn`` on the window, under ``noise``: the inverse Fisher information
    of the image (the Gaussian form with the model's variance, exact for a shifted-Poisson pixel)."""
    p, du, dv = model_derivatives(model, u, v)
    keep = np.ones(p.shape, bool) if mask is None else np.asarray(mask, bool)
    var = noise.variance(flux_dn * p + background_dn)
    F, _ = _fisher(p[keep], du[keep], dv[keep], flux_dn, var[keep])
    return np.linalg.inv(F)


def fit_spot_model(roi: np.ndarray, model: SpotModel, noise: NoiseModel, u0: float, v0: float, *,
                   flux0: float | None = None, background0: float | None = None, mask: np.ndarray | None = None,
                   max_iter: int = 30, tol_px: float = 1e-5, max_step_px: float = 1.0,
                   effects: tuple[str, ...] = ()) -> ModelFit:
    """Fit ``model`` (module docstring) to the window ``roi`` (DN) starting from (u0, v0), by
    maximum likelihood under ``noise``. ``mask``: the pixels that count (False: saturated, defective
    or another source's). Flux and background enter linearly and are solved exactly at every step
    (variable projection); the position takes damped Gauss–Newton steps of at most ``max_step_px``,
    until a step is below ``tol_px`` or 1 % of the position's σ.
    ``effects`` names what the model includes; it is copied into the result."""
    d = np.asarray(roi, dtype=float)
    keep = np.isfinite(d) if mask is None else (np.asarray(mask, bool) & np.isfinite(d))
    n = int(keep.sum())
    bad = np.full((4, 4), math.nan)
    if n <= len(UNKNOWNS):
        return ModelFit(math.nan, math.nan, math.nan, math.nan, bad, math.nan, 0, 0, False, effects,
                        f"{n} usable pixels: too few for {len(UNKNOWNS)} unknowns")
    y = d[keep]
    u, v = float(u0), float(v0)
    p = np.asarray(model(u, v), dtype=float)[keep]
    B = float(np.median(d[keep])) if background0 is None else float(background0)
    F = float(max(np.sum(y - B), 1e-9)) if flux0 is None else float(flux0)
    var = noise.variance(F * p + B)
    converged, it = False, 0
    for it in range(1, max_iter + 1):
        p, du, dv = (np.asarray(a, dtype=float)[keep] for a in model_derivatives(model, u, v))
        w = 1.0 / var
        # the linear unknowns at this position: weighted least squares of [p, 1]
        A = np.stack([p, np.ones_like(p)])
        F, B = np.linalg.solve((A * w) @ A.T, (A * w) @ y)
        r = y - F * p - B
        J = np.stack([F * du, F * dv, p, np.ones_like(p)])
        H = (J * w) @ J.T
        g = (J * w) @ r
        try:
            step = np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            break
        duv = step[:2]
        s = float(np.max(np.abs(duv)))
        if s > max_step_px:
            duv = duv * (max_step_px / s)
        # a step that does not lower the weighted squares (these weights) is halved: no limit cycles
        now = float(np.sum(w * r * r))
        for _ in range(6):
            if _weighted_squares(model, keep, y, w, u + float(duv[0]), v + float(duv[1])) <= now:
                break
            duv = duv / 2.0
        s = float(np.max(np.abs(duv)))
        u, v = u + float(duv[0]), v + float(duv[1])
        var = noise.variance(np.maximum(F * p + B, 0.0))  # weights from the model (IRLS)
        # converged: a step below tol_px, or below 1 % of the position's own σ (a faint spot's
        # reweighted steps shrink slowly, far below what the data can tell)
        sig = np.sqrt(np.abs(np.diag(np.linalg.inv(H))[:2]))
        if s < tol_px or s < 0.01 * float(np.min(sig)):
            converged = True
            break
    p, du, dv = (np.asarray(a, dtype=float)[keep] for a in model_derivatives(model, u, v))
    A = np.stack([p, np.ones_like(p)])
    w = 1.0 / noise.variance(np.maximum(F * p + B, 0.0))
    F, B = np.linalg.solve((A * w) @ A.T, (A * w) @ y)
    mu = F * p + B
    var = noise.variance(np.maximum(mu, 0.0))
    chi2 = float(np.sum((y - mu) ** 2 / var))
    H, _ = _fisher(p, du, dv, F, var)
    try:
        cov = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        cov = bad
    problem = None
    if not converged:
        problem = f"the fit did not converge in {max_iter} iterations"
    elif not (np.isfinite(u) and np.isfinite(v)) or F <= 0:
        problem = "no spot (the fitted flux is not positive)"
    return ModelFit(u, v, float(F), float(B), cov, chi2, n - len(UNKNOWNS), it, converged, effects, problem)
