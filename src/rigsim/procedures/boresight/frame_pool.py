"""The orbit scenario's ROI frames rendered by two processes: this one and one worker subprocess.

A frame is a pure function of its renderer (camera, detector), the camera state and the frame's seed:
it is rendered on one Dr.Jit thread, and its truth and detector noise are seeded per frame. So which
process renders a frame does not change a bit of it, and the frames are the same for any number of
workers. The worker renders the frames of the cameras it is given, this process the others.

The worker is a fresh interpreter started as ``python -m rigsim.procedures.boresight.frame_pool`` (not
multiprocessing's spawn, which re-imports the caller's main script: a script without an
``if __name__ == "__main__"`` guard would run again in the worker). It reads its renderers and its
whole task list as two messages on stdin (so it can start, and compile its kernels, before the tasks
are known) and streams the frames back on its stdout (length-prefixed pickles; anything else the worker
prints goes to stderr). If it cannot start, dies, or stays silent
for :data:`SILENCE_S`, :meth:`FramePool.result` returns ``None`` after one warning, and the caller
renders the frame itself: the same frames, slower.
"""

from __future__ import annotations

import contextlib
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
    """A worker subprocess rendering the frames of the cameras in ``remote`` (both detectors; ``spp``: the
    renderers' samples per pixel, ``None``: the rig's). It starts at once and builds and warms up its
    renderers while the caller does other work; :meth:`start` then hands it the task list (a list of
    :data:`Task`), and :meth:`result` (i) returns task i's frame when it is the worker's, ``None`` when
    it is not or the worker failed (render it here). No worker when ``remote`` is empty."""

    def __init__(self, rig, remote=(), spp: int | None = None):
        self.remote = frozenset(int(c) for c in remote)
        self._index: dict = {}
        self._results: dict = {}
        self._inbox: queue.Queue = queue.Queue()
        self._outbox: queue.Queue = queue.Queue()
        self._failed = False
        self._proc = None
        if not self.remote:
            return
        init = {"rig": rig, "renderers": [(c, j) for c in sorted(self.remote) for j in range(2)], "spp": spp}
        root = str(Path(__file__).resolve().parents[3])   # the folder holding this rigsim package
        env = dict(os.environ)
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        try:
            # its own session: a Ctrl-C reaches this process only, which stops the worker (no second traceback)
            self._proc = subprocess.Popen([sys.executable, "-m", __name__], stdin=subprocess.PIPE,
                                          stdout=subprocess.PIPE, env=env, start_new_session=True)
        except OSError as exc:
            self._fail(f"could not start ({exc})")
            return
        threading.Thread(target=self._talk, args=(self._proc, init), daemon=True, name="rigsim-boresight-frames").start()

    def start(self, tasks: list) -> None:
        """Hand the worker its tasks: those of ``tasks`` whose camera is remote (indices are kept)."""
        self._index = {i: t for i, t in enumerate(tasks) if t[0] in self.remote}
        self._outbox.put(self._index)

    def _talk(self, proc, init) -> None:
        """The worker's pipes: send the renderers, then the tasks, then queue every reply until the stream ends."""
        try:
            _send(proc.stdin, init)
            tasks = self._outbox.get()
            if tasks is None:   # closed before any task
                return
            _send(proc.stdin, tasks)
            proc.stdin.close()
            while True:
                self._inbox.put(_recv(proc.stdout))
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
        self._outbox.put(None)
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
    """The worker: build and warm up the renderers, read the tasks, render them in order, reply per frame.
    An error is one message (the caller renders the frames itself and meets it there)."""
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)              # whatever else writes to stdout (Mitsuba's log, a print) goes to stderr
    sys.stdout = sys.stderr
    try:
        init = _recv(sys.stdin.buffer)
        from rigsim.render.boresight import LoopRenderer

        rends = {key: LoopRenderer(init["rig"], key[0], key[1], spp=init["spp"]) for key in init["renderers"]}
        for r in rends.values():
            r.warm_up()
        tasks = _recv(sys.stdin.buffer)
        for i, task in tasks.items():
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                frame = render_task(rends, task)
            _send(out, ("frame", i, frame, [(w.category, str(w.message)) for w in caught]))
    except EOFError:   # the caller closed before sending the tasks
        return
    except Exception as exc:  # noqa: BLE001  (reported to the caller, which renders the frames itself)
        with contextlib.suppress(OSError):   # unless the caller is gone
            _send(out, ("error", f"{type(exc).__name__}: {exc}"))
    finally:
        with contextlib.suppress(OSError):
            out.close()


if __name__ == "__main__":
    _serve()
