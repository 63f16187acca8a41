"""The 4-star pattern database of the lost-in-space identifier (:mod:`rigsim.estimation.star_lis`).

A pattern is four catalogue stars; its key is the five ratios of its six edges (angular separations,
sorted, each divided by the largest), which a camera of unknown scale sees unchanged. Which
patterns: the sky is covered by a Fibonacci lattice of circular *pattern fields* small enough that
one of them lies inside the image whatever the attitude; the ``stars_per_field`` brightest stars of
each field (after dropping stars closer than ``min_separation_rad`` to a brighter one: blends and
tight clusters) give every 4-star combination. The table is sorted by a hash of the binned ratios,
so that a lookup is a binary search (:meth:`PatternDatabase.lookup`).

The database is built once per (catalogue, magnitude limit, epoch, field, settings, format) and
cached on disk in :func:`rigsim.files.cache_dir` (``star-patterns/``); a cache file is trusted only
when its header equals the expected key and its arrays' checksum and shapes hold, else it is
rebuilt (atomic write). docs/lost-in-space.md describes the design and the numbers.
"""

from __future__ import annotations

import hashlib
import io
import itertools
import json
import logging
import math
import threading
import time
import zipfile
from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial import cKDTree

from rigsim.files import atomic_write_bytes, cache_dir
from rigsim.optics.sky import SkyCatalogue

__all__ = ["FORMAT_VERSION", "PatternDatabase", "PatternSettings", "build_pattern_database", "cache_file",
           "clear_memory_cache", "database_key", "edge_ratios", "fibonacci_lattice", "lattice_size", "pattern_database",
           "pattern_settings"]

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
"""Bump when the file layout or the meaning of an array changes: older files are then rebuilt."""

PAIRS = np.array(list(itertools.combinations(range(4), 2)))  # the 6 edges of a 4-star pattern
_ARRAYS = ("stars", "ratios", "largest", "keys")


@dataclass(frozen=True)
class PatternSettings:
    """What a pattern database depends on besides the catalogue (angles in radians)."""

    field_radius_rad: float      # a pattern's stars lie within this radius of a lattice point
    lattice_radius_rad: float    # every direction lies within this of a lattice point
    stars_per_field: int = 10    # the brightest stars of a field that form its patterns
    min_separation_rad: float = 0.0  # a star this close to a brighter one is never a pattern star
    bins: int = 100              # hash bins per unit edge ratio

    def __post_init__(self) -> None:
        for name in ("field_radius_rad", "lattice_radius_rad", "min_separation_rad"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and 0.0 <= v < math.pi / 2):
                raise ValueError(f"PatternSettings.{name} = {v!r}: allowed 0 to π/2 rad")
        if not 4 <= int(self.stars_per_field) <= 30:
            raise ValueError(f"PatternSettings.stars_per_field = {self.stars_per_field!r}: allowed 4 to 30")
        if not 4 <= int(self.bins) <= 1000:
            raise ValueError(f"PatternSettings.bins = {self.bins!r}: allowed 4 to 1000")
        if self.field_radius_rad <= 0.0 or self.lattice_radius_rad <= 0.0:
            raise ValueError("PatternSettings: field_radius_rad and lattice_radius_rad must be > 0")


def pattern_settings(inscribed_radius_rad: float, *, field_fraction: float = 1.0, lattice_fraction: float = 0.3,
                     stars_per_field: int = 8, min_separation_fraction: float = 0.04, bins: int = 100) -> PatternSettings:
    """Settings for an image whose inscribed circle (about the principal point, at the longest focal
    length allowed) has radius ρ = ``inscribed_radius_rad``: pattern fields of radius
    ``field_fraction`` × ρ on a lattice whose points are at most ``lattice_fraction`` × ρ from any
    direction. The radius is rounded down to 0.01° so that cameras of nearly the same field share
    one database."""
    step = math.radians(0.01)
    rho = max(step, math.floor(float(inscribed_radius_rad) / step) * step)
    return PatternSettings(field_radius_rad=round(field_fraction * rho, 12),
                           lattice_radius_rad=round(lattice_fraction * rho, 12),
                           stars_per_field=int(stars_per_field),
                           min_separation_rad=round(min_separation_fraction * rho, 12), bins=int(bins))


