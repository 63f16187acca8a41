"""The forward-model star centroider: each star's window fitted with the image its optics predict,
by maximum likelihood under the detector's noise model.

Model of pixel k: μ_k = F · p_k(u, v) + B (DN), with p the unit-flux, pixel-integrated star image of
a model from :mod:`rigsim.optics.star_image_model` (a Gaussian, or the traced lens's PSF at the
star's field position), bound to the stars beforehand. Unknowns u, v, F, B. Iteratively reweighted
Gauss–Newton: the weights are 1 / :meth:`rigsim.imaging.NoiseModel.variance` of the current model
(the Poisson-plus-read-noise likelihood in its Gaussian form, whose maximum this is), a step is
halved while it raises χ². σ_u, σ_v are the inverse Fisher matrix at the solution (the Cramér–Rao
bound at the fitted parameters); χ²/dof says how well the model explains the pixels.

The model's reference point is the star's geometric image point (what the camera model projects),
so the positions need no centroid-shift map.
"""

from __future__ import annotations

import numpy as np

from .result import CentroidBatch, Flag, NoiseModel

__all__ = ["fit_star_models"]


def fit_star_models(stack, origin_uv, model, noise: NoiseModel, u0, v0, *, flags=None, saturation: float | None = None,
                    max_iter: int = 25, tol_px: float = 1e-4, min_snr: float = 5.0) -> CentroidBatch:
    """Fit ``model`` (a bound model: ``model.pixels(u, v, origin_uv, shape_hw)`` → (p, ∂p/∂u, ∂p/∂v), each
    (N, h, w); ``model.subset(idx)`` the same for some of its stars) to the windows ``stack`` (N, h, w, DN) whose pixel (0, 0) lies at ``origin_uv`` (N, 2),
    from the start positions (``u0``, ``v0``) (frame px). Saturated (≥ ``saturation``) and non-finite
    pixels are left out. Returns frame positions with their inverse-Fisher σ; ``extra`` holds
    sigma_flux, chi2_red, dof and n_iter. Flags: ``flags`` (per star, kept), INVALID (no solution,
    flux ≤ 0, position off its window), FAINT (SNR < ``min_snr``), NOT_CONVERGED, POOR_FIT (χ²/dof
    beyond 1 + 5√(2/dof), the Gaussian fit's test)."""
    data = np.asarray(stack, dtype=float)
    n, h, w = data.shape
    o = np.asarray(origin_uv, dtype=float).reshape(n, 2)
    fl = np.zeros(n, np.int64) if flags is None else np.asarray(flags, np.int64).copy()
    use = np.isfinite(data)
    if saturation is not None:
        sat = use & (data >= float(saturation))
        fl[sat.any(axis=(1, 2))] |= int(Flag.SATURATED)
        use &= ~sat
    fl[(~np.isfinite(data)).any(axis=(1, 2))] |= int(Flag.NAN)
    d = np.where(use, data, 0.0)
    u = np.asarray(u0, dtype=float).copy()
    v = np.asarray(v0, dtype=float).copy()
    # start: the background from the window's border, the flux from the sum above it
    ring = np.zeros((h, w), bool)
    ring[0, :] = ring[-1, :] = ring[:, 0] = ring[:, -1] = True
    rv = np.where(use[:, ring], d[:, ring], np.nan)
    with np.errstate(all="ignore"):
        B = np.nanmedian(rv, axis=1) if n else np.zeros(0)
    B = np.where(np.isfinite(B), B, noise.offset_dn)
    F = np.maximum(np.sum(np.where(use, d - B[:, None, None], 0.0), axis=(1, 2)), 1.0 * noise.gain_dn_per_e)
    floor = noise.min_variance_dn2
    active = (fl & int(Flag.INVALID)) == 0
    n_iter = np.zeros(n, np.int64)
    converged = np.zeros(n, bool)

    def evaluate(u_, v_, F_, B_, idx):
        p, pu, pv = model_pixels(u_, v_, idx)
        mu = F_[:, None, None] * p + B_[:, None, None]
        return p, pu, pv, mu

    def model_pixels(u_, v_, idx):
        return (model if len(idx) == n else model.subset(idx)).pixels(u_, v_, o[idx], (h, w))

    idx_all = np.arange(n)
    for it in range(max_iter):
        idx = idx_all[active & ~converged]
        if idx.size == 0:
            break
        uu, vv, FF, BB = u[idx], v[idx], F[idx], B[idx]
        p, pu, pv, mu = evaluate(uu, vv, FF, BB, idx)
        wts = np.where(use[idx], 1.0 / np.maximum(noise.variance(mu), floor), 0.0)
        r = d[idx] - mu
        chi0 = np.sum(wts * r * r, axis=(1, 2))
        J = np.stack([FF[:, None, None] * pu, FF[:, None, None] * pv, p, np.ones_like(p)], axis=1).reshape(idx.size, 4, -1)
        Wf = wts.reshape(idx.size, -1)
        A = np.einsum("npk,nqk->npq", J * Wf[:, None, :], J)
        g = np.einsum("npk,nk->np", J * Wf[:, None, :], r.reshape(idx.size, -1))
        try:
            step = np.linalg.solve(A + 1e-12 * np.eye(4) * np.trace(A, axis1=1, axis2=2)[:, None, None], g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            step = np.stack([np.linalg.lstsq(a, b, rcond=None)[0] for a, b in zip(A, g)])
        step[:, :2] = np.clip(step[:, :2], -1.0, 1.0)   # at most a pixel per iteration
        lam = np.ones(idx.size)
        for _ in range(6):   # halve the step while it raises χ² (weights held)
            t = lam[:, None] * step
            _, _, _, mu1 = evaluate(uu + t[:, 0], vv + t[:, 1], FF + t[:, 2], BB + t[:, 3], idx)
            r1 = d[idx] - mu1
            worse = np.sum(wts * r1 * r1, axis=(1, 2)) > chi0 * (1 + 1e-12) + 1e-9
            if not worse.any():
                break
            lam = np.where(worse, lam * 0.5, lam)
        t = lam[:, None] * step
        u[idx], v[idx], F[idx], B[idx] = uu + t[:, 0], vv + t[:, 1], FF + t[:, 2], BB + t[:, 3]
        n_iter[idx] += 1
        converged[idx] = np.maximum(np.abs(t[:, 0]), np.abs(t[:, 1])) < tol_px
        off = ~np.isfinite(u[idx]) | ~np.isfinite(v[idx]) | (np.abs(u[idx] - o[idx, 0] - (w - 1) / 2) > w / 2) \
            | (np.abs(v[idx] - o[idx, 1] - (h - 1) / 2) > h / 2)
        active[idx[off]] = False
        fl[idx[off]] |= int(Flag.INVALID)
    # the inverse Fisher matrix and χ² at the solution
    su, sv, sF, chi2, dof = (np.full(n, np.nan) for _ in range(5))
    ok_idx = idx_all[(fl & int(Flag.INVALID)) == 0]
    if ok_idx.size:
        p, pu, pv, mu = evaluate(u[ok_idx], v[ok_idx], F[ok_idx], B[ok_idx], ok_idx)
        var = np.maximum(noise.variance(mu), floor)
        wts = np.where(use[ok_idx], 1.0 / var, 0.0)
        FF = F[ok_idx]
        J = np.stack([FF[:, None, None] * pu, FF[:, None, None] * pv, p, np.ones_like(p)], axis=1).reshape(ok_idx.size, 4, -1)
        A = np.einsum("npk,nqk->npq", J * wts.reshape(ok_idx.size, 1, -1), J)
        with np.errstate(all="ignore"):
            good = np.linalg.cond(A) < 1e14
            cov = np.full_like(A, np.nan)
            cov[good] = np.linalg.inv(A[good])
        su[ok_idx], sv[ok_idx], sF[ok_idx] = (np.sqrt(cov[:, i, i]) for i in range(3))
        r = d[ok_idx] - mu
        chi2[ok_idx] = np.sum(wts * r * r, axis=(1, 2))
        dof[ok_idx] = use[ok_idx].sum(axis=(1, 2)) - 4
        fl[ok_idx[~good]] |= int(Flag.INVALID)
    with np.errstate(all="ignore"):
        chi2_red = chi2 / dof
        snr = F / sF
        fl[~(F > 0)] |= int(Flag.EMPTY | Flag.INVALID)
        fl[~(snr >= min_snr)] |= int(Flag.FAINT)
        fl[chi2_red > 1.0 + 5.0 * np.sqrt(2.0 / np.maximum(dof, 1))] |= int(Flag.POOR_FIT)
    fl[~converged & ((fl & int(Flag.INVALID)) == 0)] |= int(Flag.NOT_CONVERGED)
    inv = (fl & int(Flag.INVALID)) != 0
    u, v, su, sv = (np.where(inv, np.nan, x) for x in (u, v, su, sv))
    return CentroidBatch(u, v, su, sv, F, B, fl, "model",
                         extra={"sigma_flux": sF, "chi2_red": chi2_red, "dof": dof, "n_iter": n_iter})

