"""Old vs new, side by side, in one run: the harness every speed benchmark uses.

The old code path is the package as it was at a git commit (``--base``, default the last commit
before the speed work), extracted with ``git archive`` into a temporary folder. Each case runs the
same Python snippet in fresh subprocesses, once with that old ``src/`` on ``PYTHONPATH`` and once
with the working tree's, alternating old and new so that load on a shared machine hits both alike.
Per side it reports the best and median wall time of the timed statement, the child's peak
resident memory, and whatever the snippet stored in ``result`` (a dict of numbers: accuracy).

A case where the old path no longer exists passes ``old=False`` and prints the measured figure
only. Thread pools are limited by the snippet itself (see docs/performance.md).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BASE = "03aff45"  # the commit before the speed work: "today's code path"

_CHILD = r"""
import json, resource, sys, time
_setup = {setup!r}
_stmt = {stmt!r}
ns = {{}}
exec(compile(_setup, "<setup>", "exec"), ns)
times = []
for _ in range({repeat}):
    t0 = time.perf_counter()
    exec(compile(_stmt, "<stmt>", "exec"), ns)
    times.append(time.perf_counter() - t0)
rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
res = ns.get("result", {{}})
sys.stdout.write("\n@@RESULT@@" + json.dumps({{"times": times, "rss_mb": rss_mb,
                 "result": {{k: float(v) for k, v in dict(res).items()}}}}) + "\n")
