"""The 4-star pattern database: its contents against a direct computation, the lattice's coverage,
the hash lookup, and the disk cache (reused when whole, rebuilt when corrupt, stale or tampered with,
never fatal when it cannot be written)."""

from __future__ import annotations

import io
import itertools
import json
import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from rigsim.estimation import star_patterns as sp
from rigsim.optics.sky import SkyCatalogue

SETTINGS = sp.pattern_settings(math.radians(9.0))  # a 20° sensor's inscribed circle, roughly


@pytest.fixture(scope="module")
def sky5():
    return SkyCatalogue.load(5.0, 2020.0)  # ~1600 stars: a database in a fraction of a second


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("RIGSIM_CACHE_DIR", str(tmp_path / "cache"))
    sp.clear_memory_cache()
    yield tmp_path / "cache"
    sp.clear_memory_cache()


def test_patterns_hold_what_a_direct_computation_gives(sky5):
    db = sp.build_pattern_database(sky5, SETTINGS)
    assert len(db) > 1000 and np.all(np.diff(db.keys) >= 0)
    rng = np.random.default_rng(1)
    for p in rng.choice(len(db), 200, replace=False):
        v = sky5.vectors[db.stars[p]]
        e = sorted(math.acos(min(1.0, float(v[a] @ v[b]))) for a, b in itertools.combinations(range(4), 2))
        np.testing.assert_allclose(db.largest[p], e[5], rtol=1e-6)
        np.testing.assert_allclose(db.ratios[p], np.array(e[:5]) / e[5], atol=1e-6)
        assert e[5] <= 2 * SETTINGS.field_radius_rad  # four stars of one field
        assert len(set(db.stars[p].tolist())) == 4
        # the hash finds the pattern from its own ratios
        q, hits = db.lookup(db.ratios[p][None] - 1e-4, db.ratios[p][None] + 1e-4,
                            np.array([db.largest[p] - 1e-6]), np.array([db.largest[p] + 1e-6]))
        assert p in hits
    # no two pattern stars closer than the separation
    used = np.unique(db.stars)
    pairs = cKDTree(sky5.vectors[used]).query_pairs(2 * math.sin(SETTINGS.min_separation_rad / 2))
    assert len(pairs) == 0


def test_lattice_covers_the_sphere_within_its_radius():
    r = math.radians(3.0)
    pts = sp.fibonacci_lattice(sp.lattice_size(r))
    probe = np.random.default_rng(2).normal(size=(100_000, 3))
    probe /= np.linalg.norm(probe, axis=1, keepdims=True)
    d, _ = cKDTree(pts).query(probe)
    assert 2 * math.asin(d.max() / 2) <= r
    assert 2 * math.asin(d.max() / 2) > 0.7 * r  # and not wastefully dense


def test_database_cached_on_disk_and_reused(sky5, cache):
    db = sp.pattern_database(sky5, SETTINGS)
    assert db.source == "built"
    path = sp.cache_file(sp.database_key(sky5, SETTINGS))
    assert path.is_file() and path.parent.parent == cache
    assert sp.pattern_database(sky5, SETTINGS) is db  # memory
    sp.clear_memory_cache()
    again = sp.pattern_database(sky5, SETTINGS)
    assert again.source == "disk"
    for name in ("stars", "ratios", "largest", "keys"):
        np.testing.assert_array_equal(getattr(again, name), getattr(db, name))


def _rebuilt(sky, path) -> bool:
    sp.clear_memory_cache()
    db = sp.pattern_database(sky, SETTINGS)
    sp.clear_memory_cache()
    assert sp.pattern_database(sky, SETTINGS).source == "disk"  # and the rebuilt file is whole
    return db.source == "built"


def test_corrupt_cache_rebuilt(sky5, cache):
    sp.pattern_database(sky5, SETTINGS)
    path = sp.cache_file(sp.database_key(sky5, SETTINGS))
    whole = path.read_bytes()
    path.write_bytes(np.random.default_rng(3).bytes(5000))       # garbage
    assert _rebuilt(sky5, path)
    path.write_bytes(whole[: len(whole) // 2])                   # cut short (a killed writer)
    assert _rebuilt(sky5, path)
    path.write_bytes(b"")                                         # empty
    assert _rebuilt(sky5, path)


def test_tampered_arrays_rebuilt(sky5, cache):
    sp.pattern_database(sky5, SETTINGS)
    path = sp.cache_file(sp.database_key(sky5, SETTINGS))
    with np.load(path) as z:
        arrays = {k: z[k].copy() for k in z.files}
    arrays["ratios"][10, 2] += 0.01                               # one ratio changed, header kept
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path.write_bytes(buf.getvalue())
    assert _rebuilt(sky5, path)
    arrays["stars"] = arrays["stars"].astype(np.int64)            # right numbers, wrong type
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path.write_bytes(buf.getvalue())
    assert _rebuilt(sky5, path)


def test_stale_cache_rebuilt(sky5, cache):
    """A file at the expected name built for other inputs (another epoch, other settings, an older
    format) is not trusted."""
    path = sp.cache_file(sp.database_key(sky5, SETTINGS))
    other = SkyCatalogue.load(5.0, 2030.0)
    sp.pattern_database(other, SETTINGS)
    path.write_bytes(sp.cache_file(sp.database_key(other, SETTINGS)).read_bytes())
    assert _rebuilt(sky5, path)
    with np.load(path) as z:
        arrays = {k: z[k].copy() for k in z.files}
    header = json.loads(str(arrays["header"][()]))
    header["format"] = sp.FORMAT_VERSION - 1
    arrays["header"] = np.array(json.dumps(header, sort_keys=True))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path.write_bytes(buf.getvalue())
    assert _rebuilt(sky5, path)
    assert sp.database_key(sky5, SETTINGS) != sp.database_key(sky5, sp.pattern_settings(math.radians(8.0)))
    assert sp.database_key(sky5, SETTINGS) != sp.database_key(SkyCatalogue.load(5.5, 2020.0), SETTINGS)


def test_unwritable_cache_only_costs_a_rebuild(sky5, tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("RIGSIM_CACHE_DIR", str(blocker))
    sp.clear_memory_cache()
    db = sp.pattern_database(sky5, SETTINGS)
    assert db.source == "built" and len(db) > 0
    sp.clear_memory_cache()
