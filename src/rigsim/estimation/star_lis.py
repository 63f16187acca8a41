"""Lost-in-space star identification: no attitude prior, the focal length known only roughly.

1. **Patterns**: the brightest observed stars (after dropping any star closer than the database's
   separation to a brighter one) form 4-star patterns, brightest combinations first. Each pattern's
   six edges (angles through the nominal camera) give five edge ratios, which do not depend on the
   focal length; the ratios are computed at both ends of the focal-length range, widened by the
   centroid tolerance, and looked up in the pattern database
   (:mod:`rigsim.estimation.star_patterns`), together with the largest edge's angle.
2. **Hypotheses**: every database pattern that fits gives the star-to-star correspondence (the one of
   the 24 orderings whose edges agree best), the focal length (image edges against catalogue
   edges) and an attitude (Wahba); a hypothesis whose four stars do not fit within the tolerance
   is dropped.
3. **Verification**: the catalogue stars in the hypothesis's field are projected, matched to the
   brightest observed stars, the attitude and focal length refitted on the matches and matched
   again. The chance that a wrong hypothesis matches as many of the other stars by accident is a
   binomial tail (each observed star falls within the match radius of one of the predicted stars
   with probability (stars predicted × π r²) / detector area); multiplied by the number of
   database patterns (any one could have been tried) it is the false-match probability. A
   hypothesis is accepted only below ``false_match_probability``.
4. **Identification**: every observed star is matched to the predicted catalogue stars (ambiguous
   pairs dropped), and the attitude and focal length are fitted on all matches (distortion and
   principal point kept at their nominal values); the result carries the focal length the matches
   imply and the false-match probability.

Bad input (no stars, NaN rows, thousands of detections) never raises: the result is ``ok=False``
with a reason. docs/lost-in-space.md has the design, the parameters and the measured numbers.
"""

from __future__ import annotations

import itertools
import math
import time

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import bdtrc

from rigsim.estimation.star_id import IdentResult, _empty
from rigsim.estimation.star_patterns import (
    PAIRS,
    PatternDatabase,
    PatternSettings,
    _angles,
    _thin,
    pattern_database,
    pattern_settings,
)
from rigsim.optics.camera import project
from rigsim.optics.sky import SkyCatalogue

__all__ = ["LIS_DEFAULTS", "database_for", "identify_lost_in_space", "settings_for"]

LIS_DEFAULTS = {"focal_length_tolerance": 0.05, "match_tolerance_px": 2.0, "min_matches": 4,
                "false_match_probability": 1e-9, "pattern_tolerance_px": 1.0, "pattern_stars": 24,
                "verify_stars": 60}
"""The defaults of :func:`identify_lost_in_space` (the rig's ``[identification]`` table sets them)."""

_MAX_HYPOTHESES = 200  # verifications per frame at most (a frame whose first 200 hypotheses fail is refused)
_PERMS = np.array(list(itertools.permutations(range(4))))  # (24, 4)
_PAIR_INDEX = {tuple(p): k for k, p in enumerate(PAIRS.tolist())}
# edge k of an image pattern maps to catalogue edge _PERM_EDGES[π, k] under the ordering π
_PERM_EDGES = np.array([[_PAIR_INDEX[tuple(sorted((int(p[a]), int(p[b]))))] for a, b in PAIRS] for p in _PERMS])


def _breadth_first(n: int) -> np.ndarray:
    """All 4-combinations of range(n), ordered by their largest member, then lexicographically."""
    rows = [c + (m,) for m in range(3, n) for c in itertools.combinations(range(m), 3)]
    return np.array(rows, np.int64).reshape(-1, 4)


_COMBOS: dict[int, np.ndarray] = {}


def _combos(n: int) -> np.ndarray:
    if n not in _COMBOS:
        _COMBOS[n] = _breadth_first(n)
    return _COMBOS[n]


