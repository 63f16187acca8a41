"""Lists of input files read as one set: each file once, and (where files are matched to a log or a table by
their name) each base name once."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from rigsim.errors import InputError

from .names import printable

__all__ = ["check_distinct"]


def check_distinct(paths: Sequence, label: str, *, by_name: bool = True, what: str = "frame") -> None:
    """Refuse the same file listed twice (by device and inode: a second spelling, a link or a hard link is the
    same file) and, with ``by_name``, two files of the same base name in different folders (a log row or a
    table's ``frame`` cell names a file by its base name: both would take the same row)."""
    ids: dict[tuple[int, int], str] = {}
    names: dict[str, str] = {}
    for p in paths:
        s = str(p)
        try:
            st = os.stat(s)
            key = (st.st_dev, st.st_ino)
        except (OSError, ValueError):
            key = None
        if key is not None and key in ids:
            raise InputError(f"{label} {printable(s)}: the same file as {printable(ids[key])}, listed twice; give each "
                             f"{what} once (a {what} counted twice is not new data)")
        name = Path(s).name
        if by_name and name in names:
            raise InputError(f"{label} {printable(s)} and {printable(names[name])}: two {what}s named {printable(name)!r} in "
                             f"different folders; {what}s are matched by their file name: rename one")
        if key is not None:
            ids[key] = s
        names[name] = s
