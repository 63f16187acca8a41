"""Names that become paths: a file stem given on the command line must stay in its output folder, and a
name read from a rig file becomes a folder name only through :func:`slug`."""

from __future__ import annotations

import re

STEM = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+-]{0,99}")
STEM_RULE = "1 to 100 letters, digits, '.', '_', '+' or '-', starting with a letter or digit (no folder)"


def printable(s, limit: int = 200) -> str:
    """``s`` for a terminal: control characters escaped (\\x1b, \\n, …), at most ``limit`` characters."""
    out = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in str(s))
    return out if len(out) <= limit else out[: limit - 1] + "…"


def check_stem(value: str) -> str:
    """``value`` if it is a safe file stem, else ValueError naming the rule (argparse ``type=``)."""
    if not isinstance(value, str) or not STEM.fullmatch(value):
        raise ValueError(STEM_RULE)
    return value


def slug(name: str, limit: int = 60) -> str:
    """A folder-safe form of a free-text name: every run of other characters becomes '_'."""
    s = re.sub(r"[^A-Za-z0-9._+-]+", "_", str(name)).strip("._") or "rig"
    return s[:limit]


def file_stem(value: str) -> str:
    """argparse ``type=`` of ``--name``: a safe file stem, else the rule in argparse's one-line error."""
    import argparse

    try:
        return check_stem(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{printable(value)!r} is not a file stem: {STEM_RULE}") from None
