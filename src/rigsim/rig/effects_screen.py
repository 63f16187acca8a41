"""The ``[effects]`` of the diaphragm screen and the aiming camera (the 2-axis cube-mirror rig).

docs/effects.md gives every default value and its source.
"""

from __future__ import annotations

from rigsim.rig.effects import EffectsTable

__all__ = ["ScreenEffects"]


class ScreenEffects(EffectsTable):
    """Effects of the diaphragm screen and the aiming camera (the 2-axis cube-mirror rig)."""
