"""The orbit scenario's ROI frames rendered by two processes: this one and one worker subprocess.

A frame is a pure function of its renderer (camera, detector), the camera state and the frame's seed:
it is rendered on one Dr.Jit thread, and its truth and detector noise are seeded per frame. So which
process renders a frame does not change a bit of it, and the frames are the same for any number of
workers. The worker renders the frames of the cameras it is given, this process the others.

The worker is a fresh interpreter started as ``python -m rigsim.procedures.boresight.frame_pool`` (not
multiprocessing's spawn, which re-imports the caller's main script: a script without an
``if __name__ == "__main__"`` guard would run again in the worker). It reads its renderers and its
whole task list as one message on stdin and streams the frames back on its stdout (length-prefixed
pickles; anything else the worker prints goes to stderr). If it cannot start, dies, or stays silent
for :data:`SILENCE_S`, :meth:`FramePool.result` returns ``None`` after one warning, and the caller
renders the frame itself: the same frames, slower.
"""

from __future__ import annotations

import os
import pickle
import queue
import struct
import subprocess
import sys
import threading
import warnings
from pathlib import Path

__all__ = ["SILENCE_S", "FramePool", "Task", "default_workers", "render_task"]

SILENCE_S = 180.0   # the longest wait for the worker's next message (start-up and kernel compilation included)
_HEADER = struct.Struct("<Q")

# (camera, detector, E_hrc or None, delta_f_mm, seed, with_truth)
Task = tuple


def default_workers() -> int:
    """2 when this process may use two or more CPUs, else 1 (no worker)."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        n = os.cpu_count() or 1
    return 2 if n > 1 else 1


def render_task(renderers: dict, task: Task):
    """The frame of ``task`` from ``renderers`` ({(camera, detector): LoopRenderer})."""
    c, j, E, df, seed, with_truth = task
    return renderers[(c, j)].render(E, df, seed=seed, with_truth=with_truth)


def _send(stream, obj) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)))
    stream.write(data)
    stream.flush()


def _recv(stream):
    """The next message, or ``EOFError`` when the stream ends."""
    head = stream.read(_HEADER.size)
    if len(head) < _HEADER.size:
        raise EOFError
    (n,) = _HEADER.unpack(head)
    data = stream.read(n)
    if len(data) < n:
        raise EOFError
    return pickle.loads(data)


class FramePool:
    """Renders ``tasks`` (a list of :data:`Task`) of the cameras in ``remote`` in a worker subprocess,
    started at once; :meth:`result` (i) returns task i's frame when it is the worker's, ``None`` when the
    worker failed (render it here). ``spp``: the renderers' samples per pixel (``None``: the rig's)."""

    def __init__(self, rig, tasks: list, remote: set, spp: int | None = None):
        self._index = {i: t for i, t in enumerate(tasks) if t[0] in remote}
        self._results: dict = {}
        self._inbox: queue.Queue = queue.Queue()
        self._failed = False
        self._proc = None
        if not self._index:
            return
        keys = sorted({(t[0], t[1]) for t in self._index.values()})
        message = {"rig": rig, "renderers": keys, "spp": spp, "tasks": self._index}
        root = str(Path(__file__).resolve().parents[3])   # the folder holding this rigsim package
        env = dict(os.environ)
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        try:
            self._proc = subprocess.Popen([sys.executable, "-m", __name__], stdin=subprocess.PIPE,
                                          stdout=subprocess.PIPE, env=env)
        except OSError as exc:
            self._fail(f"could not start ({exc})")
            return
        self._thread = threading.Thread(target=self._talk, args=(message,), daemon=True,
                                        name="rigsim-boresight-frames")
        self._thread.start()

    def _talk(self, message) -> None:
        """The worker's pipes: send the one message, then queue every reply until the stream ends."""
        try:
            _send(self._proc.stdin, message)
            self._proc.stdin.close()
            while True:
                self._inbox.put(_recv(self._proc.stdout))
        except Exception as exc:  # noqa: BLE001  (EOF, a broken pipe, an unpicklable reply: the worker is gone)
            self._inbox.put(("gone", exc))

    def result(self, i: int):
        """Task i's frame, rendered by the worker (its warnings re-emitted here), or ``None``: render it here."""
        if self._failed or i not in self._index:
            return None
        while i not in self._results:
            try:
                kind, *rest = self._inbox.get(timeout=SILENCE_S)
            except queue.Empty:
                self._fail(f"silent for {SILENCE_S:.0f} s")
                return None
            if kind == "frame":
                k, frame, caught = rest
                self._results[k] = (frame, caught)
            elif kind == "error":
                self._fail(f"failed: {rest[0]}")
                return None
            elif kind == "gone":
                code = self._proc.poll() if self._proc is not None else None
                self._fail("stopped" + (f" (exit status {code})" if code is not None else f" ({type(rest[0]).__name__})"))
                return None
        frame, caught = self._results.pop(i)
        for category, text in caught:
            warnings.warn(text, category, stacklevel=2)
        return frame

    def _fail(self, why: str) -> None:
        self._failed = True
        warnings.warn(f"boresight render worker {why}; rendering its frames in this process (same frames, slower)",
                      RuntimeWarning, stacklevel=3)
        self.close()

    def close(self) -> None:
        """Stop the worker (at once if it is still rendering)."""
        p, self._proc = self._proc, None
        if p is None:
            return
        if p.poll() is None:
            p.kill()
        p.wait()
        for s in (p.stdin, p.stdout):
            try:
                s.close()
            except OSError:
                pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _serve() -> None:
    """The worker: read the message, build the renderers, render the tasks in order, reply per frame."""
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)              # whatever else writes to stdout (Mitsuba's log, a print) goes to stderr
    sys.stdout = sys.stderr
    msg = _recv(sys.stdin.buffer)
    from rigsim.render.boresight import LoopRenderer

    rends = {key: LoopRenderer(msg["rig"], key[0], key[1], spp=msg["spp"]) for key in msg["renderers"]}
    for r in rends.values():
        r.warm_up()
    for i, task in msg["tasks"].items():
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                frame = render_task(rends, task)
        except Exception as exc:  # noqa: BLE001  (reported to the caller, which renders the frame itself)
            _send(out, ("error", f"{type(exc).__name__}: {exc}"))
            return
        _send(out, ("frame", i, frame, [(w.category, str(w.message)) for w in caught]))
    out.close()


if __name__ == "__main__":
    _serve()
