"""Inputs read strictly and bounded before work: an image's header is checked (size against the memory budget and
the rig's detector, pages) before its pixels are decoded; FITS pixels of 1e300 are refused; numbers in tables and
options take ASCII digits only; JSON and OpenCV FileStorage files are bounded in nesting, integer length and claimed
matrix size before they are parsed."""

import sys
from pathlib import Path

import numpy as np
import pytest

from rigsim.errors import InputError
from rigsim.files import Column, read_image, read_table, write_image
from rigsim.files.results import parse_json, read_json

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "attack"))
import hostile_inputs as H  # noqa: E402


@pytest.mark.parametrize("make, words", [
    (lambda p: H.png_header_bomb(p / "h.png"), "its header announces a 65535×65535 px frame"),
    (lambda p: H.tiff_header_bomb(p / "h.tif"), "its header announces a 100000×100000 px frame"),
    (lambda p: H.fits_header_bomb(p / "h.fits"), "its header announces a 100000×100000 px frame"),
])
def test_a_header_that_claims_too_many_pixels_is_refused_before_decoding(tmp_path, monkeypatch, make, words):
    """The decoders (OpenCV's, astropy's data reader) are never called: the header alone refuses the file."""
    import cv2

    from rigsim.files import images

    p = make(tmp_path)
    calls = []
    monkeypatch.setattr(cv2, "imread", lambda *a, **k: calls.append(a))
    monkeypatch.setattr(images, "_read_fits", lambda *a, **k: calls.append(a))
    with pytest.raises(InputError, match=words):
        read_image(p)
    assert calls == []


def test_a_valid_frame_larger_than_the_memory_budget_is_refused(tmp_path, monkeypatch):
    """A 4000² PNG of zeros (a few kB) decodes to 32 MB and needs about 1 GB to measure: refused under a 0.5 GB
    budget, read under the machine's."""
    p = H.png_zero_bomb(tmp_path / "z.png", 4000)
    assert p.stat().st_size < 200_000
    monkeypatch.setenv("RIGSIM_MEMORY_GB", "0.5")
    with pytest.raises(InputError, match=r"4000×4000 px frame \(16 Mpx\), which needs about 1.02 GB .* 500 MB is available"):
        read_image(p)
    monkeypatch.setenv("RIGSIM_MEMORY_GB", "x")
    with pytest.raises(Exception, match="RIGSIM_MEMORY_GB = 'x'"):
        read_image(p)
    monkeypatch.delenv("RIGSIM_MEMORY_GB")
    assert read_image(p).shape == (4000, 4000)


def test_the_rig_detector_is_checked_from_the_header(tmp_path, monkeypatch):
    """With the rig's detector given, a frame of another size is refused from its header: the decoder is never called."""
    import cv2

    p = H.png_zero_bomb(tmp_path / "z.png", 2000)
    calls = []
    monkeypatch.setattr(cv2, "imread", lambda *a, **k: calls.append(a))
    with pytest.raises(InputError, match=r"2000×2000 px \(width×height\); expected 1024×1024 px, the rig's detector"):
        read_image(p, shape=(1024, 1024))
    assert calls == []


def test_multi_page_and_disguised_files_are_refused(tmp_path):
    with pytest.raises(InputError, match=r"a multi-page TIFF \(2 pages\); rigsim reads one frame per file"):
        read_image(H.tiff_pages(tmp_path / "two.tif"))
    assert read_image(H.tiff_pages(tmp_path / "one.tif", pages=1)).shape == (64, 64)
    import cv2

    ok, jpg = cv2.imencode(".jpg", np.zeros((8, 8), np.uint8))
    (tmp_path / "j.png").write_bytes(jpg.tobytes())  # a JPEG named .png: OpenCV would decode it by its content
    with pytest.raises(InputError, match=r"j\.png: not a readable PNG image \(no PNG signature\)"):
        read_image(tmp_path / "j.png")
    write_image(tmp_path / "t.tif", np.zeros((4, 4), np.uint16))
    (tmp_path / "t.png").write_bytes((tmp_path / "t.tif").read_bytes())
    with pytest.raises(InputError, match="no PNG signature"):
        read_image(tmp_path / "t.png")


def test_a_fits_file_with_two_images_is_refused(tmp_path):
    from astropy.io import fits

    fits.HDUList([fits.PrimaryHDU(np.zeros((4, 4), np.uint16)), fits.ImageHDU(np.ones((4, 4), np.uint16))]).writeto(
        tmp_path / "two.fits")
    with pytest.raises(InputError, match=r"a FITS file with several images \(2 image HDUs with data\)"):
        read_image(tmp_path / "two.fits")


@pytest.mark.parametrize("value", [1e300, -1e300, 2e9])
def test_fits_pixels_beyond_any_detector_are_refused(tmp_path, value):
    with pytest.raises(InputError, match=r"FITS pixel values up to .* in magnitude; expected at most 1e\+09"):
        read_image(H.fits_huge_values(tmp_path / "f.fits", (16, 16), value))
    assert read_image(H.fits_huge_values(tmp_path / "ok.fits", (16, 16), 60000.0)).max() == 60000.0


