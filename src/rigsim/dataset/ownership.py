"""One run owns a dataset folder at a time: an OS file lock (filelock; released by the kernel when the
holder dies, so a killed run never leaves the folder locked) plus a note naming the holder."""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import os
import socket
from pathlib import Path

from rigsim.errors import DatasetError
from rigsim.files.atomic import atomic_write_bytes

LOCK_FILE = "dataset.lock"
OWNER_FILE = "dataset.lock.owner.json"
# files of the folder that are not part of the dataset (verify does not list them as extra)
BOOKKEEPING = (LOCK_FILE, OWNER_FILE)


def _holder(root: Path, owner_file: str = OWNER_FILE) -> str:
    from rigsim.files.results import parse_json

    try:
        o = parse_json((root / owner_file).read_bytes(), root / owner_file, "lock note", max_bytes=1 << 16)
        return f"pid {int(o['pid'])} on {o['host']}, {o['command']}, since {o['since_utc']}"
    except (OSError, ValueError, KeyError, TypeError):
        return "holder unknown"


@contextlib.contextmanager
def dataset_lock(root, command: str, *, lock_file: str = LOCK_FILE, owner_file: str = OWNER_FILE):
    """Hold ``root``'s lock for the block; another holder → one-line DatasetError naming it. Other
    folders that one run must own (a robustness report's) name their own ``lock_file`` and
    ``owner_file``."""
    from filelock import FileLock, Timeout

    root = Path(root)
    path = root / lock_file
    if path.is_symlink() or (path.exists() and not path.is_file()):
        raise DatasetError(f"{path}: is a link or not a regular file; remove it (rigsim creates its own lock file)")
    lock = FileLock(str(path), timeout=0, mode=0o644)
    try:
        lock.acquire()
    except Timeout:
        raise DatasetError(f"{root}: in use by another run ({_holder(root, owner_file)}); wait for it or choose another --out") \
            from None
    except OSError as e:
        raise DatasetError(f"{path}: cannot lock the folder ({e.strerror or e})") from None
    try:
        note = {"pid": os.getpid(), "host": socket.gethostname(), "command": command,
                "since_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
        atomic_write_bytes(root / owner_file, (json.dumps(note) + "\n").encode())
        yield
    finally:
        with contextlib.suppress(OSError):
            (root / owner_file).unlink()
        lock.release()


def remove_stale_temporaries(root) -> int:
    """Delete the temporary files that killed runs left (``.NAME.XXXX.tmp`` from the atomic writer, and
    the older ``.NAME.tmp-PID``): never under a final name, never read. Call only while holding the lock.
    Returns how many were removed."""
    root = Path(root)
    n = 0
    for d in (root, root / "frames"):
        if not d.is_dir() or d.is_symlink():
            continue
        for p in list(d.glob(".*.tmp")) + list(d.glob(".*.tmp-*")):
            if p.is_file() or p.is_symlink():
                with contextlib.suppress(OSError):
                    p.unlink()
                    n += 1
    return n