def _scaled(camera, f: float):
    """``camera`` with its focal length (fx; fy in proportion) set to ``f``."""
    return camera.with_params(fx=float(f), fy=float(f) * camera.fy / camera.fx)


def settings_for(camera, focal_length_tolerance: float) -> PatternSettings:
    """The pattern-database settings of a camera: its inscribed circle about the principal point at
    the longest focal length allowed, f / (1 − tolerance)."""
    cam_hi = _scaled(camera, camera.fx / (1.0 - focal_length_tolerance))
    W, H, cx, cy = camera.width, camera.height, camera.cx, camera.cy
    edges = np.array([[-0.5, cy], [W - 0.5, cy], [cx, -0.5], [cx, H - 0.5]])
    d = cam_hi.unproject(edges)
    rho = float(np.nanmin(np.arccos(np.clip(d[:, 2], -1.0, 1.0))))
    if not math.isfinite(rho) or rho <= 0.0:
        raise ValueError("the camera's field cannot be computed (principal point off the detector?)")
    return pattern_settings(rho)


def database_for(sky: SkyCatalogue, camera, focal_length_tolerance: float = LIS_DEFAULTS["focal_length_tolerance"],
                 *, use_cache: bool = True) -> PatternDatabase:
    """The pattern database of this catalogue and camera (built once, cached on disk)."""
    return pattern_database(sky, settings_for(camera, focal_length_tolerance), use_cache=use_cache)


_TREES: dict[int, tuple[SkyCatalogue, cKDTree]] = {}


def _sky_tree(sky: SkyCatalogue) -> cKDTree:
    hit = _TREES.get(id(sky))
    if hit is None or hit[0] is not sky:
        if len(_TREES) > 8:
            _TREES.clear()
        hit = _TREES[id(sky)] = (sky, cKDTree(sky.vectors))
    return hit[1]


def _wahba_batch(b: np.ndarray, r: np.ndarray) -> np.ndarray:
    """R (n, 3, 3) minimising Σ|b − R r|² for each batch of vectors b, r (n, k, 3) (SVD, proper rotations)."""
    M = np.einsum("nki,nkj->nij", b, r)
    U, _s, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    U[:, :, 2] *= d[:, None]
    return U @ Vt


def _normalized_dirs(xy: np.ndarray, scale) -> np.ndarray:
    """Unit vectors of normalised image points ``xy`` (…, 2) scaled by ``scale`` (the nominal f over
    the hypothesis's f: a pinhole approximation of a focal-length change)."""
    v = np.concatenate([xy * np.asarray(scale)[..., None, None], np.ones(xy.shape[:-1] + (1,))], axis=-1)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


