"""rigsim.files: frames, tables and JSON results round-trip exactly, and every bad file is one
InputError naming the file, the line/column and what was expected."""

import json
import os

import cv2
import numpy as np
import pytest

from rigsim.errors import InputError
from rigsim.files import Column, covariance_block, read_image, read_json, read_table, write_image, write_json, write_table


@pytest.mark.parametrize("suffix", [".png", ".tif", ".tiff", ".fits"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_frames_round_trip_bit_exact(tmp_path, suffix, dtype):
    rng = np.random.default_rng(1)
    a = rng.integers(0, np.iinfo(dtype).max, (37, 53)).astype(dtype)
    b = read_image(write_image(tmp_path / f"f{suffix}", a))
    assert b.dtype == a.dtype and b.shape == (37, 53) and np.array_equal(a, b)


def test_fits_float_and_one_based_convention(tmp_path):
    from astropy.io import fits

    a = np.zeros((5, 7), np.float32)
    a[1, 3] = 1.0  # FITS pixel (x=4, y=2), rigsim (u=3, v=1)
    fits.PrimaryHDU(a).writeto(tmp_path / "f.fits")
    b = read_image(tmp_path / "f.fits")
    assert b.dtype == np.float64 and np.unravel_index(np.argmax(b), b.shape) == (1, 3)


def test_bad_frames_name_file_and_expectation(tmp_path):
    rgb = np.zeros((4, 4, 3), np.uint8)
    cv2.imwrite(str(tmp_path / "rgb.png"), rgb)
    with pytest.raises(InputError, match=r"rgb\.png: 3-channel \(colour\) image; expected a single-channel"):
        read_image(tmp_path / "rgb.png")
    cv2.imwrite(str(tmp_path / "f32.tiff"), np.zeros((4, 4), np.float32))
    with pytest.raises(InputError, match=r"f32\.tiff: pixel type float32; expected an unsigned 8-bit or 16-bit"):
        read_image(tmp_path / "f32.tiff")
    write_image(tmp_path / "small.png", np.zeros((4, 6), np.uint16))
    with pytest.raises(InputError, match=r"small\.png: 6×4 px \(width×height\); expected 1024×1024 px"):
        read_image(tmp_path / "small.png", shape=(1024, 1024))
    with pytest.raises(InputError, match="expected an unsigned 16-bit"):
        read_image(write_image(tmp_path / "eight.png", np.zeros((2, 2), np.uint8)), allowed_bits=(16,))
    (tmp_path / "junk.png").write_bytes(b"not a png")
    with pytest.raises(InputError, match=r"junk\.png: not a readable PNG"):
        read_image(tmp_path / "junk.png")
    with pytest.raises(InputError, match="no such file"):
        read_image(tmp_path / "missing.png")
    with pytest.raises(InputError, match="not a regular file"):
        read_image(tmp_path)
    with pytest.raises(InputError, match="unsupported frame file type '.jpg'"):
        (tmp_path / "x.jpg").write_bytes(b"")
        read_image(tmp_path / "x.jpg")


COLS = [Column("frame", kind="str"), Column("x", "deg"), Column("u", "px", allow_nan=True),
        Column("n", kind="int", required=False)]


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_tables_round_trip_bit_exact(tmp_path, suffix):
    x = np.random.default_rng(2).normal(size=5) * 1e3
    p = write_table(tmp_path / f"t{suffix}", {"frame": [f"f{i}.png" for i in range(5)], "x_deg": x,
                                               "u_px": [1.5, np.nan, 3, 4, 5], "extra": [1, 2, 3, 4, 5]})
    t = read_table(p, COLS)
    assert np.array_equal(t["x_deg"], x)  # repr precision: bit-identical
    assert np.isnan(t["u_px"][1]) and list(t["frame"]) == [f"f{i}.png" for i in range(5)]
    assert "n" not in t and list(t["extra"]) == ["1", "2", "3", "4", "5"]


@pytest.mark.parametrize("text, message", [
    ("frame,x_rad,u_px\na,1,2\n", r"t\.csv: column x_rad: expected x_deg \(degrees\), got radians"),
    ("frame,u_px\na,2\n", r"t\.csv: no column x_deg \(degrees\); the header has frame, u_px"),
    ("frame,x_deg,u_px\na,1,2\nb,abc,3\n", r"t\.csv: line 3, column x_deg: 'abc' is not a number"),
    ("frame,x_deg,u_px\na,,2\n", r"t\.csv: line 2, column x_deg: empty cell; expected a number"),
    ("frame,x_deg,u_px\na,inf,2\n", r"t\.csv: line 2, column x_deg: 'inf'; expected a finite number"),
    ("frame,x_deg,u_px\na,1,2,3\n", r"t\.csv: line 2: 4 fields; expected 3 like the header"),
    ("frame,x_deg,x_deg\na,1,2\n", r"t\.csv: column x_deg appears twice"),
    ("frame,x_deg,u_px,n\na,1,2,1.5\n", r"t\.csv: line 2, column n: '1.5' is not an integer"),
    ("", r"t\.csv: empty table"),
])
def test_bad_tables_one_line(tmp_path, text, message):
    (tmp_path / "t.csv").write_text(text)
    with pytest.raises(InputError, match=message) as e:
        read_table(tmp_path / "t.csv", COLS)
    assert "\n" not in str(e.value)


def test_table_comments_blank_lines_and_encoding(tmp_path):
    (tmp_path / "t.csv").write_text("# rig log\n\nframe,x_deg,u_px\n\na,1,2\n")
    t = read_table(tmp_path / "t.csv", COLS)
    assert t["__line__"].tolist() == [5] and t["x_deg"].tolist() == [1.0]
    (tmp_path / "b.csv").write_bytes(b"frame,x_deg,u_px\n\xff,1,2\n")
    with pytest.raises(InputError, match=r"b\.csv: not UTF-8 text"):
        read_table(tmp_path / "b.csv", COLS)


def test_json_results_and_covariance(tmp_path):
    cov = covariance_block(["a", "b"], [[4.0, 1.0], [1.0, 9.0]], ["arcsec2", "arcsec2"])
    p = write_json(tmp_path / "r.json", {"x": np.float64(np.nan), "R": np.eye(3), "cov": cov})
    r = read_json(p, required=("R", "cov"))
    assert r["x"] is None and r["R"] == np.eye(3).tolist() and r["cov"]["sigma"] == [2.0, 3.0]
    (tmp_path / "bad.json").write_text('{"a": 1,\n "b": }')
    with pytest.raises(InputError, match=r"bad\.json: line 2, column 7: not valid JSON"):
        read_json(tmp_path / "bad.json")
    with pytest.raises(InputError, match=r"r\.json: no key 'zz'"):
        read_json(p, required=("zz",))
    (tmp_path / "l.json").write_text("[1]")
    with pytest.raises(InputError, match="a JSON list; expected an object"):
        read_json(tmp_path / "l.json")


def test_writes_are_atomic_and_never_follow_a_planted_symlink(tmp_path):
    outside = tmp_path / "outside.txt"
    outside.write_text("keep")
    out = tmp_path / "out"
    out.mkdir()
    # a planted temp-name symlink and a stale temp file: neither is followed nor kept as the result
    os.symlink(outside, out / ".r.json.tmp")
    write_json(out / "r.json", {"a": 1})
    assert outside.read_text() == "keep" and json.loads((out / "r.json").read_text()) == {"a": 1}
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".r.json.") and p.is_file()
                  and not p.is_symlink()) == []