def fibonacci_lattice(n: int) -> np.ndarray:
    """``n`` nearly evenly spaced unit vectors (the golden-angle spiral)."""
    i = np.arange(int(n), dtype=float)
    z = 1.0 - (2.0 * i + 1.0) / n
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def lattice_size(covering_radius_rad: float) -> int:
    """Points of a Fibonacci lattice whose covering radius is at most ``covering_radius_rad``: a
    hexagonal lattice of that covering radius has 8π / (3√3 r²) points; the spiral's largest gap, at
    the poles, is up to 1.23 × the hexagonal one (measured for n = 500 … 40 000), hence 1.55 × as many
    points."""
    r = float(covering_radius_rad)
    return int(math.ceil(1.55 * 8.0 * math.pi / (3.0 * math.sqrt(3.0) * r * r)))


def _angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles between unit vectors (…, 3), accurate at small angles (2 asin of half the chord)."""
    d = a - b
    return 2.0 * np.arcsin(np.clip(0.5 * np.sqrt(np.einsum("...k,...k->...", d, d)), 0.0, 1.0))


def edge_ratios(vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For patterns (P, 4, 3) of unit vectors: the 6 edge angles (P, 6) in :data:`PAIRS` order, the
    5 smaller sorted edges over the largest (P, 5) and the largest edge (P,)."""
    G = np.einsum("pik,pjk->pij", vectors, vectors)[:, PAIRS[:, 0], PAIRS[:, 1]]
    e = 2.0 * np.arcsin(np.sqrt(np.clip(0.5 * (1.0 - G), 0.0, 1.0)))  # |a − b| = 2 sin(θ/2)
    s = np.sort(e, axis=1)
    largest = s[:, 5]
    with np.errstate(divide="ignore", invalid="ignore"):
        return e, s[:, :5] / largest[:, None], largest


def hash_keys(bins_5: np.ndarray, bins: int) -> np.ndarray:
    """One int64 per row of five bin numbers (0 … bins − 1), ordered as the rows are lexicographically."""
    b = np.asarray(bins_5, np.int64)
    k = np.zeros(b.shape[:-1], np.int64)
    for d in range(5):
        k = k * bins + b[..., d]
    return k


@dataclass(frozen=True)
class PatternDatabase:
    """Patterns sorted by hash key. ``stars`` (P, 4): catalogue indices (``SkyCatalogue`` order);
    ``ratios`` (P, 5) and ``largest`` (P,) as in :func:`edge_ratios`; ``keys`` (P,) sorted."""

    settings: PatternSettings
    stars: np.ndarray
    ratios: np.ndarray
    largest: np.ndarray
    keys: np.ndarray
    build_seconds: float = float("nan")
    source: str = "built"  # "built", "disk" (read from the cache) or "memory"

    def __len__(self) -> int:
        return int(self.keys.shape[0])

    def lookup(self, lo: np.ndarray, hi: np.ndarray, largest_lo: np.ndarray, largest_hi: np.ndarray,
               max_bins_per_ratio: int = 3) -> tuple[np.ndarray, np.ndarray]:
        """Every (query, pattern) whose five ratios lie in [lo, hi] (Q, 5) and whose largest edge lies in
        [largest_lo, largest_hi] (Q,). The hash enumerates the bins of the first four ratios (queries
        spanning more than ``max_bins_per_ratio`` bins of one ratio are skipped: too vague) and finds
        the fifth's bin range by binary search. Returns (query index, pattern index), query order."""
        B = self.settings.bins
        lo = np.asarray(lo, float)
        hi = np.asarray(hi, float)
        blo = np.clip(np.floor(lo * B), 0, B - 1).astype(np.int64)
        bhi = np.clip(np.floor(hi * B), 0, B - 1).astype(np.int64)
        span = bhi - blo + 1
        usable = np.all(span[:, :4] <= max_bins_per_ratio, axis=1) & np.all(np.isfinite(lo) & np.isfinite(hi), axis=1)
        q = np.flatnonzero(usable)
        if q.size == 0 or len(self) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        m = max_bins_per_ratio
        offs = np.array(list(itertools.product(range(m), repeat=4)), np.int64)  # (m⁴, 4)
        b4 = blo[q, None, :4] + offs[None]                                      # (Q, m⁴, 4)
        ok = np.all(b4 <= bhi[q, None, :4], axis=2)
        qi, oi = np.nonzero(ok)
        b4 = b4[qi, oi]
        qq = q[qi]
        base = np.zeros(qq.size, np.int64)
        for d in range(4):
            base = base * B + b4[:, d]
        k_lo = base * B + blo[qq, 4]
        k_hi = base * B + bhi[qq, 4]
        start = np.searchsorted(self.keys, k_lo, side="left")
        stop = np.searchsorted(self.keys, k_hi, side="right")
        n = stop - start
        if n.sum() == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        qrep = np.repeat(qq, n)
        first = np.repeat(start - np.cumsum(n) + n, n)
        pat = first + np.arange(qrep.size)
        r = self.ratios[pat]
        keep = (np.all((r >= lo[qrep]) & (r <= hi[qrep]), axis=1)
                & (self.largest[pat] >= largest_lo[qrep]) & (self.largest[pat] <= largest_hi[qrep]))
        qrep, pat = qrep[keep], pat[keep]
        o = np.argsort(qrep, kind="stable")
        return qrep[o], pat[o]