class _Frame:
    """One frame's observed stars and the fixed inputs of the search."""

    def __init__(self, uv, sky, camera, tol, match_tol, verify_stars, db):
        self.uv, self.sky, self.camera, self.tol, self.match_tol, self.db = uv, sky, camera, tol, match_tol, db
        self.f0 = camera.fx
        self.verify = np.arange(min(int(verify_stars), uv.shape[0]))  # the brightest stars verify
        self.area = float(camera.width * camera.height)
        half_diag = math.hypot(camera.width, camera.height) / 2.0
        # the true f may be f0 / (1 ± tol) (the nominal off by ± tol); a little slack for the pattern's estimate
        self.f_lo, self.f_hi = self.f0 / (1.0 + tol), self.f0 / (1.0 - tol)
        self.cone = math.atan(half_diag / self.f_lo) + math.radians(0.5)
        self.chord = 2.0 * math.sin(self.cone / 2.0)
        self.p0 = camera.params()
        self.fy_ratio = camera.fy / camera.fx

    def f_ok(self, f) -> np.ndarray:
        """True where a focal length lies in the allowed range (0.5 % slack)."""
        f = np.asarray(f, float)
        return np.isfinite(f) & (f >= 0.995 * self.f_lo) & (f <= 1.005 * self.f_hi)

    def params(self, f: float) -> np.ndarray:
        """The camera's parameter vector (``PARAM_NAMES`` order) with its focal length set to f."""
        p = self.p0.copy()
        p[0], p[1] = f, f * self.fy_ratio
        return p

    def predict(self, R: np.ndarray, f: float):
        """Catalogue stars whose images fall on the detector for attitude R and focal length f:
        (catalogue indices in magnitude order, their pixels)."""
        idx = np.asarray(_sky_tree(self.sky).query_ball_point(R[2], self.chord), np.int64)
        if idx.size == 0:
            return idx, np.zeros((0, 2))
        uv = project(self.sky.vectors[idx] @ R.T, self.params(f))
        on = self.camera.on_detector(uv)
        idx, uv = idx[on], uv[on]
        o = np.argsort(self.sky.hp_mag[idx], kind="stable")
        return idx[o], uv[o]

    def fit(self, R: np.ndarray, f: float, obs: np.ndarray, cat: np.ndarray, iterations: int = 4):
        """Attitude and focal length minimising the pixel residuals of the pairs (obs → uv rows,
        cat → catalogue stars); Gauss–Newton on a small rotation and f. Returns (R, f, residuals px)."""
        r = self.sky.vectors[cat]
        uv = self.uv[obs]
        for _ in range(iterations):
            d = r @ R.T
            pred, du_dd, du_dk = project(d, self.params(f), get_gradients=True)
            res = (uv - pred).reshape(-1)
            if not np.all(np.isfinite(res)):
                break
            # d(R r)/dδ for R ← (I + [δ]×) R is −[d]×
            dx = np.zeros((d.shape[0], 3, 3))
            dx[:, 0, 1], dx[:, 0, 2], dx[:, 1, 2] = d[:, 2], -d[:, 1], d[:, 0]
            dx[:, 1, 0], dx[:, 2, 0], dx[:, 2, 1] = -d[:, 2], d[:, 1], -d[:, 0]
            J = np.concatenate([du_dd @ dx, (du_dk[..., 0] + self.fy_ratio * du_dk[..., 1])[..., None]],
                               axis=2).reshape(-1, 4)
            J[:, 3] *= f  # solve for a relative change of f (better conditioned)
            try:
                step = np.linalg.solve(J.T @ J, J.T @ res)
            except np.linalg.LinAlgError:
                break
            w = step[:3]
            th = float(np.linalg.norm(w))
            if th > 0:
                k = w / th
                Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
                R = (np.eye(3) + math.sin(th) * Kx + (1 - math.cos(th)) * Kx @ Kx) @ R
            f = f * (1.0 + step[3])
            if th < 1e-9 and abs(step[3]) < 1e-9:
                break
        pred = project(r @ R.T, self.params(f))
        return R, f, np.linalg.norm(uv - pred, axis=1)

    def match(self, R, f, obs_idx: np.ndarray, radius: float, *, ambiguity: float | None = None,
              max_cat: int | None = None):
        """Mutual nearest neighbours between the observed stars ``obs_idx`` and the predicted catalogue
        stars, within ``radius`` px. With ``ambiguity`` (px) a pair is also dropped when another
        predicted star lies within ``ambiguity`` of the observed one, or another observed star within
        ``ambiguity`` of the predicted one (unresolved doubles, blends). ``max_cat``: only the
        brightest predicted stars. Returns (obs, cat, predicted count)."""
        cat, pred = self.predict(R, f)
        if max_cat is not None:
            cat, pred = cat[:max_cat], pred[:max_cat]
        empty = np.zeros(0, np.int64)
        if cat.size == 0 or obs_idx.size == 0:
            return empty, empty, int(cat.size)
        uvo = self.uv[obs_idx]
        k = min(2, cat.size)
        d, j = cKDTree(pred).query(uvo, k=k)
        d, j = d.reshape(len(uvo), k), j.reshape(len(uvo), k)
        back_d, back = cKDTree(uvo).query(pred[j[:, 0]], k=min(2, len(uvo)))
        back_d, back = back_d.reshape(len(uvo), -1), back.reshape(len(uvo), -1)
        ok = (d[:, 0] <= radius) & (back[:, 0] == np.arange(len(uvo)))
        if ambiguity is not None:
            if k > 1:
                ok &= d[:, 1] > ambiguity
            if back_d.shape[1] > 1:
                ok &= back_d[:, 1] > ambiguity
        return obs_idx[ok], cat[j[ok, 0]], int(cat.size)

    def false_probability(self, n_matched: int, n_observed: int, n_predicted: int, radius: float) -> float:
        """Chance that a wrong attitude matches ``n_matched`` − 4 of the other ``n_observed`` − 4 stars
        by accident, times the number of database patterns."""
        extra, trials = n_matched - 4, n_observed - 4
        if extra <= 0 or trials <= 0:
            return 1.0
        p = min(1.0, n_predicted * math.pi * radius * radius / self.area)
        return float(min(1.0, bdtrc(extra - 1, trials, p) * max(len(self.db), 1)))


