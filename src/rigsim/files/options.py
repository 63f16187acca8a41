"""argparse types for numeric options: a value outside its range (or not finite, or not written in ASCII
digits: :mod:`rigsim.files.numbers`) is refused while the command line is parsed, with argparse's one-line
error naming the option, the value and the range."""

from __future__ import annotations

import argparse
import math

from .numbers import parse_float, parse_int


def integer(lo: int, hi: int):
    """An integer option in [lo, hi]."""

    def parse(text: str) -> int:
        try:
            v = parse_int(text)
        except (TypeError, ValueError):
            v = None
        if v is None or not (lo <= v <= hi):
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer from {lo} to {hi}")
        return v

    parse.__name__ = f"integer in [{lo}, {hi}]"
    return parse


def number(lo: float, hi: float):
    """A finite real option in [lo, hi]."""

    def parse(text: str) -> float:
        try:
            v = parse_float(text)
        except (TypeError, ValueError):
            v = math.nan
        if not (math.isfinite(v) and lo <= v <= hi):
            raise argparse.ArgumentTypeError(f"{text!r} is not a number from {lo:g} to {hi:g}")
        return v

    parse.__name__ = f"number in [{lo:g}, {hi:g}]"
    return parse


def real(text: str) -> float:
    """A real option in ASCII digits (its range checked by the command, which names it), ``nan``/``inf`` included."""
    try:
        return parse_float(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"{text!r} is not a number in ASCII digits") from None


SEED = integer(0, 2**63 - 1)  # every seed: numpy's SeedSequence and Mitsuba's sampler take it whole
SPP = integer(1, 65536)
