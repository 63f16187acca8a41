"""The centre of an autocollimator's projected cross-hair reticle on a DN frame: two line fits.

The instrument's software knows its targets: a pinhole reticle images as a compact spot (the
thresholded centroid of :func:`rigsim.imaging.spot.measure_spot` is its centre); a cross-hair
images as two long bars. :func:`measure_reticle` tells them apart from the frame alone (the
bright region around the brightest pixel is larger than the spot's centroid window) and, for a
cross, fits a straight line to the centre of each bar (a weighted least-squares fit of the
per-row centroids of the vertical bar and the per-column centroids of the horizontal bar, the
crossing itself left out) and returns their intersection. Rings and other lines crossing a bar do
so symmetrically and do not bias the fits.
"""

from __future__ import annotations

import numpy as np

from rigsim.imaging.spot import THRESHOLD_SIGMA, SpotMeasurement

__all__ = ["DETECT_SIGMA", "measure_reticle"]

DETECT_SIGMA = 5.0
"""The reticle's lines: pixels this many σ above the background (as the spot's detection)."""


def _line_fit(coord: np.ndarray, centre: np.ndarray, weight: np.ndarray, c0: float):
    """Weighted fit centre = a + b·(coord − c0); returns (a, b, σ_a)."""
    w = weight / weight.sum()
    x = coord - c0
    A = np.stack([np.ones_like(x), x], axis=1)
    W = np.sqrt(w)[:, None]
    sol, *_ = np.linalg.lstsq(A * W, centre * W[:, 0], rcond=None)
    r = centre - A @ sol
    dof = max(len(x) - 2, 1)
    s2 = float(np.sum(w * r ** 2) / dof * len(x))
    cov = s2 * np.linalg.inv((A * w[:, None]).T @ A) / len(x)
    return float(sol[0]), float(sol[1]), float(np.sqrt(max(cov[0, 0], 0.0)))


def _windowed_centres(P: np.ndarray, c0: float, R: float, iterations: int = 20):
    """Centre of each row of ``P`` (signal above the background) in a window of half-width ``R``
    around the running estimate, pixels weighted by their overlap with the window (a symmetric
    window: converges on the centre of a symmetric profile). Returns (centres, weights, ok)."""
    x = np.arange(P.shape[1], dtype=float)
    c = np.full(P.shape[0], float(c0))
    w = np.zeros(P.shape[0])
    for _ in range(iterations):
        f = np.clip(np.minimum(x[None, :] + 0.5, c[:, None] + R) - np.maximum(x[None, :] - 0.5, c[:, None] - R), 0.0, 1.0)
        w = (f * P).sum(axis=1)
        ok = w > 0
        c = np.where(ok, (f * P * x[None, :]).sum(axis=1) / np.where(ok, w, 1.0), c)
    return c, w, w > 0


def _typical(w: np.ndarray, ok: np.ndarray, tol: float = 0.25) -> np.ndarray:
    """Rows whose light is within ``tol`` of the median row's (a bar's full cross-section)."""
    if not ok.any():
        return ok
    med = float(np.median(w[ok]))
    return np.abs(w - med) <= tol * med


def measure_reticle(dn: np.ndarray, spot: SpotMeasurement, roi_px: int, *,
                    threshold_sigma: float = THRESHOLD_SIGMA) -> SpotMeasurement | None:
    """The centre of a cross-hair reticle's image, or ``None`` when the frame shows a compact spot
    (its bright region fits the ``roi_px`` centroid window: keep ``spot``'s centroid). ``spot``
    is :func:`measure_spot`'s result on the same frame (its background and peak are reused)."""
    from scipy import ndimage

    if not spot.ok:
        return None
    a = np.asarray(dn, float)
    level, rms = spot.background_dn, spot.background_rms_dn
    lab, _ = ndimage.label(a > level + DETECT_SIGMA * rms)
    u0, v0 = (round(float(x)) for x in spot.uv)
    k = lab[v0, u0]
    if k == 0:  # the centroid is between pixels of the region: take the brightest pixel near it
        win = a[max(v0 - 2, 0):v0 + 3, max(u0 - 2, 0):u0 + 3]
        j = np.unravel_index(np.argmax(win), win.shape)
        k = lab[max(v0 - 2, 0) + j[0], max(u0 - 2, 0) + j[1]]
    if k == 0:
        return None
    vs, us = ndimage.find_objects((lab == k).astype(np.int32))[0]
    if (us.stop - us.start) <= roi_px and (vs.stop - vs.start) <= roi_px:
        return None  # a compact spot

    def bad(problem):
        return SpotMeasurement(None, spot.flags, problem, spot.n_detections, spot.peak_dn, level, rms)

    H, W = a.shape
    if us.start == 0 or vs.start == 0 or us.stop == W or vs.stop == H:
        return bad("the reticle's image is cut by the detector's edge: edge of the measuring range")
    m = 3
    sl = (slice(max(vs.start - m, 0), min(vs.stop + m, H)), slice(max(us.start - m, 0), min(us.stop + m, W)))
    sub = a[sl]
    s = np.where(sub > level + threshold_sigma * rms, sub - level, 0.0)  # the bars' cores, to find them
    ou, ov = sl[1].start, sl[0].start
    Pu, Pv = s.sum(axis=0), s.sum(axis=1)
    uc, vc = int(np.argmax(Pu)), int(np.argmax(Pv))
    w_vert = int(np.count_nonzero(Pu > 0.5 * Pu.max()))  # the vertical bar's width (columns)
    w_horz = int(np.count_nonzero(Pv > 0.5 * Pv.max()))
    strip_u, strip_v = w_vert + 3, w_horz + 3
    # background-subtracted, not thresholded: a symmetric window per row / column (below) keeps
    # the bars' faint diffraction tails symmetric, so they cannot pull the centres
    d = sub - level
    R = float(max(w_vert, w_horz) + 6)
    # rows (columns) along the vertical (horizontal) bar: its core is there, the crossing is not
    rows = (np.abs(np.arange(d.shape[0]) - vc) > strip_v) & (s[:, max(uc - strip_u, 0):uc + strip_u + 1].sum(axis=1) > 0)
    cols = (np.abs(np.arange(d.shape[1]) - uc) > strip_u) & (s[max(vc - strip_v, 0):vc + strip_v + 1, :].sum(axis=0) > 0)
    ur, wr, okr = _windowed_centres(d[rows], uc, R)
    vcol, wc, okc = _windowed_centres(d[:, cols].T, vc, R)
    # only the bars' full stretches: not their blurred ends, nor where another line (a ring)
    # crosses them (there the row holds more light than the bar alone)
    okr &= _typical(wr, okr)
    okc &= _typical(wc, okc)
    if okr.sum() < 4 or okc.sum() < 4:
        return bad("the reticle's bars are too short to fit (fewer than 4 rows or columns outside the crossing)")
    vv = np.flatnonzero(rows)[okr].astype(float)
    uu = np.flatnonzero(cols)[okc].astype(float)
    ur, wr, vcol, wc = ur[okr], wr[okr], vcol[okc], wc[okc]
    a1, b1, sa = _line_fit(vv, ur, wr, vc)      # u = a1 + b1 (v − vc)
    a2, b2, sb = _line_fit(uu, vcol, wc, uc)    # v = a2 + b2 (u − uc)
    det = 1.0 - b1 * b2
    u = (a1 + b1 * (a2 - vc - b2 * uc)) / det
    v = a2 + b2 * (u - uc)
    return SpotMeasurement(np.array([u + ou, v + ov]), spot.flags, None, spot.n_detections, spot.peak_dn, level, rms,
                           np.array([sa, sb]))
