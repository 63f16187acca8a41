"""The textbook extended Kalman filter the star calibration's filters are compared with: identity transition,
P += q²I before each frame, one update per frame of 4 stars or more, gain by numpy's solve, P⁺ = (I − KH)P and
NIS = νᵀS⁻¹ν. Written from the equations, not from rigsim's filter."""

from __future__ import annotations

import numpy as np

from rigsim.estimation.star_calibration import frame_system


def _fd_jacobian(fo, th, est, model):
    """H by central differences of the model's predicted centroids (steps 1e-3 px for f, u0, v0; 1e-6 for k1, k2)."""
    h0 = frame_system(fo, th, model).h
    H = np.empty((h0.size, len(est)))
    for c, p in enumerate(est):
        e = np.zeros(5)
        e[p] = 1e-3 if p < 3 else 1e-6
        H[:, c] = (frame_system(fo, th + e, model).h - frame_system(fo, th - e, model).h) / (2 * e[p])
    return H


def textbook_ekf(frames, theta0, est, prior_sigma, q, model, weighting, equations="framework", fd_jacobian=False):
    """x, P, history and NIS per frame. ``fd_jacobian``: H by central differences instead of the model's own."""
    th = np.array(theta0, float)
    P = np.diag(np.asarray(prior_sigma, float) ** 2)
    hist, nis = [th[est].copy()], []
    for fo in frames:
        if len(fo) < 4:
            nis.append(np.nan)
            hist.append(th[est].copy())
            continue
        P = P + q**2 * np.eye(len(est))
        s = frame_system(fo, th, model, weighting, equations=equations)
        H = _fd_jacobian(fo, th, est, model) if fd_jacobian else s.H[:, est]
        nu = s.z - s.h
        S = H @ P @ H.T + s.R
        K = np.linalg.solve(S, H @ P).T
        th[est] = th[est] + K @ nu
        P = (np.eye(len(est)) - K @ H) @ P
        nis.append(nu @ np.linalg.solve(S, nu))
        hist.append(th[est].copy())
    return th, P, np.array(hist), np.array(nis)
