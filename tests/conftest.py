"""Project-wide test rules.

Tests marked ``@pytest.mark.slow`` are skipped in the default run (which must stay well under
ten minutes on 2 cores) and run with ``-m slow`` or ``RIGSIM_SLOW=1``; .ci/run runs them after
the default suite.
"""

import os

import pytest


def _slow_requested(config) -> bool:
    expr = config.getoption("markexpr") or ""
    return ("slow" in expr and "not slow" not in expr) or os.environ.get("RIGSIM_SLOW") == "1"


def pytest_collection_modifyitems(config, items):
    if _slow_requested(config):
        return
    skip = pytest.mark.skip(reason="slow: run with -m slow or RIGSIM_SLOW=1")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
