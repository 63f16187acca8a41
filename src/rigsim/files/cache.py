"""Where rigsim keeps what it can rebuild (libLLVM verdicts, star-pattern databases):
``$RIGSIM_CACHE_DIR`` when set, else ``$XDG_CACHE_HOME/rigsim``, else ``~/.cache/rigsim``. Nothing in
it is trusted: every reader checks what it loads and rebuilds it when it does not fit."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_dir"]


def cache_dir() -> Path:
    """The cache folder (not created here; :func:`rigsim.files.atomic_write_bytes` creates it)."""
    base = os.environ.get("RIGSIM_CACHE_DIR")
    if base:
        return Path(base)
    xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(xdg) / "rigsim"
