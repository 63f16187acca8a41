"""Poisson variates by inversion of the CDF: one uniform per value, so a value depends on its own
uniform and λ only (a tiny change of λ moves a count only when u sits at a CDF step)."""

from __future__ import annotations

import numpy as np

__all__ = ["poisson_inverse_cdf"]


def _walk(lam: np.ndarray, u: np.ndarray, out: np.ndarray | None = None, work=None) -> np.ndarray:
    """Inversion for small λ: the smallest k with u <= F(k), by walking up the CDF (in the
    precision of ``lam``: float32 sums the CDF to ~1e-7).

    Dense steps over all values while more than 1 in 32 is undecided, then steps over the
    undecided ones only, compacted whenever half of them are decided: the cost is ~ Σλ
    element-steps. A value whose u lies above the rounded CDF's top stops past the mode where the
    pmf falls below a quarter of the float epsilon (its tail holds less than the uniforms'
    resolution): a deep-tail count. ``out``: the counts' array (``lam``'s dtype); ``work``: a
    :class:`~rigsim.detector.scratch.Scratch` for the walk's arrays."""
    shape = lam.shape
    lam, u = lam.reshape(-1), u.reshape(-1)
    dt = lam.dtype.type
    size = lam.size
    past_mode = float(lam.max()) + 1.0
    tiny = dt(np.finfo(lam.dtype).eps / 4)  # a pmf below it no longer moves a CDF near 1
    # counts as uint16 while walking (cheaper to add to), exact as floats at the end
    kt = np.uint16 if past_mode < 30000.0 else lam.dtype
    if work is not None:
        p, c = work.get("walk_p", size, lam.dtype), work.get("walk_c", size, lam.dtype)
        m, k = work.get("walk_m", size, bool), work.get("walk_k", size, kt)
    else:
        p, c, m, k = np.empty_like(lam), np.empty_like(lam), np.empty(size, bool), np.empty(size, kt)
    np.negative(lam, out=p)
    np.exp(p, out=p)
    np.copyto(c, p)
    np.greater(u, c, out=m)
    np.copyto(k, m)
    n_alive = int(np.count_nonzero(m))
    step = 0
    while 32 * n_alive > size:  # dense phase
        step += 1
        p *= lam
        p *= dt(1.0 / step)
        c += p
        np.greater(u, c, out=m)
        if step > past_mode:
            m &= p >= tiny
        k += m
        n_alive = int(np.count_nonzero(m))
    if n_alive:
        act = np.flatnonzero(m)
        lam_a, u_a, p_a, c_a, k_a = lam[act], u[act], p[act], c[act], k[act]
        while True:
            step += 1
            p_a *= lam_a
            p_a *= dt(1.0 / step)
            c_a += p_a
            m_a = u_a > c_a
            if step > past_mode:
                m_a &= p_a >= tiny
            k_a += m_a
            n_alive = int(np.count_nonzero(m_a))
            if n_alive == 0:
                break
            if 2 * n_alive <= m_a.size:
                k[act] = k_a
                act, lam_a, u_a, p_a, c_a, k_a = act[m_a], lam_a[m_a], u_a[m_a], p_a[m_a], c_a[m_a], k_a[m_a]
        k[act] = k_a
    if out is None:
        return k.astype(lam.dtype, copy=work is not None).reshape(shape)
    np.copyto(out.reshape(-1), k)
    return out


