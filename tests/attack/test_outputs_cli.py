"""Outputs never destroy inputs or each other, through the commands: an output option that names an input (by any
spelling), the command's other output, a file of an input folder, a device node, a FIFO or a folder is refused with
one line before anything is written, and a command's outputs are either all refused or all written. Every input
here is valid: without the checks each command would run to its writes."""

import os
import stat
import sys
from pathlib import Path

import pytest

from rigsim.cli import main

sys.path.insert(0, str(Path(__file__).resolve().parent))
import valid_inputs as V  # noqa: E402


def _digest(folder: Path) -> dict:
    import hashlib

    return {p.relative_to(folder).as_posix(): (hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() and not p.is_symlink()
                                               else stat.S_IFMT(p.lstat().st_mode))
            for p in sorted(folder.rglob("*"))}


def _refused(capsys, argv, words, folder):
    before = _digest(folder)
    rc = main(argv)
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and err.startswith("rigsim") and words in err, (argv, err)
    assert _digest(folder) == before, "a file was written, replaced or destroyed"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    V.sweep_tables(d)
    V.nulls(d)
    assert main(["triad", "--nulls", str(d / "nulls.csv"), "--out", str(d / "cube.json")]) == 0
    assert main(["calibrate", "sun-sensor", "--angles", str(d / "angles.csv"), "--centroids", str(d / "centroids.csv"),
                 "--out", str(d / "sun.json")]) == 0
    return d


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    d = tmp_path_factory.mktemp("ds")
    assert main(["dataset", "generate", V.RIG, "--out", str(d / "ds"), "--frames", "2", "--spp", "1", "--workers", "1",
                 "--quiet"]) == 0
    (d / "p.csv").write_text("frame,u,v\n0,500,500\n1,510,505\n")
    return d


def test_an_output_that_names_an_input_is_refused(files, capsys, monkeypatch):
    d = files
    monkeypatch.chdir(d)
    cal = ["calibrate", "sun-sensor", "--angles", "angles.csv", "--centroids", "centroids.csv"]
    _refused(capsys, ["triad", "--nulls", "nulls.csv", "--out", "nulls.csv"], "is also --nulls", d)
    _refused(capsys, ["triad", "--nulls", "nulls.csv", "--out", "./x/../nulls.csv"], "is also --nulls", d)
    _refused(capsys, [*cal, "--out", "angles.csv"], "the name must end in .json", d)
    _refused(capsys, [*cal, "--out", "sun.json", "--opencv", "centroids.csv"], "the name must end in", d)
    _refused(capsys, [*cal, "--out", "sun.json", "--opencv", "sun.json"], "is also --out", d)
    _refused(capsys, ["compose", "--cube-from-rot", "cube.json", "--sun-from-rot", "sun.json", "--out", "sun.json"],
             "is also --sun-from-rot", d)
    os.link(d / "cube.json", d / "hard.json")
    try:
        _refused(capsys, ["compose", "--cube-from-rot", "cube.json", "--sun-from-rot", "sun.json", "--out", "hard.json"],
                 "is also --cube-from-rot", d)
    finally:
        os.unlink(d / "hard.json")


def test_a_derived_output_that_names_an_input_is_refused(files, capsys, monkeypatch, tmp_path):
    """calibrate writes its residual plot beside --out: an input of that name is refused up front."""
    monkeypatch.chdir(tmp_path)
    for f in ("angles.csv", "centroids.csv"):
        (tmp_path / f).write_bytes((files / f).read_bytes())
    (tmp_path / "cal.residuals.png").write_bytes(b"an input the user keeps")
    _refused(capsys, ["calibrate", "sun-sensor", "--angles", "angles.csv", "--centroids", "cal.residuals.png",
                      "--out", "cal.json"], "--out's residual plot", tmp_path)


def test_outputs_are_all_refused_or_all_written(files, capsys, monkeypatch, tmp_path):
    """The second output is checked before the first is written: a bad --opencv leaves no --out behind."""
    monkeypatch.chdir(tmp_path)
    cal = ["calibrate", "sun-sensor", "--angles", str(files / "angles.csv"), "--centroids", str(files / "centroids.csv")]
    (tmp_path / "file").write_text("")
    _refused(capsys, [*cal, "--out", "a.json", "--opencv", "cam.txt"], "the name must end in .yml", tmp_path)
    _refused(capsys, [*cal, "--out", "a.json", "--opencv", "file/cam.yml"], "is a file, not a folder", tmp_path)
    assert main([*cal, "--out", "a.json", "--opencv", "cam.yml"]) == 0
    assert {p.name for p in tmp_path.iterdir()} == {"file", "a.json", "a.residuals.png", "cam.yml"}


@pytest.mark.parametrize("kind", ["device", "fifo", "folder", "socket", "stdout-link"])
def test_only_regular_files_are_replaced(files, capsys, monkeypatch, tmp_path, kind):
    """As root, --out /dev/null would have replaced the machine's /dev/null: a device node of our own stands in."""
    import socket

    monkeypatch.chdir(tmp_path)
    target = tmp_path / "out.json"
    if kind == "device":
        if os.geteuid() != 0:
            pytest.skip("mknod needs root")
        os.mknod(target, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    elif kind == "fifo":
        os.mkfifo(target)
    elif kind == "folder":
        target.mkdir()
    elif kind == "socket":
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(target))
    else:
        target.symlink_to("/proc/self/fd/1")
    _refused(capsys, ["triad", "--nulls", str(files / "nulls.csv"), "--out", str(target)], "out.json", tmp_path)


def test_score_never_writes_over_its_predictions_or_the_dataset(dataset, capsys, monkeypatch):
    d = dataset
    monkeypatch.chdir(d)
    _refused(capsys, ["dataset", "score", "ds", "p.csv", "--json-out", "p.csv"], "is also CSV p.csv", d)
    _refused(capsys, ["dataset", "score", "ds", "p.csv", "--errors-out", "ds/truth.csv"], "is a file of the input folder",
             d)
    _refused(capsys, ["dataset", "score", "ds", "p.csv", "--json-out", "s.csv", "--errors-out", "s.csv"], "is also", d)
    _refused(capsys, ["dataset", "score", "ds", "p.csv", "--json-out", "s.json", "--errors-out", "e.txt"],
             "the name must end in .csv", d)