def _sanitise(obs_uv):
    """(uv (N, 2) of the finite rows, their indices into obs_uv) or a reason string."""
    try:
        uv = np.asarray(obs_uv, dtype=float)
    except (TypeError, ValueError) as exc:
        return f"the centroids are not numbers ({exc})"
    if uv.size == 0:
        return "no stars observed"
    if uv.ndim != 2 or uv.shape[1] != 2:
        return f"the centroids must be an (N, 2) array of pixels, got shape {uv.shape}"
    finite = np.flatnonzero(np.all(np.isfinite(uv), axis=1))
    return uv[finite], finite


def identify_lost_in_space(obs_uv, sky: SkyCatalogue, camera, *,
                           focal_length_tolerance: float = LIS_DEFAULTS["focal_length_tolerance"],
                           match_tolerance_px: float = LIS_DEFAULTS["match_tolerance_px"],
                           min_matches: int = LIS_DEFAULTS["min_matches"],
                           false_match_probability: float = LIS_DEFAULTS["false_match_probability"],
                           pattern_tolerance_px: float = LIS_DEFAULTS["pattern_tolerance_px"],
                           pattern_stars: int = LIS_DEFAULTS["pattern_stars"],
                           verify_stars: int = LIS_DEFAULTS["verify_stars"],
                           use_cache: bool = True) -> IdentResult:
    """Identify the stars of one frame with no attitude prior.

    ``obs_uv``: centroids (N, 2) px, brightest first; ``sky``: the catalogue at the observation epoch;
    ``camera``: the *nominal* camera, whose focal length may be off by ``focal_length_tolerance``
    (relative: the true f lies in f / (1 ± tolerance)). ``match_tolerance_px``: largest residual of
    an identified star; ``min_matches``: fewest stars identified; ``false_match_probability``: the
    largest accepted chance that the identification is a coincidence; ``pattern_tolerance_px``:
    centroid error allowed in a pattern's edges (noise, distortion left after the nominal model);
    ``pattern_stars``: brightest stars that form patterns; ``verify_stars``: brightest stars that
    verify a hypothesis. Returns an :class:`IdentResult` with ``f_px`` (the focal length the matches
    imply) and ``false_match_probability``; ``ok=False`` with a reason when the frame cannot be
    identified."""
    if not isinstance(sky, SkyCatalogue):
        raise TypeError(f"sky must be a rigsim.optics.sky.SkyCatalogue (catalogue only), got {type(sky).__name__}")
    t0 = time.perf_counter()
    got = _sanitise(obs_uv)
    if isinstance(got, str):
        return _empty(np.eye(3), got)
    uv, finite = got
    if uv.shape[0] < 4:
        return _empty(np.eye(3), f"only {uv.shape[0]} stars observed (lost in space needs 4)")
    tol = float(focal_length_tolerance)
    if not (math.isfinite(tol) and 0.0 <= tol < 0.5):
        return _empty(np.eye(3), f"focal_length_tolerance = {tol!r}: allowed 0 to 0.5")
    try:
        settings = settings_for(camera, tol)
    except ValueError as exc:
        return _empty(np.eye(3), str(exc))
    db = pattern_database(sky, settings, use_cache=use_cache)
    if len(db) == 0:
        return _empty(np.eye(3), "the catalogue has no 4-star patterns for this field")
    fr = _Frame(uv, sky, camera, tol, float(match_tolerance_px), verify_stars, db)
    try:
        found = _search(fr, settings, float(pattern_tolerance_px), int(pattern_stars), float(false_match_probability),
                        int(min_matches))
    except np.linalg.LinAlgError as exc:  # a degenerate configuration (all stars on a line, …)
        return _empty(np.eye(3), f"numerical failure in the pattern search ({exc})")
    if isinstance(found, str):
        return _empty(np.eye(3), found)
    R, f, prob, n_verified = found
    # 4. identify every observed star, refit on all matches; then keep the matches within 4.5 σ of the
    # residual scatter (σ from the median residual), at most the match tolerance: a detection that is
    # not a star (noise, a hot pixel) rarely falls that close to an undetected catalogue star
    every = np.arange(uv.shape[0])
    amb = 2.0 * fr.match_tol
    radius = fr.match_tol
    for _ in range(3):
        mo, mc, _n = fr.match(R, f, every, radius, ambiguity=amb)
        if mo.size < 3:
            break
        R, f, res = fr.fit(R, f, mo, mc)
        sigma = float(np.median(res)) / 1.1774  # per axis: the median of a Rayleigh distribution is 1.1774 σ
        radius = min(fr.match_tol, max(4.5 * sigma, 0.5))
    mo, mc, _n = fr.match(R, f, every, radius, ambiguity=amb)
    if mo.size < max(int(min_matches), 3):
        return _empty(R, f"{mo.size} stars matched within {radius:.2g} px (need {min_matches})", n_verified)
    R, f, res = fr.fit(R, f, mo, mc)
    o = np.argsort(mo, kind="stable")
    mo, mc, res = mo[o], mc[o], res[o]
    return IdentResult(True, finite[mo], mc, sky.hip[mc], sky.vectors[mc], R, float(np.sqrt(np.mean(res ** 2))),
                       n_verified, f_px=float(f), false_match_probability=prob,
                       seconds=time.perf_counter() - t0)


