"""Poisson variates by inversion of the CDF: one uniform per value, so a value depends on its own
uniform and λ only (a tiny change of λ moves a count only when u sits at a CDF step)."""

from __future__ import annotations

import numpy as np

__all__ = ["poisson_inverse_cdf"]


def _walk(lam: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Inversion for small λ: the smallest k with u <= F(k), by walking up the CDF (in the
    precision of ``lam``: float32 sums the CDF to ~1e-7).

    Dense steps over all values while many are undecided, then steps over the undecided ones only,
    compacted whenever half of them are decided: the cost is ~ Σλ element-steps. A value whose u
    lies above the rounded CDF's top stops past the mode where the pmf falls below a quarter of the
    float epsilon (its tail holds less than the uniforms' resolution): a deep-tail count."""
    dt = lam.dtype.type
    past_mode = float(lam.max()) + 1.0
    tiny = dt(np.finfo(lam.dtype).eps / 4)  # a pmf below it no longer moves a CDF near 1
    p = np.exp(-lam)
    c = p.copy()
    m = u > c
    # counts as uint16 while walking (cheaper to add to), exact as floats at the end
    kt = np.uint16 if past_mode < 30000.0 else lam.dtype
    k = m.astype(kt)
    n_alive = int(np.count_nonzero(m))
    step = 0
    while 8 * n_alive > m.size:  # dense phase
        step += 1
        p *= lam
        p *= dt(1.0 / step)
        c += p
        np.greater(u, c, out=m)
        if step > past_mode:
            m &= p >= tiny
        k += m
        n_alive = int(np.count_nonzero(m))
    if not n_alive:
        return k.astype(lam.dtype, copy=False)
    act = np.flatnonzero(m)
    lam_a, u_a, p_a, c_a, k_a = lam[act], u[act], p[act], c[act], k[act]
    while True:
        step += 1
        p_a *= lam_a
        p_a *= dt(1.0 / step)
        c_a += p_a
        m = u_a > c_a
        if step > past_mode:
            m &= p_a >= tiny
        k_a += m
        n_alive = int(np.count_nonzero(m))
        if n_alive == 0:
            break
        if 2 * n_alive <= m.size:
            k[act] = k_a
            act, lam_a, u_a, p_a, c_a, k_a = act[m], lam_a[m], u_a[m], p_a[m], c_a[m], k_a[m]
    k[act] = k_a
    return k.astype(lam.dtype, copy=False)


def _cornish_fisher(lam: np.ndarray, u: np.ndarray) -> np.ndarray:
    from scipy import special

    lam = lam.astype(np.float64)
    if u.dtype == np.float32:  # 24-bit uniforms: the middle of each 2^-24 step
        z = special.ndtri(u.astype(np.float64) + 2.0 ** -25)
    else:
        z = special.ndtri(np.clip(u, 1e-300, 1 - 1e-16))
    g1, g2 = 1.0 / np.sqrt(lam), 1.0 / lam
    z2 = z * z
    x = z + g1 * (z2 - 1) / 6 + g2 * z * (z2 - 3) / 24 - g1 * g1 * z * (2 * z2 - 5) / 36
    return np.maximum(np.floor(lam + np.sqrt(lam) * x + 0.5), 0.0)


def poisson_inverse_cdf(lam: np.ndarray, u: np.ndarray, small: float = 30.0) -> np.ndarray:
    """Poisson(λ) variates from uniforms ``u`` by inverting the CDF (one uniform per value).

    float32 ``lam`` and ``u`` give float32 counts (the CDF summed in float32, ~1e-7), otherwise
    float64.

    λ ≤ ``small``: exact — a vectorised walk up the CDF over the still-undecided values (cost ∝ Σλ).
    λ > ``small``: the Cornish–Fisher quantile of the Poisson distribution to O(1/λ) (skewness and
    kurtosis terms), rounded to an integer (mean, variance and histogram tested against the exact
    distribution); the exact inverse (scipy's ppf) costs ~1 s per megapixel.
    """
    lam, u = np.asarray(lam), np.asarray(u)
    dt = np.float32 if lam.dtype == np.float32 and u.dtype == np.float32 else np.float64
    lam, u = lam.astype(dt, copy=False), u.astype(dt, copy=False)
    if lam.size == 0:
        return np.zeros(lam.shape, dt)
    if lam.max() <= small:
        return _walk(lam, u)
    if lam.min() > small:
        return _cornish_fisher(lam, u).astype(dt, copy=False)
    out = np.empty(lam.shape, dtype=dt)
    lo = lam <= small
    out[lo] = _walk(lam[lo], u[lo])
    hi = ~lo
    out[hi] = _cornish_fisher(lam[hi], u[hi])
    return out
