"""The ``[effects]`` of the sun sensor (both cube-mirror rigs): the sun and its simulator, the cover glass, the pinhole.

docs/effects.md gives every default value and its source.
"""

from __future__ import annotations

from rigsim.rig.effects import EffectsTable

__all__ = ["SunSensorEffects"]


class SunSensorEffects(EffectsTable):
    """Effects of the sun sensor (both cube-mirror rigs): the sun and its simulator, the cover glass, the pinhole."""
