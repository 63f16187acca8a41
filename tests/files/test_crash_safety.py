"""Crash safety by fault injection (tests/files/fs_faults.py): a ``kill -9`` at every step of the atomic writer
and of a dataset frame write, a power cut after every step, and a failure at every step, leave each file
either old or new and whole; a frame is trusted on resume only when its image and its sidecar are both the
new ones. The last tests break the writer on purpose (no fsync, no flush, the rename before the sync, a
write straight onto the target) and check that these checks see it."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from fs_faults import Disk, kill_at, record, steps

from rigsim.files.atomic import atomic_write_bytes

OLD = b"old contents, whole\n" * 7
NEW = b'{"new": "contents"}\n' * 5  # within a buffered file's 8 kB buffer: written to the kernel at flush
LARGE = bytes(range(256)) * 80  # 20 kB: past the buffer, a buffered file hands it to the kernel at once


def _folder_files(folder: Path) -> dict[str, bytes]:
    return {str(p): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _leftovers(folder: Path, finals: set[str]) -> list[str]:
    """Files other than the final names: only the writer's temporaries (``.name.*.tmp``) may be left by a kill."""
    return [p.name for p in folder.rglob("*") if p.is_file() and str(p) not in finals
            and not (p.name.startswith(".") and p.name.endswith(".tmp"))]


def _kill_each(write, target: Path, old: bytes | None, new: bytes) -> list[str]:
    """A kill just before every step of ``write()``, one per run (a kill just after a step leaves what a kill
    before the next one does: nothing else touches a file in between): the target must read ``old`` (or be
    absent when ``old`` is None) or ``new``, whole, and nothing but a temporary may be left beside it."""
    problems, n = [], 0
    while True:
        killed = kill_at(write, n, 0)
        after = target.read_bytes() if target.exists() else None
        if after not in (old, new):
            problems.append(f"killed before step {n}: the target holds {len(after or b'')} bytes, neither old nor new")
        left = _leftovers(target.parent, {str(target)})
        if left:
            problems.append(f"killed before step {n}: {left} left beside it")
        for p in target.parent.iterdir():
            p.unlink()
        if old is not None:
            target.write_bytes(old)
        if not killed:
            return problems
        n += 1


def power_cut_problems(write, target: Path, old: bytes | None, new: bytes) -> list[str]:
    """A power cut after every step of ``write()`` (the disk model of fs_faults.Disk): the target must read
    ``old`` (absent when None) or ``new`` whole; after the last step, ``new``."""
    start = _folder_files(target.parent)
    events = record(write)
    problems = []
    for k in range(len(events) + 1):
        for names in ("all", "synced"):  # the journal committed every name so far, or only the synced ones
            got = Disk.after(start, events[:k], names).get(str(target))
            if got not in (old, new):
                problems.append(f"power cut after step {k} ({events[k - 1][0] if k else 'start'}, {names} names): "
                                f"the target holds {len(got or b'')} bytes, neither old nor new")
    if Disk.after(start, events, "synced").get(str(target)) != new:
        problems.append("after the last step the new data is not on the disk (the folder was not synced)")
    return problems


@pytest.fixture(params=["replace", "create"])
def target(request, tmp_path):
    t = tmp_path / "out" / "result.json"
    t.parent.mkdir()
    old = None
    if request.param == "replace":
        t.write_bytes(OLD)
        old = OLD
    return t, old


@pytest.mark.parametrize("new", [NEW, LARGE], ids=["small", "large"])
def test_a_kill_at_any_step_of_the_atomic_write_leaves_the_old_or_the_new_file(target, new):
    t, old = target
    assert _kill_each(lambda: atomic_write_bytes(t, new), t, old, new) == []


@pytest.mark.parametrize("new", [NEW, LARGE], ids=["small", "large"])
def test_a_power_cut_after_any_step_of_the_atomic_write_leaves_the_old_or_the_new_file(target, new):
    t, old = target
    assert power_cut_problems(lambda: atomic_write_bytes(t, new), t, old, new) == []
    kinds = [e[0] for e in record(lambda: atomic_write_bytes(t, new))]
    assert kinds.index("fsync") < kinds.index("rename")  # the data is synced before the name is published