@pytest.mark.parametrize("umask, mode", [(0o027, 0o640), (0o000, 0o666), (0o077, 0o600)])
def test_written_files_take_the_umask_like_any_other_file(tmp_path, umask, mode):
    """Not mkstemp's private 0o600: a result shared with a group is readable by it; the umask in force before
    the write is in force after it."""
    old = os.umask(umask)
    try:
        write_json(tmp_path / "r.json", {"a": 1})
        write_image(tmp_path / "f.png", np.zeros((4, 4), np.uint16))
        assert os.umask(umask) == umask
    finally:
        os.umask(old)
    assert {(p.name, p.stat().st_mode & 0o777) for p in tmp_path.iterdir()} == {("r.json", mode), ("f.png", mode)}


def test_an_output_folder_that_cannot_be_one_is_one_line(tmp_path):
    from rigsim.files.atomic import output_folder

    (tmp_path / "file").write_text("x")
    os.symlink(tmp_path / "nowhere", tmp_path / "dangling")
    assert output_folder(tmp_path / "new" / "deep", "--out") == tmp_path / "new" / "deep" and (tmp_path / "new" / "deep").is_dir()
    with pytest.raises(InputError, match=r"^--out .*file: is a file, not a folder$"):
        output_folder(tmp_path / "file", "--out")
    with pytest.raises(InputError, match=r"^--out .*dangling: is a file, not a folder$"):
        output_folder(tmp_path / "dangling", "--out")
    with pytest.raises(InputError, match=r"^--out .*dangling/sub: a part of the path is a file, not a folder$"):
        output_folder(tmp_path / "dangling" / "sub", "--out")  # mkdir meets the link it cannot enter
    with pytest.raises(InputError, match=r"^--out .*file/sub: cannot create the folder \(Not a directory\)$"):
        output_folder(tmp_path / "file" / "sub", "--out")
    with pytest.raises(InputError, match=r"^output folder .*: cannot create the folder \(File name too long\)$"):
        output_folder(tmp_path / ("x" * 300))
    with pytest.raises(InputError, match=r"r\.json: is a folder; rigsim replaces only regular files"):
        (tmp_path / "r.json").mkdir()
        write_json(tmp_path / "r.json", {"a": 1})


