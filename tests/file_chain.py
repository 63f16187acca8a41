"""Helpers of the file-chain tests: run ``python -m rigsim`` as a lab would, in a subprocess, and a
rig file derived from a packaged one (cheaper cameras, a search that starts near its null)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

__all__ = ["assert_rel", "derived_rig", "rigsim", "rigsim_in_process"]


def rigsim(*args, cwd=None, ok=(0,), timeout=300, stdin=None) -> subprocess.CompletedProcess:
    """``python -m rigsim ARGS`` in a subprocess; its exit status must be in ``ok``."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    p = subprocess.run([sys.executable, "-m", "rigsim", *map(str, args)], cwd=cwd, capture_output=True, text=True,
                       timeout=timeout, env=env, input=stdin)
    assert p.returncode in ok, f"rigsim {' '.join(map(str, args))}: exit {p.returncode}\n{p.stderr[-2000:]}"
    return p


def rigsim_in_process(*args, cwd=None, ok=(0,)) -> subprocess.CompletedProcess:
    """``rigsim ARGS`` through :func:`rigsim.cli.main` in this process (from ``cwd``), the same body the
    subprocess runs without the interpreter's start-up: for the repeats of a command a test has already run
    as a subprocess. Its exit status must be in ``ok``; its output is returned as :func:`rigsim`'s."""
    import contextlib
    import io

    from rigsim.cli import main

    argv = [str(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.chdir(cwd or os.getcwd()), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(argv)
    assert rc in ok, f"rigsim {' '.join(argv)}: exit {rc}\n{err.getvalue()[-2000:]}"
    return subprocess.CompletedProcess(["rigsim", *argv], rc, out.getvalue(), err.getvalue())


def derived_rig(name: str, dst: Path, edits: dict[str, str]) -> Path:
    """The packaged rig ``name`` with whole lines replaced: ``edits`` maps a regular expression matching one
    line (anchored at its start) to its new text."""
    from rigsim.rig.load import resolve_rig_path

    text = resolve_rig_path(name).read_text()
    for pat, new in edits.items():
        text, n = re.subn(rf"^{pat}.*$", new, text, count=1, flags=re.M)
        assert n == 1, f"{name}: no line matches {pat!r}"
    dst.write_text(text)
    return dst


def assert_rel(a, b, rel=1e-9):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert a.shape == b.shape and np.max(np.abs(a - b)) <= rel * np.max(np.abs(b)), (a, b)


def read(path) -> dict:
    return json.loads(Path(path).read_text())
