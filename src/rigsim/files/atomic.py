"""One way to write a file: a temporary file created exclusively in the target's folder (never
following a symlink), fsync, then an atomic rename over the target and an fsync of the folder. Only a regular file (or a link,
which is replaced, not followed) is ever replaced; a folder, a device node, a FIFO or a socket at the
target is refused, and so is an input of the running command (:mod:`rigsim.files.outputs`)."""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path

from rigsim.errors import InputError


def _file_mode() -> int:
    """The mode an ordinary ``open(path, "w")`` would give (0o666 less the umask): mkstemp's 0o600
    would leave a user's outputs unreadable to their group."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def output_folder(path, what: str = "output folder") -> Path:
    """``path`` as a folder to write into, created if missing; one line (naming ``what``, e.g. ``--out``) when it
    is a file or cannot be created (a name too long, no permission, a component that is a file)."""
    path = Path(path)
    try:
        if path.is_dir():
            return path
        if path.exists() or path.is_symlink():
            raise InputError(f"{what} {path}: is a file, not a folder")
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise InputError(f"{what} {path}: a part of the path is a file, not a folder") from None
    except OSError as exc:
        raise InputError(f"{what} {path}: cannot create the folder ({exc.strerror or exc})") from None
    return path


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; the folder is created if missing. Returns the path."""
    from .outputs import check_target

    path = Path(path)
    check_target(path)
    output_folder(path.parent)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, _file_mode())
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    _sync_folder(path.parent)
    return path


def _sync_folder(folder: Path) -> None:
    """fsync the folder: the rename that published the file is on the disk when the write returns (POSIX makes a
    name durable only with its directory). A folder that cannot be opened (no read permission) or a file system
    that cannot sync one (EINVAL) is left as it is; an I/O error is raised: the file is in place, its name may
    not survive a power cut."""
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError as exc:
        if exc.errno not in (errno.EINVAL, errno.ENOTSUP, errno.EBADF):
            raise
    finally:
        os.close(fd)


def atomic_write_text(path, text: str) -> Path:
    """:func:`atomic_write_bytes` of UTF-8 text."""
    return atomic_write_bytes(path, str(text).encode("utf-8"))


def save_figure(fig, path, **savefig_kw) -> Path:
    """A Matplotlib figure written through :func:`atomic_write_bytes` (format from the suffix)."""
    import io

    buf = io.BytesIO()
    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    fig.savefig(buf, format=fmt, **savefig_kw)
    return atomic_write_bytes(path, buf.getvalue())