# -- building -----------------------------------------------------------------------------------------

def _thin(vectors: np.ndarray, order: np.ndarray, min_sep_rad: float) -> np.ndarray:
    """The stars of ``order`` (brightest first) with no brighter kept star within ``min_sep_rad``
    (greedy, in brightness order); returned in brightness order."""
    if min_sep_rad <= 0.0 or order.size < 2:
        return order
    rank = np.empty(vectors.shape[0], np.int64)
    rank[order] = np.arange(order.size)
    chord = 2.0 * math.sin(min_sep_rad / 2.0)
    pairs = cKDTree(vectors[order]).query_pairs(chord, output_type="ndarray")  # in rank space
    keep = np.ones(order.size, bool)
    if pairs.size:
        pairs = np.sort(pairs, axis=1)                 # (brighter, fainter)
        pairs = pairs[np.argsort(pairs[:, 1], kind="stable")]
        for a, b in pairs:                             # a fainter star goes when a kept brighter one is near
            if keep[a]:
                keep[b] = False
    return order[keep]


def build_pattern_database(sky: SkyCatalogue, settings: PatternSettings) -> PatternDatabase:
    """Build the database of ``sky`` (all its stars are candidates; the brightest of each field win)."""
    t0 = time.perf_counter()
    V = np.asarray(sky.vectors, float)
    order = np.argsort(np.asarray(sky.hp_mag, float), kind="stable")
    cand = _thin(V, order, settings.min_separation_rad)        # catalogue indices, brightest first
    K = int(settings.stars_per_field)
    tops = []
    if cand.size >= 4:
        tree = cKDTree(V[cand])
        centres = fibonacci_lattice(lattice_size(settings.lattice_radius_rad))
        chord = 2.0 * math.sin(settings.field_radius_rad / 2.0)
        for members in tree.query_ball_point(centres, chord):
            if len(members) >= 4:
                tops.append(np.sort(np.asarray(members, np.int64))[:K])  # ranks: brightest first
    rows = []
    for k in range(4, K + 1):  # fields by their number of stars (a sparse field has fewer than K)
        group = [t for t in tops if t.size == k]
        if group:
            combos = np.array(list(itertools.combinations(range(k), 4)), np.int64)
            rows.append(np.stack(group)[:, combos].reshape(-1, 4))
    if rows:
        ranks = np.concatenate(rows)                                 # ascending in each row
        used = np.flatnonzero(np.bincount(ranks.ravel(), minlength=cand.size))  # renumber the stars used
        lut = np.zeros(cand.size, np.int64)
        lut[used] = np.arange(used.size)
        dense = lut[ranks]
        if used.size < 1 << 15:  # one int64 per row: a fast 1-D unique
            code = (dense[:, 0] << 45) | (dense[:, 1] << 30) | (dense[:, 2] << 15) | dense[:, 3]
            code.sort()
            code = code[np.concatenate([[True], code[1:] != code[:-1]])]
            m = (1 << 15) - 1
            dense = np.stack([code >> 45, (code >> 30) & m, (code >> 15) & m, code & m], axis=1)
        else:
            dense = np.unique(dense, axis=0)
        stars = cand[used[dense]].astype(np.int32)
        _e, ratios, largest = edge_ratios(V[stars])
        keys = hash_keys(np.clip(np.floor(ratios * settings.bins), 0, settings.bins - 1), settings.bins)
        o = np.argsort(keys, kind="stable")
        stars, ratios, largest, keys = stars[o], ratios[o].astype(np.float32), largest[o].astype(np.float32), keys[o]
    else:
        stars = np.zeros((0, 4), np.int32)
        ratios = np.zeros((0, 5), np.float32)
        largest = np.zeros(0, np.float32)
        keys = np.zeros(0, np.int64)
    return PatternDatabase(settings, stars, ratios, largest, keys, time.perf_counter() - t0, "built")


# -- the cache ----------------------------------------------------------------------------------------

_MEMORY: dict[str, PatternDatabase] = {}
_DIGESTS: dict[int, tuple[SkyCatalogue, str]] = {}
_LOCK = threading.Lock()


