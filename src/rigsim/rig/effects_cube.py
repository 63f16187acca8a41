"""The ``[effects]`` table of a cube-mirror rig: the sun sensor's effects (both rigs), and the
diaphragm screen's and aiming camera's (method ``diaphragm``) or the autocollimator's (method
``autocollimator``)."""

from __future__ import annotations

from rigsim.rig.effects_autocollimator import AutocollimatorEffects
from rigsim.rig.effects_screen import ScreenEffects
from rigsim.rig.effects_sun import SunSensorEffects

__all__ = ["CubeMirrorEffects", "cube_effect_names"]


class CubeMirrorEffects(AutocollimatorEffects, ScreenEffects, SunSensorEffects):
    """Every cube-mirror effect (the sun sensor's first, in the rig file's order: pydantic collects
    the fields of the bases last to first); :func:`cube_effect_names` says which apply to a method."""


def cube_effect_names(method: str) -> tuple[str, ...]:
    """The effects that apply to a rig measuring its cube by ``method`` (diaphragm / autocollimator)."""
    other = AutocollimatorEffects if method == "diaphragm" else ScreenEffects
    return tuple(n for n in CubeMirrorEffects.names() if n not in other.names())
