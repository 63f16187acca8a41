"""Project-wide test rules and shared fixtures. The tree mirrors src/rigsim (one folder per layer).

Tests marked ``@pytest.mark.slow`` are skipped in the default run (which must stay well under
ten minutes on 2 cores) and run with ``-m slow`` or ``RIGSIM_SLOW=1``; .ci/run runs them after
the default suite. Tests marked ``@pytest.mark.long`` (each above ~15 minutes on one core: the dense
acceptance campaigns) run only with ``-m long`` or ``RIGSIM_LONG=1``, not in CI (docs/testing.md).
"""

import os

import pytest
from threadpoolctl import threadpool_limits

# the CLI's thread policy (rigsim.render.threads.command_threads): one BLAS thread per process. The
# test workers already share the cores, and multithreaded BLAS on small matrices only spins.
threadpool_limits(limits=1, user_api="blas")


def _hypothesis_without_local_constants() -> None:
    """Hypothesis mixes into its draws the literal constants of every project module loaded in the
    process, and which modules a test worker has loaded depends on the tests it ran before: the
    derandomized random-rig tests then drew other rigs in CI than in a local run of one file, and a
    failing rig could not be replayed. With that pool empty a derandomized test draws the same
    examples in any order and any worker (the global pool of edge values stays)."""
    try:
        from hypothesis.internal.conjecture import providers
    except ImportError:  # pragma: no cover - a hypothesis without the pool
        return
    if hasattr(providers, "_get_local_constants") and hasattr(providers, "Constants"):
        empty = providers.Constants()
        providers._get_local_constants = lambda: empty


_hypothesis_without_local_constants()


def _slow_requested(config) -> bool:
    expr = config.getoption("markexpr") or ""
    return ("slow" in expr and "not slow" not in expr) or os.environ.get("RIGSIM_SLOW") == "1"


def _long_requested(config) -> bool:
    expr = config.getoption("markexpr") or ""
    return ("long" in expr and "not long" not in expr) or os.environ.get("RIGSIM_LONG") == "1"


# imported before the freeze in a large run: the modules tests import later (plots, the 3-D view, Dask, the report
# schema, Parquet, Hypothesis) held ~200k of a worker's ~270k collectable objects at the end of a run
LATE_IMPORTS = ("matplotlib.pyplot", "pyvista", "jsonschema", "pyarrow.parquet", "hypothesis", "sep", "dask.distributed",
                "astropy.wcs", "astropy.io.fits", "astropy.time", "scipy.stats", "scipy.signal")


def _import_everything() -> None:
    import importlib
    import pkgutil

    import matplotlib

    matplotlib.use("Agg")
    import rigsim

    for name in LATE_IMPORTS:
        importlib.import_module(name)
    for m in pkgutil.walk_packages(rigsim.__path__, "rigsim."):
        if not m.name.endswith("__main__"):
            importlib.import_module(m.name)


def pytest_collection_finish(session):
    """Everything imported by collection (numpy, scipy, Mitsuba, astropy, the test modules: ~200k objects) moves to
    the garbage collector's permanent generation. Every new Mitsuba scene runs a full collection (Scene frees the
    cycles of earlier scenes first); it cost ~0.15 s a scene over those objects, ~0.002 s once they are frozen.
    In a run of more than 200 tests every rigsim module and the libraries tests import later are imported first
    (~1.5 s), so that they are frozen too. Nothing frozen is ever garbage: no scene exists yet."""
    import gc

    if len(session.items) > 200:
        _import_everything()
    gc.collect()
    gc.freeze()


def pytest_collection_modifyitems(config, items):
    slow, long = _slow_requested(config), _long_requested(config)
    skip_slow = pytest.mark.skip(reason="slow: run with -m slow or RIGSIM_SLOW=1")
    skip_long = pytest.mark.skip(reason="long: run with -m long or RIGSIM_LONG=1 (not in CI)")
    for item in items:
        if "long" in item.keywords and not long:
            item.add_marker(skip_long)
        elif "slow" in item.keywords and not slow:
            item.add_marker(skip_slow)
    if slow:  # the longest files first (xdist hands out files in this order): no worker is left alone at the end
        items.sort(key=lambda it: (not it.nodeid.startswith("tests/rig/test_random_rig_frames_"),
                                   "_diaphragm" not in it.nodeid))


@pytest.fixture(scope="session")
def star_rig():
    """The default star-sensor rig (seed 004)."""
    from rigsim.rig.load import load_star_rig

    return load_star_rig()


@pytest.fixture(scope="session")
def star_sky(star_rig):
    """Its true sky: the catalogue and the true camera (truth side)."""
    from rigsim.truth.star import StarSky

    return StarSky(star_rig)