def test_save_figure_writes_the_format_its_suffix_names(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rigsim.files.atomic import save_figure

    fig = plt.figure(figsize=(1, 1))
    save_figure(fig, tmp_path / "f.svg")
    save_figure(fig, tmp_path / "f.png")
    plt.close(fig)
    assert (tmp_path / "f.svg").read_bytes().lstrip().startswith((b"<?xml", b"<svg"))
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"



def test_cache_dir_follows_rigsim_then_xdg_then_home(tmp_path, monkeypatch):
    from pathlib import Path

    from rigsim.files import cache_dir

    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("RIGSIM_CACHE_DIR", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    assert cache_dir() == Path(tmp_path / "home" / ".cache" / "rigsim")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "rigsim"
    monkeypatch.setenv("RIGSIM_CACHE_DIR", str(tmp_path / "mine"))
    assert cache_dir() == tmp_path / "mine"


def test_cached_json_computes_once_and_trusts_only_a_file_that_fits(tmp_path, monkeypatch):
    import json
    import os

    from rigsim.files import cached_json

    monkeypatch.setenv("RIGSIM_CACHE_DIR", str(tmp_path / "cache"))
    calls = []

    def compute():
        calls.append(1)
        return {"F_mm": 0.1 + 0.2, "uv": [1.0 / 3.0, -2.5e-17]}

    key = {"what": "a calibration", "n": 3, "code": "abc"}
    first = cached_json("kind", key, compute, lambda d: "F_mm" in d)
    assert first == compute() and len(calls) == 2                     # no file yet: computed
    (f,) = (tmp_path / "cache" / "kind").iterdir()
    again = cached_json("kind", key, compute, lambda d: "F_mm" in d)
    assert again == first and len(calls) == 2                         # from the file, every float bit for bit
    assert cached_json("kind", {**key, "code": "abd"}, compute, lambda d: True) == first and len(calls) == 3
    # a file that does not fit is computed again and replaced: garbage, another key under this name, a value refused
    for text in ("{not json", json.dumps({"key": {**key, "n": 4}, "value": first}), json.dumps({"key": key, "value": [1]}),
                 json.dumps({"key": key, "value": {"F_mm": float("nan")}})):
        f.write_text(text)
        n = len(calls)
        assert cached_json("kind", key, compute, lambda d: d.get("F_mm") == d.get("F_mm")) == first and len(calls) == n + 1
        assert json.loads(f.read_text())["value"] == first
    # a cache folder that cannot be written costs the computation only
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where the cache folder should be")
    monkeypatch.setenv("RIGSIM_CACHE_DIR", str(blocker))
    assert cached_json("kind", key, compute, lambda d: True) == first and blocker.is_file()
    assert not any(p.name.startswith(".") for p in os.scandir(tmp_path / "cache" / "kind"))  # no temporary left
