"""argparse types for numeric options: a value outside its range (or not finite) is refused while the
command line is parsed, with argparse's one-line error naming the option, the value and the range."""

from __future__ import annotations

import argparse
import math


def integer(lo: int, hi: int):
    """An integer option in [lo, hi]."""

    def parse(text: str) -> int:
        try:
            v = int(text)
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
            v = float(text)
        except (TypeError, ValueError):
            v = math.nan
        if not (math.isfinite(v) and lo <= v <= hi):
            raise argparse.ArgumentTypeError(f"{text!r} is not a number from {lo:g} to {hi:g}")
        return v

    parse.__name__ = f"number in [{lo:g}, {hi:g}]"
    return parse


SEED = integer(0, 2**63 - 1)  # every seed: numpy's SeedSequence and Mitsuba's sampler take it whole
SPP = integer(1, 65536)
