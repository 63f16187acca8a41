"""The finished trials of a robustness run, one small JSON file each in the report folder, so that a
run that is killed or fails resumes where it stopped. A trial is reused only when the rig, the effects
studied, the trial function, rigsim's source and the renderer's version are all the same, and when its
own checksum (SHA-256 of its canonical JSON, written beside the values) still holds: a trial edited by
hand, or damaged, is run again, never reused (as a dataset's frames)."""

from __future__ import annotations

import hashlib
import json
import re
import shutil
from importlib import metadata
from pathlib import Path

from rigsim.errors import InputError
from rigsim.files.atomic import atomic_write_bytes, output_folder

__all__ = ["FOLDER", "TrialStore", "run_key", "source_digest"]

FOLDER = "robustness-trials"
FORMAT = "rigsim.robustness-trial/2"  # /2: with its own checksum ("sha256")


def _checksum(doc: dict) -> str:
    """SHA-256 of the trial's canonical JSON (sorted keys, no spaces), its "sha256" left out."""
    body = {k: v for k, v in doc.items() if k != "sha256"}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def source_digest() -> str:
    """SHA-256 of every Python file of the rigsim package (path and bytes): any edit changes it."""
    import rigsim

    root = Path(rigsim.__file__).resolve().parent
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


def _versions() -> dict[str, str]:
    out = {}
    for name in ("mitsuba", "drjit", "numpy", "scipy", "opencv-python-headless"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "absent"
    return out


def run_key(rig, names, trial_fn) -> str:
    """What a stored trial must match to be reused: the rig (every field), the effects studied, the
    trial function, rigsim's source and the versions of the packages that make the numbers."""
    ident = {"rig": json.loads(rig.model_dump_json()), "names": list(names),
             "trial": f"{trial_fn.__module__}.{trial_fn.__qualname__}", "source": source_digest(),
             "versions": _versions()}
    return hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()


def _slug(config: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "-", config).strip("-").lower() or "config"


class TrialStore:
    """``folder``/<config>-seed<seed>.json per finished trial, reused when its key is ``key``."""

    def __init__(self, folder, key: str):
        self.folder, self.key = Path(folder), str(key)

    def _path(self, config: str, seed: int) -> Path:
        return self.folder / f"{_slug(config)}-seed{int(seed)}.json"

    def get(self, config: str, seed: int) -> dict | None:
        """The stored values of (``config``, ``seed``), or None when absent, unreadable, edited since it was
        written (its checksum does not hold) or from another rig, source or version (such a file is then
        overwritten)."""
        from rigsim.files.results import parse_json

        p = self._path(config, seed)
        if self.folder.is_symlink() or p.is_symlink() or not p.is_file():
            return None
        try:
            d = parse_json(p.read_bytes(), p, "kept trial", max_bytes=16 << 20)
        except (OSError, ValueError):
            return None
        if not isinstance(d, dict) or d.get("format") != FORMAT or d.get("key") != self.key \
                or d.get("config") != config or d.get("seed") != int(seed) or not isinstance(d.get("values"), dict):
            return None
        if d.get("sha256") != _checksum(d):
            return None
        return d["values"]

    def _refuse_link(self) -> None:
        if self.folder.is_symlink():
            raise InputError(f"{self.folder}: is a link; rigsim keeps its robustness trials in a plain folder of the "
                             "report folder (remove the link)")

    def create(self) -> Path:
        """The folder, created if missing (a link is refused: nothing is written outside the report folder)."""
        self._refuse_link()
        return output_folder(self.folder, "robustness trials folder")

    def put(self, config: str, seed: int, values: dict) -> None:
        self.create()
        doc = {"format": FORMAT, "key": self.key, "config": config, "seed": int(seed), "values": values}
        doc = json.loads(json.dumps(doc))  # the checksum is of what is read back (tuples become lists)
        doc["sha256"] = _checksum(doc)
        atomic_write_bytes(self._path(config, seed), (json.dumps(doc) + "\n").encode())

    def count(self, configs, seeds) -> int:
        """How many of the (config, seed) trials are stored and reusable."""
        return sum(self.get(c, s) is not None for c in configs for s in seeds)

    def clear(self) -> None:
        """Remove the folder (after the report is written). Refuses a link: it never deletes
        outside the report folder."""
        self._refuse_link()
        if self.folder.is_dir():
            shutil.rmtree(self.folder)