@pytest.mark.parametrize("cell", ["١٢", "1_0", "１２", "12.5\u0663", "0x10", "1" * 70, "٣e2"])
def test_table_numbers_take_ascii_digits_only(tmp_path, cell):
    (tmp_path / "t.csv").write_text(f"frame,x_deg,n\na,{cell},{cell}\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"line 2, column x_deg: .* is not a number in ASCII digits"):
        read_table(tmp_path / "t.csv", [Column("frame", kind="str"), Column("x", "deg")])
    with pytest.raises(InputError, match=r"line 2, column n: .* is not an integer in ASCII digits"):
        read_table(tmp_path / "t.csv", [Column("frame", kind="str"), Column("n", kind="int")])


def test_table_numbers_in_ascii_still_read(tmp_path):
    (tmp_path / "t.csv").write_text("frame,x_deg,n\na, -1.5e-3 ,+7\nb,.5,-0\nc,3.,9223372036854775807\n")
    t = read_table(tmp_path / "t.csv", [Column("frame", kind="str"), Column("x", "deg"), Column("n", kind="int")])
    assert t["x_deg"].tolist() == [-1.5e-3, 0.5, 3.0] and t["n"].tolist() == [7, 0, 2**63 - 1]
    (tmp_path / "big.csv").write_text("frame,n\na,9223372036854775808\n")
    with pytest.raises(InputError, match="at most 2⁶³"):
        read_table(tmp_path / "big.csv", [Column("frame", kind="str"), Column("n", kind="int")])


@pytest.mark.parametrize("argv, words", [
    (["triad", "181.398", "0.528", "91.386", "-0.0٤8"], "'-0.0٤8' is not a number in ASCII digits"),
    (["triad", "181.398", "0.528", "91.386", "0_048"], "'0_048' is not a number in ASCII digits"),
    (["triad", "--sigma-arcsec", "١", "181.398", "0.528", "91.386", "-0.048"], "'١' is not a number from"),
    (["dataset", "generate", "sun_sensor_2axis_diaphragm", "--out", "d", "--frames", "1_0"], "'1_0' is not an integer"),
    (["check-matrix", "1 0 0; 0 1 0; 0 0 ١"], "'١' is not a number in ASCII digits"),
    (["render", "sun-sensor", "--pose", "X=١٠,Y=0"], "not a number of degrees in ASCII digits"),
    (["render", "star-field", "--attitude", "ra=1,dec=2,ra=3"], "ra given twice"),
    (["dataset", "generate", "sun_sensor_2axis_diaphragm", "--out", "d", "--sweep", "X=1,2 X=3"], "'X' given twice"),
])
def test_options_take_ascii_digits_and_each_axis_once(tmp_path, monkeypatch, capsys, argv, words):
    from rigsim.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("text, words", [
    ("[" * 100_000 + "]" * 100_000, "JSON nested 100000 deep"),
    ('{"a": ' + "9" * 100_001 + "}", "an integer of 100001 digits"),
    ('{"a": [1, 2' + ", 3" * 10 + "}", "not valid JSON"),
])
def test_json_is_bounded_before_it_is_parsed(tmp_path, text, words):
    (tmp_path / "r.json").write_text(text)
    with pytest.raises(InputError, match=words):
        read_json(tmp_path / "r.json")
    with pytest.raises(InputError, match="at most 1 MiB"):
        parse_json(b"{}" + b" " * (2 << 20), "big.json", max_bytes=1 << 20)
    assert parse_json('{"a": [[[1]]], "s": "[[[[[["}', "ok.json") == {"a": [[[1]]], "s": "[[[[[["}


@pytest.mark.parametrize("make, words", [
    (lambda p: H.deep_yaml(p / "c.yml"), "nested 100001 deep"),
    (lambda p: H.deep_json(p / "c.json"), "nested 10000[01] deep"),
    (lambda p: H.deep_xml(p / "c.xml"), "nested 100001 deep"),
    (lambda p: H.opencv_matrix_bomb(p / "c.yml"), r"a matrix claims 1000000000000 values \(rows 1000000, cols 1000000\)"),
    (lambda p: (p / "c.json").write_text("[1, 2, 3]") and p / "c.json", "the top level is not a map"),
])
def test_opencv_camera_files_are_bounded_before_opencv_parses_them(tmp_path, make, words):
    """OpenCV's FileStorage parser recurses (a 10⁵-deep file crashes the process) and allocates a matrix's claimed
    size before reading its data: both are refused from the text first."""
    from rigsim.rig.opencv_camera import read_opencv_camera

    with pytest.raises(InputError, match=words):
        read_opencv_camera(make(tmp_path))


@pytest.mark.parametrize("suffix", [".yml", ".json", ".xml"])
def test_an_opencv_camera_file_still_reads(tmp_path, suffix):
    from rigsim.files.opencv import write_opencv_camera
    from rigsim.rig.opencv_camera import read_opencv_camera

    write_opencv_camera(tmp_path / f"c{suffix}", 1000, 1001, 640, 512, [0.01, -0.02, 0, 0, 0.003], 1280, 1024)
    cam = read_opencv_camera(tmp_path / f"c{suffix}")
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.size, cam.dist["k3"]) == (1000, 1001, 640, 512, (1280, 1024), 0.003)