"""


@dataclass
class Side:
    times: list[float] = field(default_factory=list)
    rss_mb: float = 0.0
    result: dict = field(default_factory=dict)
    tree_pss_mb: float = 0.0  # with ``tree=True``: peak of the summed PSS of the child's process tree

    @property
    def best(self) -> float:
        return min(self.times)

    @property
    def median(self) -> float:
        t = sorted(self.times)
        return t[len(t) // 2]


def old_src(base: str = BASE) -> Path:
    """The package at ``base`` (extracted once per process into a temporary folder)."""
    cache = getattr(old_src, "_cache", {})
    if base not in cache:
        d = Path(tempfile.mkdtemp(prefix=f"rigsim-old-{base}-"))
        # src/ and the rig files beside it (a default rig is found in the repository's scenes/)
        arc = subprocess.run(["git", "-C", str(REPO), "archive", base, "src", "scenes"], check=True,
                             capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(d)], input=arc, check=True)
        cache[base] = d / "src"
        old_src._cache = cache
    return cache[base]


def _tree_pids(pid: int) -> list[int]:
    """``pid`` and all its descendants (from /proc/<pid>/task/<tid>/children)."""
    out, i = [pid], 0
    while i < len(out):
        try:
            for tid in os.listdir(f"/proc/{out[i]}/task"):
                with open(f"/proc/{out[i]}/task/{tid}/children") as fh:
                    out += [int(x) for x in fh.read().split()]
        except OSError:
            pass
        i += 1
    return out


def _pss_kb(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/smaps_rollup") as fh:
            for line in fh:
                if line.startswith("Pss:"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return 0


class TreeSampler:
    """Polls the summed proportional set size (PSS) of a process and its descendants every ``period``
    seconds in a thread (Linux /proc); ``peak_mb`` is the largest sum seen (shared pages counted once)."""

    def __init__(self, pid: int, period: float = 0.05):
        import threading

        self.pid, self.period, self.peak_mb = int(pid), float(period), 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            total = sum(_pss_kb(p) for p in _tree_pids(self.pid)) / 1024.0
            self.peak_mb = max(self.peak_mb, total)
            self._stop.wait(self.period)

    def stop(self) -> float:
        self._stop.set()
        self._thread.join()
        return self.peak_mb


def run_side(src: Path, setup: str, stmt: str, repeat: int, env: dict | None = None, tree: bool = False) -> Side:
    code = _CHILD.format(setup=textwrap.dedent(setup), stmt=textwrap.dedent(stmt), repeat=int(repeat))
    e = dict(os.environ)
    e.update(env or {})
    e["PYTHONPATH"] = str(src)
    tree_mb = 0.0
    if tree and Path("/proc/self/smaps_rollup").exists():
        p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env=e, cwd=str(REPO))
        sampler = TreeSampler(p.pid)
        out, err = p.communicate()
        tree_mb = sampler.stop()
        p = subprocess.CompletedProcess(p.args, p.returncode, out, err)
    else:
        p = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, env=e,
                           cwd=str(REPO))
    if p.returncode:
        raise RuntimeError(f"benchmark child failed ({src}):\n{p.stderr[-4000:]}")
    payload = p.stdout.rsplit("@@RESULT@@", 1)[1]
    d = json.loads(payload)
    return Side(d["times"], d["rss_mb"], d["result"], tree_mb)


def compare(name: str, setup: str, stmt: str, *, repeat: int = 3, rounds: int = 2, old: bool = True,
            base: str = BASE, env: dict | None = None, target: str = "", tree: bool = False) -> dict:
    """Run ``stmt`` (after ``setup``) under the old and the new package; print one row; return both.

    ``tree``: also sample the summed PSS of the child's process tree (its worker processes included)
    and print its peak under the row."""
    sides = {"old": Side(), "new": Side()}
    new_src = REPO / "src"
    for _ in range(int(rounds)):
        order = (("old", old_src(base)), ("new", new_src)) if old else (("new", new_src),)
        for label, src in order:
            s = run_side(src, setup, stmt, repeat, env, tree=tree)
            sides[label].times += s.times
            sides[label].rss_mb = max(sides[label].rss_mb, s.rss_mb)
            sides[label].tree_pss_mb = max(sides[label].tree_pss_mb, s.tree_pss_mb)
            sides[label].result = s.result
    _print_row(name, sides, old, target)
    return sides


_HEADER_DONE = False


def _print_row(name: str, sides: dict, old: bool, target: str) -> None:
    global _HEADER_DONE
    if not _HEADER_DONE:
        print(f"{'case':<38} {'old best s':>10} {'new best s':>10} {'speed-up':>8} {'old MB':>8} {'new MB':>8}  target")
        _HEADER_DONE = True
    n = sides["new"]
    if old:
        o = sides["old"]
        print(f"{name:<38} {o.best:>10.3f} {n.best:>10.3f} {o.best / n.best:>7.2f}x {o.rss_mb:>8.0f} {n.rss_mb:>8.0f}  {target}")
    else:
        print(f"{name:<38} {'—':>10} {n.best:>10.3f} {'—':>8} {'—':>8} {n.rss_mb:>8.0f}  {target}")
    if any(sides[label].tree_pss_mb for label in sides):
        print(f"{'':<6}peak memory, MB: " + ", ".join(
            f"{label} main-process RSS {sides[label].rss_mb:.0f} / process-tree PSS {sides[label].tree_pss_mb:.0f}"
            for label in (("old", "new") if old else ("new",))))
    for label in ("old", "new") if old else ("new",):
        r = sides[label].result
        if r:
            print(f"{'':<6}{label} result: " + ", ".join(f"{k} {v:.6g}" for k, v in r.items()))
    sys.stdout.flush()


def main_for(doc: str, name: str, setup: str, stmt: str, *, target: str = "", **fmt) -> None:
    """The ``main()`` of a one-case benchmark script: ``--repeat`` and ``--rounds`` options, then
    :func:`compare` with ``setup`` formatted with ``fmt``."""
    import argparse

    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=1, help="timed runs per process (default 1)")
    ap.add_argument("--rounds", type=int, default=1, help="old/new process pairs (default 1)")
    a = ap.parse_args()
    compare(name, setup.format(**fmt), stmt, repeat=a.repeat, rounds=a.rounds, target=target)
