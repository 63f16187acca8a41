"""Noisy star observations of the default star rig's sequence, shared by the star-estimation tests."""

import numpy as np

from rigsim.estimation.star_calibration import FrameObs
from rigsim.optics import attitude as att


def true_theta(star_rig) -> np.ndarray:
    """θ = (f, u0, v0, k1, k2) of the rig's true sensor."""
    s = star_rig.sensor
    return np.array([s.f_px, *s.principal_point_px, s.k1, s.k2])


def noisy_frames(star_rig, star_sky, sigma, rng, n=None, n_stars=20, *, shuffle=False, spread_sigma=False,
                 sigma_floor=1e-4):
    """The brightest ``n_stars`` of each of the first ``n`` frames, centroids with N(0, σ) noise. ``shuffle``: store
    the stars out of brightness order; ``spread_sigma``: each star's quoted σ scaled by U(0.5, 2)."""
    seq = att.from_rig(star_rig.sequence)
    if n:
        seq = seq.subset(slice(0, n))
    out = []
    for k in range(len(seq)):
        tr = star_sky.field(seq.R_cam_from_icrs[k])
        inside = star_sky.camera.on_detector(tr.uv, 5.0)
        idx = np.flatnonzero(inside)[np.argsort(-tr.photons[inside])][:n_stars]
        if shuffle:
            idx = rng.permutation(idx)
        uv = tr.uv[idx] + rng.normal(0, sigma, (idx.size, 2))
        sig = np.full((idx.size, 2), max(sigma, sigma_floor))
        if spread_sigma:
            sig = sig * rng.uniform(0.5, 2.0, (idx.size, 1))
        out.append(FrameObs(uv, sig, tr.dirs_icrs[idx], tr.photons[idx]))
    return out
