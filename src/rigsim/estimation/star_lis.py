"""Lost-in-space star identification: no attitude prior. Geometric voting (Kolomenkin et al.
2008): every pair of the brightest observed stars votes for the catalogue pairs whose angular
separation matches its own within the tolerance of the nominal camera; each observed star takes
the catalogue star it got most votes for; the largest mutually consistent subset of those
assignments gives a first attitude (Wahba), which :func:`rigsim.estimation.star_id.identify`
then refines into the full identification."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from rigsim.estimation.star_id import IdentResult, _empty, _wahba, identify
from rigsim.optics.sky import SkyCatalogue, field_cone_cos

__all__ = ["PairIndex", "bright_subset", "identify_lost_in_space", "pair_index", "vote_and_identify"]


@dataclass
class PairIndex:
    """Every catalogue pair closer than the field's diameter, sorted by angular separation (rad)."""

    i: np.ndarray
    j: np.ndarray
    angle: np.ndarray
    max_angle: float
    _cache: dict = field(default_factory=dict, repr=False)

    def within(self, a: float, tol: float) -> np.ndarray:
        lo, hi = np.searchsorted(self.angle, [a - tol, a + tol])
        return np.arange(lo, hi)


_INDEX: dict = {}


def pair_index(sky: SkyCatalogue, max_angle_rad: float, stars: np.ndarray | None = None) -> PairIndex:
    """The pair index of the catalogue stars ``stars`` (default all) up to ``max_angle_rad``, with
    catalogue indices (built once per catalogue, subset and angle)."""
    sel = np.arange(len(sky)) if stars is None else np.asarray(stars, np.int64)
    key = (id(sky), len(sky), sel.size, int(sel.sum()), round(float(max_angle_rad), 9))
    if key not in _INDEX:
        V = sky.vectors[sel]
        chord = 2.0 * np.sin(max_angle_rad / 2.0)
        pairs = cKDTree(V).query_pairs(chord, output_type="ndarray")
        ang = np.arccos(np.clip(np.einsum("ij,ij->i", V[pairs[:, 0]], V[pairs[:, 1]]), -1, 1))
        o = np.argsort(ang, kind="stable")
        _INDEX[key] = PairIndex(sel[pairs[o, 0]], sel[pairs[o, 1]], ang[o], float(max_angle_rad))
    return _INDEX[key]


def bright_subset(sky: SkyCatalogue, camera, n_brightest: int, factor: float = 2.5) -> np.ndarray:
    """The catalogue's brightest stars, as many per field on average as ``factor`` × the observed
    stars that vote: the brightest observed stars are among them, and a sparse catalogue keeps
    chance votes rare."""
    frac = (1.0 - field_cone_cos(camera, 0.0)) / 2.0  # the field's share of the sphere
    keep = min(1.0, factor * n_brightest / max(len(sky) * frac, 1e-9))
    cut = float(np.quantile(sky.hp_mag, keep))
    return np.flatnonzero(sky.hp_mag <= cut)


def identify_lost_in_space(obs_uv: np.ndarray, sky: SkyCatalogue, camera, *, n_brightest=(12, 20, 30),
                           **kw) -> IdentResult:
    """Identify the stars of one frame without an attitude prior: :func:`vote_and_identify` with the
    ``n_brightest`` stars, then with more if the vote finds no consistent set."""
    res = None
    for n in np.atleast_1d(n_brightest):
        res = vote_and_identify(obs_uv, sky, camera, n_brightest=int(n), **kw)
        if res.ok:
            return res
    return res


def vote_and_identify(obs_uv: np.ndarray, sky: SkyCatalogue, camera, *, n_brightest: int = 12,
                           tolerance_rad: float = 1.0e-4, relative_tolerance: float = 1.5e-3, min_votes: int = 4,
                           catalogue_factor: float = 2.5, **identify_kw) -> IdentResult:
    """One geometric vote and its refinement. ``obs_uv``: centroids, brightest
    first (the voting uses the first ``n_brightest``); ``camera``: the nominal camera. The pair
    tolerance is ``tolerance_rad`` + ``relative_tolerance`` × separation (the nominal camera's
    focal-length and distortion errors scale separations). ``identify_kw`` go to :func:`identify`."""
    uv = np.asarray(obs_uv, float)
    good = np.flatnonzero(np.all(np.isfinite(uv), axis=1))[:n_brightest]
    if good.size < 4:
        return _empty(np.eye(3), f"only {good.size} stars observed (lost in space needs 4)")
    b = camera.unproject(uv[good])
    diam = 2.0 * np.arccos(field_cone_cos(camera, 0.0))
    idx = pair_index(sky, diam, bright_subset(sky, camera, good.size, catalogue_factor))
    n = good.size
    votes: dict[tuple[int, int], int] = {}
    oi, ci = [], []
    for p in range(n):
        for q in range(p + 1, n):
            a = float(np.arccos(np.clip(b[p] @ b[q], -1.0, 1.0)))
            k = idx.within(a, tolerance_rad + relative_tolerance * a)
            if k.size == 0:
                continue
            cats = np.concatenate([idx.i[k], idx.j[k]])
            oi.append(np.full(cats.size, p))
            ci.append(cats)
            oi.append(np.full(cats.size, q))
            ci.append(cats)
    if not oi:
        return _empty(np.eye(3), "no catalogue pair matches any observed pair")
    o = np.concatenate(oi)
    c = np.concatenate(ci)
    key = o * len(sky) + c
    uk, cnt = np.unique(key, return_counts=True)
    best_c = np.full(n, -1)
    best_v = np.zeros(n, int)
    for kk, v in zip(uk, cnt):
        p, cc = divmod(int(kk), len(sky))
        if v > best_v[p]:
            best_v[p], best_c[p] = v, cc
    cand = [p for p in np.argsort(-best_v, kind="stable") if best_v[p] >= min_votes]
    # the largest mutually consistent set of assignments (separations agree within the tolerance)
    chosen: list[int] = []
    for p in cand:
        ok = True
        for q in chosen:
            a_obs = np.arccos(np.clip(b[p] @ b[q], -1, 1))
            a_cat = np.arccos(np.clip(sky.vectors[best_c[p]] @ sky.vectors[best_c[q]], -1, 1))
            if best_c[p] == best_c[q] or abs(a_obs - a_cat) > tolerance_rad + relative_tolerance * a_obs:
                ok = False
                break
        if ok:
            chosen.append(p)
    if len(chosen) < 3:
        return _empty(np.eye(3), f"geometric voting found only {len(chosen)} consistent stars", len(chosen))
    R = _wahba(b[chosen], sky.vectors[best_c[chosen]])
    return identify(uv, sky, R, camera, **identify_kw)
