"""Derandomized Hypothesis draws do not depend on which project modules a test worker has loaded
(tests/conftest.py empties Hypothesis's pool of the loaded modules' literal constants)."""

import importlib

from hypothesis.internal.conjecture import providers


def test_no_local_constants_enter_the_draws():
    importlib.import_module("rigsim.procedures.cube_mirror.campaign")  # a module full of literals
    assert len(providers._get_local_constants()) == 0
