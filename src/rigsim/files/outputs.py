"""What a command writes, checked against what it reads before anything is written.

A command declares its outputs (:func:`declare`): the options that name a file or a folder it
writes, and the files it derives from them (a residual plot beside ``--out``). Before the command
runs, :func:`check_plan` refuses, with one line, an output that

- names one of the command's inputs, or a file inside an input folder (compared by the file itself:
  device and inode, so a second name, a link or another spelling of the path is the same file);
- names another output of the same command;
- is a folder where a file is written, a file where a folder is, or anything but a regular file
  (a character or block device, a FIFO, a socket, a symbolic link): only regular files (or nothing)
  are ever replaced;
- has an unsupported suffix, a name too long for the file system, or a parent that is a file or
  not writable.

So a command's outputs are either all refused or all written. While the command runs,
:func:`guard` keeps its inputs in a registry that :func:`rigsim.files.atomic.atomic_write_bytes`
consults on every write: a file a command writes inside an output folder (a report, a frame) can
never replace an input either, nor a device node. There a link planted at a file's name is replaced
(never written through) when it points to a regular file or nowhere; a link to a device, a FIFO, a
socket or a folder, or into /proc or /dev (``/dev/stdout``), is refused."""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from rigsim.errors import InputError

from .names import printable

__all__ = ["Output", "check_plan", "check_target", "declare", "declared_outputs", "guard", "protected"]

