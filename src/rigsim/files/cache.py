"""Where rigsim keeps what it can rebuild (libLLVM verdicts, star-pattern databases, instrument calibrations):
``$RIGSIM_CACHE_DIR`` when set, else ``$XDG_CACHE_HOME/rigsim``, else ``~/.cache/rigsim``. Nothing in
it is trusted: every reader checks what it loads and rebuilds it when it does not fit."""

from __future__ import annotations

import hashlib
import json
import logging
import os
from collections.abc import Callable, Iterable
from pathlib import Path

__all__ = ["cache_dir", "cached_json", "source_digest"]

log = logging.getLogger(__name__)


def cache_dir() -> Path:
    """The cache folder (not created here; :func:`rigsim.files.atomic_write_bytes` creates it)."""
    base = os.environ.get("RIGSIM_CACHE_DIR")
    if base:
        return Path(base)
    xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(xdg) / "rigsim"


def source_digest(files: Iterable) -> str:
    """SHA-256 (hex) of the named source files' bytes: a cache key part that changes with the code that computes."""
    h = hashlib.sha256()
    for f in files:
        h.update(Path(f).read_bytes())
    return h.hexdigest()


def cached_json(kind: str, key: dict, compute: Callable[[], dict], valid: Callable[[dict], bool]) -> dict:
    """``compute()`` (a JSON-able dict) kept in ``cache_dir()/kind/<digest of key>.json`` for other processes.

    A file is used only when it parses, records exactly ``key`` and ``valid`` accepts its value; else
    the value is computed and written (atomic write). A cache that cannot be read or written costs
    only the computation. ``key`` must hold everything the value depends on, the code included
    (:func:`source_digest`)."""
    from rigsim.errors import InputError
    from rigsim.files.atomic import atomic_write_text

    text_key = json.dumps(key, sort_keys=True)
    path = cache_dir() / kind / f"{hashlib.sha256(text_key.encode()).hexdigest()[:32]}.json"
    try:
        doc = json.loads(path.read_text())
        if json.dumps(doc["key"], sort_keys=True) == text_key and isinstance(doc["value"], dict) and valid(doc["value"]):
            return doc["value"]
    except (OSError, ValueError, KeyError, TypeError):
        pass
    value = compute()
    try:
        atomic_write_text(path, json.dumps({"key": key, "value": value}, sort_keys=True))
    except (OSError, InputError) as exc:  # a read-only or full cache folder, a file in its place
        log.info("cannot write the %s cache %s: %s", kind, path, exc)
    return value
