"""Fault injection for file writers: every file-system step a writer takes, a kill at each of them, and a
model of the disk after a power failure.

``steps(hook)`` wraps, for the duration of a ``with``, the calls through which Python code touches files
(``os.open/write/fsync/fdatasync/close/fchmod/ftruncate/replace/rename/unlink/remove/fdopen``, ``open`` and
``io.open`` and the file objects they return: ``write``, ``flush``, ``close``) and calls ``hook(event, phase)``
before (``phase = 0``) and after (``phase = 1``) each, ``event`` being a tuple such as ``("write", fd, data)``.
A writer that goes around these calls (a C library writing by itself) is not seen: the writers under test
write from Python.

``kill_at(write, n, phase)`` runs ``write()`` in a forked child that SIGKILLs itself just before or just after
its ``n``-th step: the process dies there with whatever the kernel holds, as a ``kill -9`` or an OOM kill would
leave it. ``record(write)`` runs it whole and returns its steps.

``Disk`` replays steps on a model of a journalling file system after a power failure: names (create, rename,
unlink, truncate) reach the disk in the order they were made; a file's data only once ``fsync``'d — data written
and not synced is lost (a new file is empty; a truncated one stays empty). ``Disk.after(events[:k])`` is what a
power cut after step ``k`` leaves when the journal had committed every name made so far;
``Disk.after(events[:k], names="synced")`` when it had committed only those made before the last ``fsync`` of
their folder (POSIX makes a name durable only then). This is the ordering POSIX and ext4/XFS guarantee to a
program that relies on nothing else (fsync of the file before the rename that publishes it, fsync of the folder
before saying the file is written).
"""

from __future__ import annotations

import builtins
import io
import os
import signal
from contextlib import contextmanager
from pathlib import Path

_OS_CALLS = ("open", "write", "fsync", "fdatasync", "close", "fchmod", "ftruncate", "replace", "rename", "unlink",
             "remove", "fdopen")


def _fd(x) -> int:
    return x if isinstance(x, int) else x.fileno()


class _File:
    """A file object whose write, flush and close are steps. A buffered write reaches the kernel later: its
    event carries the file's size in the kernel after the step (``os.fstat``), so the disk model knows how
    much of the data handed to Python an ``fsync`` covers."""

    def __init__(self, f, fire):
        self._f, self._fire = f, fire

    def _size(self, _out=None):
        return os.fstat(self._f.fileno()).st_size

    def write(self, data):
        b = bytes(data) if not isinstance(data, str) else data.encode()
        return self._fire(("write", self._f.fileno(), b, None), lambda: self._f.write(data), self._size)

    def flush(self):
        if self._f.closed:
            return None
        return self._fire(("flush", self._f.fileno(), None), self._f.flush, self._size)

    def close(self):
        if self._f.closed:
            return None
        return self._fire(("close", self._f.fileno()), self._f.close)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def __iter__(self):
        return iter(self._f)

    def __getattr__(self, name):
        return getattr(self._f, name)


def _flags_of_mode(mode: str) -> int:
    f = 0
    if "w" in mode:
        f |= os.O_CREAT | os.O_TRUNC
    if "x" in mode:
        f |= os.O_CREAT | os.O_EXCL
    if "a" in mode:
        f |= os.O_CREAT | os.O_APPEND
    return f


@contextmanager
def steps(hook):
    """Patch the file calls (see the module's docstring) to call ``hook(event, phase)`` around each."""
    real = {name: getattr(os, name) for name in _OS_CALLS}
    real_open, real_io_open = builtins.open, io.open
    busy = []  # re-entrancy: a step inside a step (fdopen -> io.open) is not a step of its own

    def fire(event, call, size=None):
        """``size``: the kernel's size of the file after the step (a buffered write's or flush's last field)."""
        if busy:
            return call()
        busy.append(1)
        try:
            hook(event, 0)
            out = call()
            if event[0] == "open" and event[2] is None:  # the descriptor is known once opened
                event = ("open", event[1], _fd(out), event[3])
            elif size is not None:
                event = event[:-1] + (size(),)
            hook(event, 1)
            return out
        finally:
            busy.pop()

    def os_open(path, flags, mode=0o777, *, dir_fd=None):
        return fire(("open", os.path.abspath(path), None, flags), lambda: real["open"](path, flags, mode, dir_fd=dir_fd))

    def py_open(file, mode="r", *args, **kw):
        if isinstance(file, int) or not any(c in mode for c in "wxa+"):
            f = real_io_open(file, mode, *args, **kw)
        else:
            f = fire(("open", os.path.abspath(file), None, _flags_of_mode(mode)),
                     lambda: real_io_open(file, mode, *args, **kw))
        return _File(f, fire) if any(c in mode for c in "wxa+") else f

    def fdopen(fd, mode="r", *args, **kw):
        f = real_io_open(fd, mode, *args, **kw)
        return _File(f, fire) if any(c in mode for c in "wxa+") else f

    patched = {
        "open": os_open,
        "write": lambda fd, data: fire(("write", fd, bytes(data), -1), lambda: real["write"](fd, data)),
        "fsync": lambda fd: fire(("fsync", _fd(fd)), lambda: real["fsync"](fd)),
        "fdatasync": lambda fd: fire(("fsync", _fd(fd)), lambda: real["fdatasync"](fd)),
        "close": lambda fd: fire(("close", fd), lambda: real["close"](fd)),
        "fchmod": lambda fd, mode: fire(("chmod", _fd(fd)), lambda: real["fchmod"](fd, mode)),
        "ftruncate": lambda fd, n: fire(("truncate", _fd(fd), n), lambda: real["ftruncate"](fd, n)),
        "replace": lambda a, b, **kw: fire(("rename", os.path.abspath(a), os.path.abspath(b)),
                                           lambda: real["replace"](a, b, **kw)),
        "rename": lambda a, b, **kw: fire(("rename", os.path.abspath(a), os.path.abspath(b)),
                                          lambda: real["rename"](a, b, **kw)),
        "unlink": lambda p, **kw: fire(("unlink", os.path.abspath(p)), lambda: real["unlink"](p, **kw)),
        "remove": lambda p, **kw: fire(("unlink", os.path.abspath(p)), lambda: real["remove"](p, **kw)),
        "fdopen": fdopen,
    }
    for name, fn in patched.items():
        setattr(os, name, fn)
    builtins.open = io.open = py_open
    try:
        yield
    finally:
        for name, fn in real.items():
            setattr(os, name, fn)
        builtins.open, io.open = real_open, real_io_open