NAME_MAX = 255 - 14  # the temporary beside the target is ".<name>.XXXXXXXX.tmp" (mkstemp: 8 random characters)
_KINDS = {stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device", stat.S_IFIFO: "a FIFO",
          stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a folder"}


@dataclass(frozen=True)
class Output:
    """A path a command writes: a file (``suffixes``: the allowed name endings, empty for any) or a
    folder it writes into (``folder=True``). ``label`` names it in messages (``--out``)."""

    path: Path
    label: str
    suffixes: tuple[str, ...] = ()
    folder: bool = False


def _kind(mode: int) -> str:
    return _KINDS.get(stat.S_IFMT(mode), "not a regular file")


def _ids(path: Path) -> set[tuple[int, int]]:
    """(device, inode) of the path itself and of what it points to."""
    out = set()
    for fn in (os.lstat, os.stat):
        try:
            st = fn(path)
        except (OSError, ValueError):
            continue
        out.add((st.st_dev, st.st_ino))
    return out


def _entry(path: Path) -> str:
    """The directory entry a write replaces: the parent resolved, the name kept (a link at the name is
    replaced, not followed)."""
    p = Path(os.path.abspath(path))
    return os.path.join(os.path.realpath(p.parent), p.name)


def _target_problem(path: Path, replace_links: bool = True) -> str | None:
    """Why a file may not be written at ``path`` (it exists and is not a regular file), or None. A link is
    replaced (never written through) when ``replace_links`` and it points to a regular file or nowhere."""
    try:
        st = os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None  # nothing there (a parent that is not a folder is the folder's problem)
    except OSError as exc:
        return f"cannot be examined ({exc.strerror or exc})"
    if stat.S_ISREG(st.st_mode):
        return None
    if stat.S_ISLNK(st.st_mode):
        if not replace_links:
            return ("is a symbolic link; rigsim replaces only regular files (it would replace the link, not write "
                    "through it): remove the link or choose another name")
        try:
            if os.readlink(path).startswith(("/proc/", "/dev/")):  # /dev/stdout → /proc/self/fd/1: a system link
                return "is a link to a process's file or a device; rigsim replaces only regular files"
            tgt = os.stat(path)
        except OSError:
            return None  # a dangling link: replaced by the new file
        if stat.S_ISREG(tgt.st_mode):
            return None  # replaced, not written through: what it points to stays as it was
        return f"is a link to {_kind(tgt.st_mode)}; rigsim replaces only regular files"
    return f"is {_kind(st.st_mode)}; rigsim replaces only regular files (or writes a new one)"


def _parent_problem(path: Path) -> str | None:
    """Why the folder of ``path`` cannot be written (or created), or None."""
    p = Path(os.path.abspath(path)).parent
    while True:
        try:
            st = os.stat(p)
        except FileNotFoundError:
            if p == p.parent:
                return None
            p = p.parent
            continue
        except OSError as exc:
            return f"its folder {p} cannot be used ({exc.strerror or exc})"
        if not stat.S_ISDIR(st.st_mode):
            return f"a part of the path, {p}, is {_kind(st.st_mode) if not stat.S_ISREG(st.st_mode) else 'a file'}, not a folder"
        if not os.access(p, os.W_OK | os.X_OK):
            return f"no permission to write in {p}"
        return None


def _linked_into(path: Path, folder: str) -> bool:
    """Whether ``path`` is a second name (a hard link) of a file inside ``folder``: looked for only when the file has
    several names, so a plain output never walks an input folder."""
    try:
        st = os.stat(path)
    except OSError:
        return False
    if not stat.S_ISREG(st.st_mode) or st.st_nlink < 2:
        return False
    for d, _, names in os.walk(folder):
        for n in names:
            try:
                o = os.lstat(os.path.join(d, n))
            except OSError:
                continue
            if (o.st_dev, o.st_ino) == (st.st_dev, st.st_ino):
                return True
    return False


# ------------------------------------------------------------------------------ the plan, before the command runs

def check_plan(outputs: Sequence[Output], inputs: Sequence[tuple[str, Path]]) -> None:
    """Refuse (one :class:`~rigsim.errors.InputError`) the first output that would destroy an input
    or another output, or that cannot be written; ``inputs`` are (label, path) of every file or folder
    the command reads."""
    ins = []
    for label, p in inputs:
        p = Path(p)
        ins.append((label, p, _ids(p), os.path.isdir(p) and not os.path.islink(p), os.path.realpath(p)))
    seen: dict[str, tuple[str, bool]] = {}
    seen_ids: dict[tuple[int, int], tuple[str, bool]] = {}
    for o in outputs:
        p = Path(o.path)
        say = f"{o.label} = {printable(p)!r}"
        if o.folder:
            try:
                st = os.stat(p)
            except OSError:
                st = None
            if st is not None and not stat.S_ISDIR(st.st_mode):
                raise InputError(f"{say}: is {'a file' if stat.S_ISREG(st.st_mode) else _kind(st.st_mode)}; expected a "
                                 "folder (new or existing)")
        else:
            if o.suffixes and p.suffix.lower() not in o.suffixes:
                raise InputError(f"{say}: the name must end in {', '.join(o.suffixes)}")
            if not p.name or p.name in (".", ".."):
                raise InputError(f"{say}: expected a file name")
            if len(p.name.encode("utf-8", "surrogateescape")) > NAME_MAX:
                raise InputError(f"{say}: a file name of at most {NAME_MAX} bytes is expected")
            why = _target_problem(p, replace_links=False)  # a link the user names is refused: it is not a file
            if why:
                raise InputError(f"{say}: {why}")
        why = _parent_problem(p)
        if why:
            raise InputError(f"{say}: {why}")
        ids = _ids(p)
        entry = _entry(p)
        for label, ip, iids, idir, ireal in ins:
            if ids & iids or entry == _entry(ip):
                raise InputError(f"{say}: is also {label} {printable(ip)} (the same file); rigsim never writes over its "
                                 "inputs: choose another name")
            if idir and not o.folder and os.path.lexists(p) and ((entry + os.sep).startswith(ireal + os.sep)
                                                                or _linked_into(p, ireal)):
                raise InputError(f"{say}: is a file of the input folder {label} {printable(ip)}; rigsim never writes over "
                                 "its inputs: choose another name")
        other = seen.get(entry) or next((seen_ids[i] for i in ids if i in seen_ids), None)
        if other is not None and not (o.folder and other[1]):  # folders may be shared: the files in them are checked
            raise InputError(f"{say}: is also {other[0]}; two outputs of one command cannot share a name")
        seen[entry] = (f"{o.label} {printable(p)!r}", o.folder)
        seen_ids.update({i: seen[entry] for i in ids})


# ------------------------------------------------------------------------------ declarations on the parser

_KEY = "_rigsim_outputs"


def declare(parser, dest: str | None = None, *, suffixes: Iterable[str] = (), folder: bool = False,
            derived: Callable | None = None) -> None:
    """Declare on an argparse (sub)parser that option ``dest`` names a file (``suffixes``: allowed
    endings) or a ``folder`` the command writes; ``derived(args)`` lists further :class:`Output` s the
    command writes (files inside an output folder, a plot beside ``--out``)."""
    spec = list(parser.get_default(_KEY) or [])
    spec.append((dest, tuple(s.lower() for s in suffixes), bool(folder), derived))
    parser.set_defaults(**{_KEY: spec})


def declared_outputs(args, labels: dict[str, str] | None = None) -> tuple[list[Output], set[str]]:
    """The outputs the parsed ``args`` name (by the declarations of their command), and the dests that are outputs."""
    labels = labels or {}
    outs: list[Output] = []
    dests: set[str] = set()
    for dest, suffixes, folder, derived in getattr(args, _KEY, None) or ():
        if dest is not None:
            dests.add(dest)
            v = getattr(args, dest, None)
            if isinstance(v, (str, os.PathLike)) and str(v) != "":
                outs.append(Output(Path(v), labels.get(dest, "--" + dest.replace("_", "-")), suffixes, folder))
        if derived is not None:
            outs.extend(derived(args))
    return outs, dests


# ------------------------------------------------------------------------------ while the command runs

_PROTECTED: list[tuple[str, Path, set, bool, str]] = []


@contextlib.contextmanager
def guard(inputs: Sequence[tuple[str, Path]]):
    """While the block runs, :func:`check_target` (every write) refuses to replace these inputs or a file
    inside an input folder."""
    added = []
    for label, p in inputs:
        p = Path(p)
        added.append((label, p, _ids(p), os.path.isdir(p) and not os.path.islink(p), os.path.realpath(p)))
    _PROTECTED.extend(added)
    try:
        yield
    finally:
        for a in added:
            _PROTECTED.remove(a)


def protected() -> list[tuple[str, Path]]:
    """The inputs the current command protects (label, path)."""
    return [(label, p) for label, p, *_ in _PROTECTED]


def check_target(path) -> None:
    """Refuse to write a file at ``path`` when a folder, a device node, a FIFO, a socket (or a link to one)
    stands there, or when it is an input of the running command (:func:`guard`)."""
    path = Path(path)
    why = _target_problem(path)
    if why:
        raise InputError(f"{printable(path)}: {why}")
    if not _PROTECTED or not os.path.lexists(path):
        return
    ids = _ids(path)
    entry = _entry(path)
    for label, ip, iids, idir, ireal in _PROTECTED:
        if ids & iids:
            raise InputError(f"{printable(path)}: is {label} {printable(ip)}, an input of this command; rigsim never "
                             "writes over its inputs")
        if idir and ((entry + os.sep).startswith(ireal + os.sep) or _linked_into(path, ireal)):
            raise InputError(f"{printable(path)}: is a file of the input folder {label} {printable(ip)}; rigsim never "
                             "writes over its inputs")
