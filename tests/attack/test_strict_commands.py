"""The small commands read their inputs strictly: a turntable reading names every axis once, an axis order is
one the table has, two nulls are two faces' nulls, spots lie on the detector, a frame is given once, and a CRLF
stream is read as lines. Each case is one line, exit 2, nothing written (or, for the stream, a clean result)."""

import io
import sys
from pathlib import Path

import numpy as np
import pytest

from rigsim.cli import main

sys.path.insert(0, str(Path(__file__).resolve().parent))
import valid_inputs as V  # noqa: E402


def _one_line(capsys, argv, words):
    rc = main(argv)
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and words in err, (argv, err)


@pytest.mark.parametrize("extra, words", [
    (["--reading", "X=1,X=2"], "axis X given twice"),
    (["--reading", "X=181.4"], "no angle for axis Y"),
    (["--reading", "X=181.4,Y=١"], "is not a number of degrees in ASCII digits"),
    (["--axis-order", "ZZ"], "--axis-order = 'ZZ': allowed for this 2-axis table: XY, YX"),
])
def test_concentricity_reads_a_whole_reading_and_a_known_axis_order(tmp_path, capsys, extra, words):
    """Refused before the frames are read (they need not exist)."""
    _one_line(capsys, ["concentricity", str(tmp_path / "h.png"), str(tmp_path / "s.png"), *extra], words)


def test_concentricity_refuses_one_frame_as_both(tmp_path, capsys):
    (tmp_path / "h.png").write_bytes(b"")
    _one_line(capsys, ["concentricity", str(tmp_path / "h.png"), str(tmp_path / "." / "h.png")], "listed twice")


@pytest.mark.parametrize("text, words", [
    ("face,x_deg,y_deg\n+Z,1e308,0.528\n+Y,91.386,-0.048\n", "column x_deg: 1e+308; expected -360 to 360 degrees"),
    ("face,x_deg,y_deg\n+Z,181.398,0.528\n+Y,181.398,0.528\n", "the two nulls give measured normals 0° apart"),
    ("face,x_deg,y_deg\n+Z,181.398,0.528\n+Z,91.386,-0.048\n", "'+Z' again; expected the nulls of two different faces"),
])
def test_triad_refuses_nulls_that_cannot_be_two_faces(tmp_path, capsys, text, words):
    (tmp_path / "n.csv").write_text(text)
    _one_line(capsys, ["triad", "--nulls", str(tmp_path / "n.csv"), "--out", str(tmp_path / "c.json")], words)
    assert not (tmp_path / "c.json").exists()


def _spots(path, u=2559.5):
    path.write_text("camera,u_m1_px,v_m1_px,u_m2_px,v_m2_px\n" f"forward,{u},1919.5,2559.5,1920.5\n")
    return path


def test_boresight_solve_refuses_spots_off_the_detector(tmp_path, capsys):
    ref = _spots(tmp_path / "ref.csv")
    _one_line(capsys, ["boresight", "solve", "--reference", str(ref), "--measured", str(_spots(tmp_path / "m.csv", 1e308))],
              "off camera forward's detector")
    _one_line(capsys, ["boresight", "solve", "--reference", str(ref), "--measured", str(tmp_path / "m.csv"),
                       str(tmp_path / "m.csv")], "listed twice")


def test_boresight_stream_reads_crlf_lines(tmp_path, capsys, monkeypatch):
    ref = _spots(tmp_path / "ref.csv")
    rows = "camera,u_m1_px,v_m1_px,u_m2_px,v_m2_px,sample\r\nforward,2559.6,1919.5,2559.5,1920.5,7\r\n\r\n"
    monkeypatch.setattr(sys, "stdin", io.StringIO(rows, newline=""))
    assert main(["boresight", "solve", "--reference", str(ref), "--stream"]) == 0
    out = capsys.readouterr().out
    assert "\r" not in out and out.splitlines()[1].startswith("7,forward,")
    monkeypatch.setattr(sys, "stdin", io.StringIO("camera,u_m1_px,v_m1_px,u_m2_px,v_m2_px\r\nforward,1e308,1,2,3\r\n"))
    _one_line(capsys, ["boresight", "solve", "--reference", str(ref), "--stream"], "stdin: line 2: u_m1_px, v_m1_px")


def test_centroid_refuses_a_frame_twice_and_two_frames_of_one_name(tmp_path, capsys):
    from rigsim.files import write_image

    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for d in ("a", "b"):
        write_image(tmp_path / d / "f.png", np.zeros((8, 8), np.uint16))
    _one_line(capsys, ["centroid", str(tmp_path / "a" / "f.png"), str(tmp_path / "a" / "." / "f.png"), "--out",
                       str(tmp_path / "c.csv")], "listed twice")
    _one_line(capsys, ["centroid", str(tmp_path / "a" / "f.png"), str(tmp_path / "b" / "f.png"), "--out",
                       str(tmp_path / "c.csv")], "two frames named 'f.png' in different folders")
    assert not (tmp_path / "c.csv").exists()


def test_a_centroid_table_listing_a_frame_twice_is_refused(tmp_path, capsys):
    a, c = V.sweep_tables(tmp_path)
    lines = c.read_text().splitlines()
    c.write_text("\n".join([*lines, lines[5]]) + "\n")
    _one_line(capsys, ["calibrate", "sun-sensor", "--angles", str(a), "--centroids", str(c), "--out",
                       str(tmp_path / "s.json")], "spot 0 already on line 6")


def test_a_centroid_off_the_sun_sensor_is_refused(tmp_path, capsys):
    a, c = V.sweep_tables(tmp_path)
    lines = c.read_text().splitlines()
    f = lines[5].split(",")
    f[1] = "1e300"
    lines[5] = ",".join(f)
    c.write_text("\n".join(lines) + "\n")
    _one_line(capsys, ["calibrate", "sun-sensor", "--angles", str(a), "--centroids", str(c), "--out",
                       str(tmp_path / "s.json")], "line 6, columns u_px, v_px: (1e+300,")