def record(write) -> list[tuple]:
    """The steps of ``write()`` run whole (each event once, as seen after it ran)."""
    events = []
    with steps(lambda e, phase: events.append(e) if phase else None):
        write()
    return events


def kill_at(write, n: int, phase: int) -> bool:
    """Run ``write()`` in a forked child killed (SIGKILL) just before (``phase`` 0) or after (1) its ``n``-th
    step (from 0). True when the kill happened, False when ``write`` had fewer steps and finished."""
    pid = os.fork()
    if pid == 0:  # the child: never returns into the test runner
        try:
            seen = [0]

            def hook(event, ph):
                if ph == phase:
                    if seen[0] == n:
                        os.kill(os.getpid(), signal.SIGKILL)
                    seen[0] += 1

            with steps(hook):
                write()
        finally:
            os._exit(0)
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        assert os.WTERMSIG(status) == signal.SIGKILL
        return True
    assert os.WEXITSTATUS(status) == 0
    return False


class Disk:
    """The disk after a power failure (see the module's docstring), starting from files that are on it whole."""

    def __init__(self, files: dict[str, bytes]):
        self._inodes = [dict(data=bytearray(v), durable=bytes(v)) for v in files.values()]
        self.names = {os.path.abspath(k): i for i, k in enumerate(files)}
        self._fds: dict[int, int] = {}
        self._handed: dict[int, bytearray] = {}  # per descriptor: bytes handed to a buffered file, not yet in the kernel
        self._dir_fds: dict[int, str] = {}  # descriptors of folders (opened to be synced)
        self.synced_names = dict(self.names)  # the names as of each folder's last fsync

    def _apply(self, e) -> None:
        kind = e[0]
        if kind == "open":
            _, path, fd, flags = e
            if flags & getattr(os, "O_DIRECTORY", 0):  # a folder opened to be synced
                self._dir_fds[fd] = path
                return
            if path not in self.names:
                assert flags & os.O_CREAT, f"opened a missing file {path}"
                self._inodes.append(dict(data=bytearray(), durable=b""))
                self.names[path] = len(self._inodes) - 1
            ino = self._inodes[self.names[path]]
            if flags & os.O_TRUNC:
                ino["data"], ino["durable"] = bytearray(), b""  # the truncation is metadata: it reaches the disk
            self._fds[fd] = self.names[path]
        elif kind == "write" and e[3] == -1:  # os.write: straight into the kernel
            self._inodes[self._fds[e[1]]]["data"] += e[2]
        elif kind == "write":  # a buffered file: the kernel holds what its size says
            self._handed.setdefault(e[1], bytearray()).extend(e[2])
            self._settle(e[1], e[3])
        elif kind == "flush":
            self._settle(e[1], e[2])
        elif kind == "truncate":
            ino = self._inodes[self._fds[e[1]]]
            del ino["data"][e[2]:]
            ino["durable"] = ino["durable"][:e[2]]
        elif kind == "fsync" and e[1] in self._dir_fds:  # the folder's names are on the disk
            folder = self._dir_fds[e[1]]
            self.synced_names = {p: i for p, i in self.synced_names.items() if os.path.dirname(p) != folder}
            self.synced_names.update({p: i for p, i in self.names.items() if os.path.dirname(p) == folder})
        elif kind == "fsync":
            ino = self._inodes[self._fds[e[1]]]
            ino["durable"] = bytes(ino["data"])
        elif kind == "close":  # closing a buffered file hands the kernel the rest
            if e[1] in self._handed:
                self._settle(e[1], None)
                del self._handed[e[1]]
            self._fds.pop(e[1], None)
            self._dir_fds.pop(e[1], None)
        elif kind == "rename":
            self.names[e[2]] = self.names.pop(e[1])
        elif kind == "unlink":
            self.names.pop(e[1])

    def _settle(self, fd: int, size) -> None:
        ino = self._inodes[self._fds[fd]]
        pending = self._handed.get(fd, bytearray())
        have = len(ino["data"])
        take = len(pending) if size is None else max(0, size - have)
        ino["data"] += pending[:take]
        del pending[:take]

    @classmethod
    def after(cls, files: dict[str, bytes], events, names: str = "all") -> dict[str, bytes]:
        """``{path: bytes}`` on the disk after a power cut that follows ``events`` (the start: ``files``), with
        every name made so far (``names="all"``) or only those synced with their folder (``"synced"``)."""
        d = cls(files)
        for e in events:
            d._apply(e)
        table = d.names if names == "all" else d.synced_names
        return {p: d._inodes[i]["durable"] for p, i in table.items()}


def materialise(files: dict[str, bytes], folder: Path) -> None:
    """Write ``{path: bytes}`` (paths under ``folder``'s original, re-rooted by name) into ``folder``."""
    for p, data in files.items():
        q = Path(folder) / Path(p).name
        q.write_bytes(data)
