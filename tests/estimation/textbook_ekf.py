"""The textbook extended Kalman filter the star calibration's filters are compared with: identity transition,
P += q²I before each frame, one update per frame of 4 stars or more, gain by numpy's solve, P⁺ = (I − KH)P and
NIS = νᵀS⁻¹ν. Written from the equations, not from rigsim's filter."""

from __future__ import annotations

import numpy as np

from rigsim.estimation.star_calibration import frame_system


def _fd_jacobian(fo, th, est, model, p12=(0.0, 0.0), equations="framework"):
    """H by central differences of the model's predicted centroids (steps 1e-3 px for f, u0, v0; 1e-6 for k1, k2)."""
    h0 = frame_system(fo, th, model, p12=p12, equations=equations).h
    H = np.empty((h0.size, len(est)))
    for c, p in enumerate(est):
        e = np.zeros(5)
        e[p] = 1e-3 if p < 3 else 1e-6
        H[:, c] = (frame_system(fo, th + e, model, p12=p12, equations=equations).h
                   - frame_system(fo, th - e, model, p12=p12, equations=equations).h) / (2 * e[p])
    return H


def _range_of(R):
    """U (M, r) and variances (r,) of R restricted to its range: the eigenvectors of R whose eigenvalues exceed
    1e-10 of the largest, each eigenvalue raised by 1e-9 of their mean (the regularisation run_ekf documents for
    propagated sets with more equations than independent angles). R = 0 has an empty range."""
    mu, U = np.linalg.eigh(R)
    keep = mu > 1e-10 * mu[-1] if mu[-1] > 0 else np.zeros(mu.size, bool)
    mu, U = mu[keep], U[:, keep]
    return U, mu + (1e-9 * np.mean(mu) if mu.size else 0.0)


def textbook_ekf_full(frames, theta0, est, prior_sigma, q, model, weighting, equations="framework", fd_jacobian=False,
                      p12=(0.0, 0.0), pinv=False):
    """x, P, history, NIS and the dimension of each update. ``pinv``: the update takes R's pseudo-inverse, i.e. the
    textbook gain form on the range of R (ν, H and R projected onto R's eigenvectors, :func:`_range_of`)."""
    th = np.array(theta0, float)
    P = np.diag(np.asarray(prior_sigma, float) ** 2)
    hist, nis, dof = [th[est].copy()], [], []
    for fo in frames:
        if len(fo) < 4:
            nis.append(np.nan)
            dof.append(0)
            hist.append(th[est].copy())
            continue
        P = P + q**2 * np.eye(len(est))
        s = frame_system(fo, th, model, weighting, p12=p12, equations=equations)
        H = _fd_jacobian(fo, th, est, model, p12, equations) if fd_jacobian else s.H[:, est]
        nu = s.z - s.h
        R = s.R
        if pinv:
            U, var = _range_of((s.G * s.var) @ s.G.T)
            nu, H, R = U.T @ nu, U.T @ H, np.diag(var)
        S = H @ P @ H.T + R
        K = np.linalg.solve(S, H @ P).T if nu.size else np.zeros((len(est), 0))
        th[est] = th[est] + K @ nu
        P = (np.eye(len(est)) - K @ H) @ P
        nis.append(nu @ np.linalg.solve(S, nu) if nu.size else 0.0)
        dof.append(nu.size)
        hist.append(th[est].copy())
    return th, P, np.array(hist), np.array(nis), np.array(dof)


def textbook_ekf(frames, theta0, est, prior_sigma, q, model, weighting, equations="framework", fd_jacobian=False,
                 p12=(0.0, 0.0)):
    """x, P, history and NIS per frame. ``fd_jacobian``: H by central differences instead of the model's own."""
    return textbook_ekf_full(frames, theta0, est, prior_sigma, q, model, weighting, equations, fd_jacobian, p12)[:4]
