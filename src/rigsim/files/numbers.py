"""Numbers in a user's text (table cells, options, ``X=181.4`` readings) read with one strict grammar:
ASCII digits only. Python's ``float`` and ``int`` also take other scripts' digits (``١٢`` is 12) and
underscores (``1_0`` is 10), so a cell typed in another keyboard layout or a digit group would pass as a
different number."""

from __future__ import annotations

import re

__all__ = ["FLOAT_RULE", "INT_RULE", "MAX_NUMBER_CHARS", "parse_float", "parse_int"]

_FLOAT = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_SPECIAL = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)
_INT = re.compile(r"[+-]?[0-9]+")
MAX_NUMBER_CHARS = 64
FLOAT_RULE = "a number in ASCII digits (e.g. 12, -0.5, 1.5e-3)"
INT_RULE = "an integer in ASCII digits"


def parse_float(text: str, *, special: bool = True) -> float:
    """``text`` (surrounding spaces ignored) as a float, or ValueError. ``special``: also ``nan``, ``inf``,
    ``infinity`` (any case, signed), which the caller then checks."""
    t = str(text).strip()
    if len(t) > MAX_NUMBER_CHARS or not (_FLOAT.fullmatch(t) or (special and _SPECIAL.fullmatch(t))):
        raise ValueError(FLOAT_RULE)
    return float(t)


def parse_int(text: str) -> int:
    """``text`` (surrounding spaces ignored) as an integer of at most 64 digits, or ValueError."""
    t = str(text).strip()
    if len(t) > MAX_NUMBER_CHARS or not _INT.fullmatch(t):
        raise ValueError(INT_RULE)
    return int(t)