def test_a_failure_at_any_step_leaves_the_old_file_and_no_temporary(target):
    """Every step in turn raises (a full disk, an I/O error): the write raises, the target is untouched, and
    the temporary is removed."""
    t, old = target
    kinds = [e[0] for e in record(lambda: atomic_write_bytes(t, NEW))]
    n_steps = kinds.index("rename") + 1  # the steps up to the publishing rename; the folder's sync follows
    if old is not None:
        t.write_bytes(old)
    else:
        t.unlink()
    for n in range(n_steps):
        seen = [0]

        def hook(event, phase, n=n):
            if phase == 0 and event[0] != "unlink":  # the clean-up's own unlink must run
                if seen[0] == n:
                    raise OSError(28, "No space left on device (injected)")
                seen[0] += 1

        with pytest.raises(OSError, match="injected"), steps(hook):
            atomic_write_bytes(t, NEW)
        assert (t.read_bytes() if t.exists() else None) == old, n
        assert sorted(p.name for p in t.parent.iterdir()) == ([t.name] if old is not None else []), n


def test_an_io_error_syncing_the_folder_is_raised_with_the_new_file_in_place(tmp_path):
    """After the rename the folder is synced: an I/O error there is raised (the name may not survive a power cut),
    the new file is whole in place and no temporary is left; a file system that cannot sync a folder (EINVAL) is
    no error."""
    t = tmp_path / "r.json"
    t.write_bytes(OLD)
    for err, raised in ((5, True), (22, False)):
        def hook(event, phase, err=err):
            if phase == 0 and event[0] == "fsync" and os.path.isdir(f"/proc/self/fd/{event[1]}"):
                raise OSError(err, "injected at the folder's fsync")

        with steps(hook):
            if raised:
                with pytest.raises(OSError, match="injected"):
                    atomic_write_bytes(t, NEW)
            else:
                atomic_write_bytes(t, NEW)
        assert t.read_bytes() == NEW and sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]
        t.write_bytes(OLD)


def test_a_failed_clean_up_does_not_hide_the_writes_own_error(tmp_path):
    """The rename fails, and so does the removal of the temporary: the rename's error is the one raised."""
    t = tmp_path / "r.json"
    t.write_bytes(OLD)

    def hook(event, phase):
        if phase == 0 and event[0] == "rename":
            raise OSError(5, "Input/output error (injected at the rename)")
        if phase == 0 and event[0] == "unlink":
            raise OSError(2, "No such file (injected at the clean-up)")

    with pytest.raises(OSError, match="injected at the rename"), steps(hook):
        atomic_write_bytes(t, NEW)
    assert t.read_bytes() == OLD


# -- a dataset frame: the image, then the sidecar holding its checksum ---------------------------------------
def _frame(root: Path, index: int, value: int, seed: int):
    from rigsim.dataset.store import write_frame_atomic

    img = np.full((32, 48), value, np.uint16)
    img[3, 5] = 7 * value + 1
    return lambda: write_frame_atomic(root, index, img, {"seed": seed, "truth": {"x": value}}, "png",
                                      params={"seed": seed, "pose": [value]})


def _frame_state(root: Path, files: dict[str, bytes], old: dict[str, bytes], new: dict[str, bytes],
                 old_params, new_params) -> list[str]:
    """Each file of the frame old or new, whole, and the frame trusted (store.frame_complete, which hashes the
    image) exactly when both files are the new ones (or both the old ones, for the old plan entry)."""
    from rigsim.dataset.store import frame_complete

    problems = []
    names = sorted(set(old) | set(new))
    state = {}
    for name in names:
        got = files.get(name)
        if got == new.get(name):
            state[name] = "new"
        elif got == old.get(name):
            state[name] = "old"
        else:
            problems.append(f"{Path(name).name}: {len(got or b'')} bytes, neither old nor new")
    if problems:
        return problems
    all_new = all(v == "new" for v in state.values())
    all_old = all(v == "old" for v in state.values()) and bool(old)
    if frame_complete(root, 3, "png", params=new_params) != all_new:
        problems.append(f"trusted as the new frame with {state}")
    if old_params is not None and frame_complete(root, 3, "png", params=old_params) != all_old:
        problems.append(f"trusted as the old frame with {state}")
    return problems


