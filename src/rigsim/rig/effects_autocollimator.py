"""The ``[effects]`` of the photoelectric autocollimator (the 3-axis cube-mirror rig).

docs/effects.md gives every default value and its source.
"""

from __future__ import annotations

from rigsim.rig.effects import EffectsTable

__all__ = ["AutocollimatorEffects"]


class AutocollimatorEffects(EffectsTable):
    """Effects of the photoelectric autocollimator (the 3-axis cube-mirror rig)."""