def catalogue_digest(sky: SkyCatalogue) -> str:
    """sha256 of the catalogue as the database sees it (HIP numbers, magnitudes, epoch vectors)."""
    hit = _DIGESTS.get(id(sky))
    if hit is not None and hit[0] is sky:
        return hit[1]
    h = hashlib.sha256()
    for a in (sky.hip, sky.hp_mag, sky.vectors):
        h.update(np.ascontiguousarray(a, dtype=np.float64 if a is not sky.hip else np.int64).tobytes())
    d = h.hexdigest()
    if len(_DIGESTS) > 16:
        _DIGESTS.clear()
    _DIGESTS[id(sky)] = (sky, d)
    return d


def database_key(sky: SkyCatalogue, settings: PatternSettings) -> dict:
    """Everything the database depends on (the header of its cache file)."""
    mags = np.asarray(sky.hp_mag, float)
    return {"format": FORMAT_VERSION, "what": "rigsim star-pattern database",
            "catalogue_sha256": catalogue_digest(sky), "stars": len(sky),
            "magnitude_limit": round(float(mags.max()), 3) if mags.size else None,
            "epoch_year": float(sky.epoch_year), "settings": asdict(settings)}


def _checksum(arrays: dict) -> str:
    h = hashlib.sha256()
    for name in _ARRAYS:
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _to_bytes(db: PatternDatabase, key: dict) -> bytes:
    arrays = {n: getattr(db, n) for n in _ARRAYS}
    header = dict(key, checksum=_checksum(arrays), build_seconds=db.build_seconds)
    buf = io.BytesIO()
    np.savez(buf, header=np.array(json.dumps(header, sort_keys=True)), **arrays)
    return buf.getvalue()


def _from_file(path, key: dict, n_stars: int) -> PatternDatabase | None:
    """The database in ``path`` when it is whole and was built for ``key``; None otherwise (and why, logged)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            header = json.loads(str(z["header"][()]))
            arrays = {n: z[n] for n in _ARRAYS}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, json.JSONDecodeError, TypeError) as exc:
        log.info("star-pattern cache %s unreadable (%s): rebuilding", path, exc)
        return None
    build = header.pop("build_seconds", float("nan")) if isinstance(header, dict) else None
    checksum = header.pop("checksum", None) if isinstance(header, dict) else None
    if header != key:
        log.info("star-pattern cache %s was built for other inputs: rebuilding", path)
        return None
    s, r, lg, k = (arrays[n] for n in _ARRAYS)
    P = k.shape[0] if k.ndim == 1 else -1
    shapes_ok = (s.dtype == np.int32 and s.shape == (P, 4) and r.dtype == np.float32 and r.shape == (P, 5)
                 and lg.dtype == np.float32 and lg.shape == (P,) and k.dtype == np.int64)
    if not shapes_ok or checksum != _checksum(arrays):
        log.info("star-pattern cache %s is damaged: rebuilding", path)
        return None
    if P and (s.min() < 0 or s.max() >= n_stars or np.any(np.diff(k) < 0)):
        log.info("star-pattern cache %s does not fit the catalogue: rebuilding", path)
        return None
    settings = PatternSettings(**key["settings"])
    return PatternDatabase(settings, s, r, lg, k, float(build) if build is not None else float("nan"), "disk")


def clear_memory_cache() -> None:
    """Forget the databases held in memory (the next :func:`pattern_database` reads the disk cache)."""
    with _LOCK:
        _MEMORY.clear()


def cache_file(key: dict):
    """Where the database of ``key`` is cached."""
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:24]
    return cache_dir() / "star-patterns" / f"patterns-v{FORMAT_VERSION}-{digest}.npz"


def pattern_database(sky: SkyCatalogue, settings: PatternSettings, *, use_cache: bool = True) -> PatternDatabase:
    """The database of ``sky`` and ``settings``: from memory, else from the disk cache, else built
    (and then written to the cache; a cache that cannot be written is only logged)."""
    key = database_key(sky, settings)
    mkey = json.dumps(key, sort_keys=True)
    with _LOCK:
        if use_cache and mkey in _MEMORY:
            return _MEMORY[mkey]
        path = cache_file(key)
        db = _from_file(path, key, len(sky)) if use_cache and path.is_file() else None
        if db is None:
            db = build_pattern_database(sky, settings)
            log.info("built a star-pattern database of %d patterns in %.2f s", len(db), db.build_seconds)
            if use_cache:
                try:
                    atomic_write_bytes(path, _to_bytes(db, key))
                except Exception as exc:  # noqa: BLE001 - a read-only or full cache only costs a rebuild
                    log.info("cannot write the star-pattern cache %s: %s", path, exc)
        if len(_MEMORY) > 8:
            _MEMORY.clear()
        _MEMORY[mkey] = db
        return db