def _search(fr: _Frame, settings: PatternSettings, pattern_tol_px: float, n_pattern: int, p_max: float,
            min_matches: int):
    """Steps 1–3: (R, f, false-match probability, stars verified) of the first verified hypothesis, or
    the reason none was found."""
    cam, f0 = fr.camera, fr.f0
    xy0 = cam.pixel_to_normalized(fr.uv)                    # at the nominal f
    ok = np.all(np.isfinite(xy0), axis=1)
    b0 = _normalized_dirs(xy0[ok], 1.0)
    # pattern stars: brightest first, none within the database's separation of a brighter one
    cand = np.flatnonzero(ok)[_thin(b0, np.arange(b0.shape[0]), settings.min_separation_rad)][:max(n_pattern, 4)]
    if cand.size < 4:
        return f"only {cand.size} separated stars for patterns (need 4)"
    P = cand.size
    xy = xy0[cand]
    B0 = _normalized_dirs(xy, 1.0)
    Blo = _normalized_dirs(xy, f0 / fr.f_lo)             # the widest field: the shortest f
    Bhi = _normalized_dirs(xy, f0 / fr.f_hi)
    eps = pattern_tol_px / f0                            # edge error allowed (rad)
    combos = _combos(P)
    ends = np.searchsorted(combos[:, 3], [6, 8, 10, 12, 15, 18, 21, 25, 30, 40, 1000], side="left")
    tried = 0
    start = 0
    for stop in ends:
        if stop <= start:
            continue
        C = combos[start:stop]
        start = stop
        i, j = C[:, PAIRS[:, 0]], C[:, PAIRS[:, 1]]
        e0 = _angles(B0[i], B0[j])
        o = np.argsort(e0, axis=1)
        elo = np.take_along_axis(_angles(Blo[i], Blo[j]), o, axis=1)
        ehi = np.take_along_axis(_angles(Bhi[i], Bhi[j]), o, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            rlo, rhi = elo[:, :5] / elo[:, 5:], ehi[:, :5] / ehi[:, 5:]
            delta = eps * (1.0 + np.minimum(rlo, rhi)) / ehi[:, 5:]
        lo = np.minimum(rlo, rhi) - delta
        hi = np.maximum(rlo, rhi) + delta
        q, pat = fr.db.lookup(lo, hi, ehi[:, 5] - 2 * eps, elo[:, 5] + 2 * eps)
        if q.size == 0:
            continue
        # 2. hypotheses: ordering, focal length, attitude
        ec = _angles(fr.sky.vectors[fr.db.stars[pat]][:, PAIRS[:, 0]], fr.sky.vectors[fr.db.stars[pat]][:, PAIRS[:, 1]])
        ei = e0[q]
        scale = ec.sum(axis=1) / ei.sum(axis=1)          # catalogue over image angles ≈ f0 / f
        cost = np.sum((ei[:, None, :] * scale[:, None, None] - ec[:, _PERM_EDGES]) ** 2, axis=2)
        best = np.argmin(cost, axis=1)
        f = f0 / scale
        keep = fr.f_ok(f)
        if not keep.any():
            continue
        q, pat, best, f, scale = q[keep], pat[keep], best[keep], f[keep], scale[keep]
        # image star k of the pattern ↔ catalogue star perm[k]
        perm = _PERMS[best]
        cat4 = np.take_along_axis(fr.db.stars[pat], perm, axis=1)
        b4 = _normalized_dirs(xy[C[q]], scale)
        r4 = fr.sky.vectors[cat4]
        R = _wahba_batch(b4, r4)
        resid = np.max(_angles(b4, np.einsum("nij,nkj->nki", R, r4)), axis=1)
        good = np.flatnonzero(resid <= 3.0 * eps)
        # 3. verification, brightest patterns first
        for g in good:
            if tried >= _MAX_HYPOTHESES:
                return f"no hypothesis verified among the first {_MAX_HYPOTHESES}"
            tried += 1
            got = _verify(fr, R[g], float(f[g]), cand[C[q[g]]], p_max, min_matches)
            if got is not None:
                return got
    return (f"no 4-star pattern of the {P} brightest stars matched the catalogue and verified "
            f"({tried} hypotheses tried)")


def _verify(fr: _Frame, R, f, pattern_obs, p_max: float, min_matches: int):
    """(R, f, false-match probability, matches) when the hypothesis verifies, else None."""
    obs = np.union1d(fr.verify, pattern_obs)
    deep = 3 * obs.size  # a catalogue much deeper than the frame: its brightest stars only
    radius = 2.0 * fr.match_tol                          # the pattern's f is rough: wider at first
    for _ in range(2):
        mo, mc, _n = fr.match(R, f, obs, radius, max_cat=deep)
        if mo.size < 4:
            return None
        R, f, _res = fr.fit(R, f, mo, mc)
        if not fr.f_ok(f):
            return None
        radius = fr.match_tol
    mo, mc, n_pred = fr.match(R, f, obs, radius, max_cat=deep)
    if mo.size < max(min_matches, 4):
        return None
    n_pred = min(n_pred, deep)
    p = fr.false_probability(int(mo.size), int(obs.size), n_pred, radius)
    if p > p_max:
        return None
    return R, f, p, int(mo.size)