@pytest.mark.parametrize("before", ["nothing", "another plan's frame", "a damaged render of this entry"])
def test_a_kill_or_power_cut_at_any_step_of_a_frame_write_leaves_a_frame_trusted_only_when_whole(tmp_path, before):
    root = tmp_path / "ds"
    (root / "frames").mkdir(parents=True)
    write_new = _frame(root, 3, 40, seed=2)
    write_new()
    new = _folder_files(root)
    for p in (root / "frames").iterdir():
        p.unlink()
    old_params = None
    if before == "another plan's frame":
        _frame(root, 3, 90, seed=1)()
        old_params = {"seed": 1, "pose": [90]}
    elif before == "a damaged render of this entry":  # the same plan entry, an image that differs
        _frame(root, 3, 40, seed=2)()
        (root / "frames" / "frame_000003.png").write_bytes(_png(41))
    old = _folder_files(root)
    new_params = {"seed": 2, "pose": [40]}

    def restore():
        for p in (root / "frames").iterdir():
            p.unlink()
        for name, data in old.items():
            Path(name).write_bytes(data)

    problems, n = [], 0
    while True:  # a kill before every step (see _kill_each)
        killed = kill_at(write_new, n, 0)
        files = {k: v for k, v in _folder_files(root).items() if not Path(k).name.startswith(".")}
        problems += [f"kill before step {n}: {p}" for p in _frame_state(root, files, old, new, old_params, new_params)]
        restore()
        if not killed:
            break
        n += 1
    assert n >= 10  # both files' steps were hit
    events = record(write_new)
    for k in range(len(events) + 1):
        for names in ("all", "synced"):  # the journal committed every name so far, or only the synced ones
            disk = Disk.after(old, events[:k], names)
            for p in (root / "frames").iterdir():
                p.unlink()
            for name, data in disk.items():
                if not Path(name).name.startswith("."):
                    Path(name).write_bytes(data)
            files = {k2: v for k2, v in disk.items() if not Path(k2).name.startswith(".")}
            problems += [f"power cut after step {k} ({names} names): {p}"
                         for p in _frame_state(root, files, old, new, old_params, new_params)]
            restore()
    assert problems == []


def _png(value: int) -> bytes:
    from rigsim.dataset.store import encode_image

    return encode_image(np.full((32, 48), value, np.uint16), "png")


# -- the checks see a broken writer --------------------------------------------------------------------------
def _sync_folder(path):
    fd = os.open(Path(path).parent, os.O_RDONLY | os.O_DIRECTORY)
    os.fsync(fd)
    os.close(fd)


def _no_fsync(path, data):
    tmp = Path(path).with_name(f".{Path(path).name}.x.tmp")
    with open(tmp, "xb") as f:
        f.write(data)
    os.replace(tmp, path)
    _sync_folder(path)


def _no_folder_sync(path, data):
    tmp = Path(path).with_name(f".{Path(path).name}.x.tmp")
    with open(tmp, "xb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _no_flush(path, data):
    fd = os.open(Path(path).with_name(f".{Path(path).name}.x.tmp"), os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    f = os.fdopen(fd, "wb")
    f.write(data)
    os.fsync(f.fileno())  # the data is still in Python's buffer
    f.close()
    os.replace(Path(path).with_name(f".{Path(path).name}.x.tmp"), path)


def _rename_then_sync(path, data):
    tmp = Path(path).with_name(f".{Path(path).name}.x.tmp")
    f = open(tmp, "xb")
    f.write(data)
    f.flush()
    os.replace(tmp, path)
    os.fsync(f.fileno())
    f.close()


def _straight_onto_the_target(path, data):
    with open(path, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


@pytest.mark.parametrize("writer, power, kill", [
    (_no_fsync, True, False), (_no_flush, True, False), (_rename_then_sync, True, False),
    (_no_folder_sync, True, False), (_straight_onto_the_target, True, True)])
def test_the_checks_fail_a_broken_writer(tmp_path, writer, power, kill):
    t = tmp_path / "out" / "result.json"
    t.parent.mkdir()
    t.write_bytes(OLD)
    assert bool(power_cut_problems(lambda: writer(t, NEW), t, OLD, NEW)) == power
    t.write_bytes(OLD)
    for p in t.parent.iterdir():
        if p != t:
            p.unlink()
    assert bool(_kill_each(lambda: writer(t, NEW), t, OLD, NEW)) == kill
