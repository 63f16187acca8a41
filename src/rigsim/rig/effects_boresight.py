"""The ``[effects]`` of the boresight rig: the lasers, the central prism, the camera objectives.

docs/effects.md gives every default value and its source.
"""

from __future__ import annotations

from rigsim.rig.effects import EffectsTable

__all__ = ["BoresightEffects"]


class BoresightEffects(EffectsTable):
    """Effects of the boresight rig: the lasers, the central prism, the camera objectives."""