def _cornish_fisher(lam: np.ndarray, u: np.ndarray, work=None) -> np.ndarray:
    """floor(λ + √λ·x + 0.5), x = z + g1(z² − 1)/6 + g2·z(z² − 3)/24 − g1²·z(2z² − 5)/36 with
    g1 = 1/√λ, g2 = 1/λ and z the normal quantile of u; evaluated in place in eight float64
    arrays (``work``'s when given: the result is then one of them)."""
    from scipy import special

    n = lam.size
    lam, u = lam.reshape(-1), u.reshape(-1)
    a = [np.empty(n) if work is None else work.get(f"cf{i}", n, np.float64) for i in range(8)]
    lam64, z, s, g1, g2, z2, x, f = a
    np.copyto(lam64, lam)
    if u.dtype == np.float32:  # 24-bit uniforms: the middle of each 2^-24 step
        np.copyto(z, u)
        z += 2.0 ** -25
    else:  # 53-bit uniforms: u = 0 stands for the middle of its step (at 1e-300, z = −37, the expansion turns back up)
        np.clip(u, 2.0 ** -54, 1 - 1e-16, out=z)
    special.ndtri(z, out=z)
    np.sqrt(lam64, out=s)
    np.divide(1.0, s, out=g1)
    np.divide(1.0, lam64, out=g2)
    np.multiply(z, z, out=z2)
    np.subtract(z2, 1, out=x)        # g1·(z² − 1)/6 + z
    x *= g1
    x /= 6
    x += z
    np.subtract(z2, 3, out=f)        # + g2·z·(z² − 3)/24
    g2 *= z
    g2 *= f
    g2 /= 24
    x += g2
    g1 *= g1                         # − g1²·z·(2z² − 5)/36
    g1 *= z
    z2 *= 2
    z2 -= 5
    g1 *= z2
    g1 /= 36
    x -= g1
    s *= x
    s += lam64
    s += 0.5
    np.floor(s, out=s)
    return np.maximum(s, 0.0, out=s)


def poisson_inverse_cdf(lam: np.ndarray, u: np.ndarray, small: float = 30.0, *, out: np.ndarray | None = None,
                        work=None) -> np.ndarray:
    """Poisson(λ) variates from uniforms ``u`` by inverting the CDF (one uniform per value).

    float32 ``lam`` and ``u`` give float32 counts (the CDF summed in float32, ~1e-7), otherwise
    float64.

    λ ≤ ``small``: exact — a vectorised walk up the CDF over the still-undecided values (cost ∝ Σλ).
    λ > ``small``: the Cornish–Fisher quantile of the Poisson distribution to O(1/λ) (skewness and
    kurtosis terms), rounded to an integer (mean, variance and histogram tested against the exact
    distribution); the exact inverse (scipy's ppf) costs ~1 s per megapixel.

    ``out``: an array of ``lam``'s shape and the result's dtype to write the counts into;
    ``work``: a :class:`~rigsim.detector.scratch.Scratch` for the temporaries, so that a caller
    looping over blocks allocates nothing per block.
    """
    lam, u = np.asarray(lam), np.asarray(u)
    dt = np.float32 if lam.dtype == np.float32 and u.dtype == np.float32 else np.float64
    lam, u = lam.astype(dt, copy=False), u.astype(dt, copy=False)
    if lam.size == 0:
        return np.zeros(lam.shape, dt) if out is None else out
    if lam.max() <= small:
        return _walk(lam, u, out, work)
    if lam.min() > small:
        if out is None:
            return _cornish_fisher(lam, u).reshape(lam.shape).astype(dt, copy=False)
        np.copyto(out, _cornish_fisher(lam, u, work).reshape(lam.shape), casting="same_kind")
        return out
    if out is None:
        out = np.empty(lam.shape, dtype=dt)
    if work is None:
        lo = lam <= small
        out[lo] = _walk(lam[lo], u[lo])
        hi = ~lo
        out[hi] = _cornish_fisher(lam[hi], u[hi])
        return out
    n = lam.size
    lo = np.less_equal(lam, small, out=work.get("lo", n, bool).reshape(lam.shape))
    hi = np.logical_not(lo, out=work.get("hi", n, bool).reshape(lam.shape))
    n_lo = int(np.count_nonzero(lo))
    for mask, count, fn in ((lo, n_lo, _walk), (hi, n - n_lo, _cornish_fisher)):
        lam_m = np.compress(mask.reshape(-1), lam.reshape(-1), out=work.get("mix_lam", count, dt))
        u_m = np.compress(mask.reshape(-1), u.reshape(-1), out=work.get("mix_u", count, dt))
        out[mask] = fn(lam_m, u_m, work=work)
    return out
