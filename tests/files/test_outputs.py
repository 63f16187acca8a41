"""rigsim.files.outputs: an output that names an input (by any spelling, a link or a hard link), another output,
a device node, a FIFO, a socket, a folder or a link is refused before anything is written; the atomic writer
never replaces a device node or an input of the running command."""

import os
import socket
import stat

import pytest

from rigsim.errors import InputError
from rigsim.files import atomic_write_bytes
from rigsim.files.outputs import Output, check_plan, guard


def _files(tmp_path):
    a = tmp_path / "a.csv"
    a.write_text("input\n")
    return a


def test_an_output_that_is_an_input_under_any_name_is_refused(tmp_path, monkeypatch):
    a = _files(tmp_path)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    os.link(a, tmp_path / "hard.csv")
    (tmp_path / "link.csv").symlink_to(a)
    (tmp_path / "dirlink").symlink_to(tmp_path)
    for name in ("a.csv", "./a.csv", "sub/../a.csv", str(a), "dirlink/a.csv", "hard.csv"):
        with pytest.raises(InputError, match=r"--out = .*: is also --angles .*a\.csv \(the same file\)"):
            check_plan([Output(tmp_path / name, "--out")], [("--angles", a)])
    # the input named through a link: the file behind it is the same file
    with pytest.raises(InputError, match="is also --angles"):
        check_plan([Output(a, "--out")], [("--angles", tmp_path / "link.csv")])
    check_plan([Output(tmp_path / "b.csv", "--out")], [("--angles", a)])  # another file: fine


def test_two_outputs_cannot_share_a_file_but_folders_may(tmp_path):
    with pytest.raises(InputError, match=r"--opencv = .*sun\.json': is also --out .*sun\.json'; two outputs"):
        check_plan([Output(tmp_path / "sun.json", "--out"), Output(tmp_path / "x" / ".." / "sun.json", "--opencv")], [])
    check_plan([Output(tmp_path / "r", "--out", folder=True), Output(tmp_path / "r", "--export-frames", folder=True)], [])


def test_a_file_of_an_input_folder_is_not_replaced(tmp_path):
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "truth.csv").write_text("t\n")
    with pytest.raises(InputError, match=r"--errors-out = .*truth\.csv': is a file of the input folder DIR"):
        check_plan([Output(ds / "truth.csv", "--errors-out")], [("DIR", ds)])
    check_plan([Output(ds / "errors.csv", "--errors-out")], [("DIR", ds)])  # a new file beside it is allowed


@pytest.mark.parametrize("kind", ["fifo", "socket", "folder", "device", "link-to-proc", "link"])
def test_only_regular_files_are_replaced(tmp_path, kind):
    p = tmp_path / "out.json"
    if kind == "fifo":
        os.mkfifo(p)
    elif kind == "socket":
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(p))
    elif kind == "folder":
        p.mkdir()
    elif kind == "device":
        if os.geteuid() != 0:
            pytest.skip("mknod needs root")
        os.mknod(p, stat.S_IFCHR | 0o666, os.makedev(1, 3))  # a /dev/null of our own
    elif kind == "link-to-proc":
        p.symlink_to("/proc/self/fd/1")
    else:
        (tmp_path / "t.json").write_text("{}")
        p.symlink_to(tmp_path / "t.json")
    before = os.lstat(p)
    with pytest.raises(InputError, match=r"out\.json'?: is (a FIFO|a socket|a folder|a character device|a symbolic link)"):
        check_plan([Output(p, "--out")], [])
    if kind != "link":  # a link planted at a name the writer chose is replaced, never written through (next test)
        with pytest.raises(InputError, match="rigsim replaces only regular files"):
            atomic_write_bytes(p, b"{}")
    after = os.lstat(p)
    assert (after.st_ino, stat.S_IFMT(after.st_mode)) == (before.st_ino, stat.S_IFMT(before.st_mode))


def test_the_writer_replaces_a_planted_link_without_following_it(tmp_path):
    (tmp_path / "victim").write_text("keep")
    (tmp_path / "r.json").symlink_to(tmp_path / "victim")
    atomic_write_bytes(tmp_path / "r.json", b"{}")
    assert (tmp_path / "victim").read_text() == "keep" and not (tmp_path / "r.json").is_symlink()


def test_the_writer_never_replaces_an_input_of_the_running_command(tmp_path):
    a = _files(tmp_path)
    with guard([("--angles", a)]):
        with pytest.raises(InputError, match=r"a\.csv: is --angles .*an input of this command"):
            atomic_write_bytes(tmp_path / "a.csv", b"x")
    assert a.read_text() == "input\n"
    atomic_write_bytes(a, b"x")  # outside the command: an ordinary file
    assert a.read_text() == "x"


def test_unwritable_outputs_are_refused_up_front(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(InputError, match=r"a part of the path, .*f, is a file, not a folder"):
        check_plan([Output(tmp_path / "f" / "x.json", "--out")], [])
    with pytest.raises(InputError, match=r"the name must end in \.csv, \.parquet"):
        check_plan([Output(tmp_path / "x.txt", "--errors-out", (".csv", ".parquet"))], [])
    with pytest.raises(InputError, match="a file name of at most 241 bytes"):
        check_plan([Output(tmp_path / ("x" * 250), "--out")], [])
    with pytest.raises(InputError, match=r"--out = .*f': is a file; expected a folder"):
        check_plan([Output(tmp_path / "f", "--out", folder=True)], [])


def test_a_second_name_of_a_file_inside_an_input_folder_is_refused(tmp_path):
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "manifest.json").write_text("{}")
    os.link(ds / "manifest.json", tmp_path / "m.json")
    with pytest.raises(InputError, match=r"--json-out = .*m\.json': is a file of the input folder DIR"):
        check_plan([Output(tmp_path / "m.json", "--json-out")], [("DIR", ds)])
    with guard([("DIR", ds)]):
        with pytest.raises(InputError, match="is a file of the input folder DIR"):
            atomic_write_bytes(tmp_path / "m.json", b"x")


def test_every_option_that_names_an_output_is_declared():
    """A command's output options are checked only when the command declares them (rigsim.files.outputs.declare):
    every option of every subcommand whose name says it is a destination must be declared, so a new command cannot
    forget. Flags (store_true) are not paths."""
    import argparse

    from rigsim.cli import build_parser

    names = {"out", "json_out", "opencv", "errors_out", "preview", "xml", "export_frames", "screenshot", "html", "export",
             "json"}
    missing = []

    def walk(p, path):
        subs = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        for a in subs:
            for name, sp in a.choices.items():
                walk(sp, (*path, name))
        if subs:
            return
        declared = {d for d, *_ in (p.get_default("_rigsim_outputs") or ())}
        for a in p._actions:
            if a.dest in names and a.nargs != 0 and a.dest not in declared:
                missing.append(f"{' '.join(path)} {a.option_strings[0]}")

    walk(build_parser(), ())
    assert missing == []
