"""``rigsim view``: registered as a plugin, writes pictures off screen, rejects bad input clearly."""

import pytest

pytest.importorskip("pyvista")

from rigsim.cli import main


def _run(capsys, *argv):
    rc = main(["view", *argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_view_command_is_registered():
    from rigsim.cli import build_parser

    p = build_parser()
    args = p.parse_args(["view", "sun_sensor_2axis_diaphragm", "--screenshot", "x.png"])
    assert args.func.__name__ == "cmd_view"


def test_view_screenshot_and_export(tmp_path, capsys):
    png, gltf = tmp_path / "r.png", tmp_path / "r.gltf"
    rc, out, err = _run(capsys, "sun_sensor_3axis_autocollimator", "--pose", "Y=0.3377,X=90.2111", "--size", "480x320",
                        "--screenshot", str(png), "--export", str(gltf))
    assert rc == 0, err
    assert png.exists() and gltf.exists()
    assert "Y'=0.338" in out and "X'=90.211" in out and "wrote" in out
    assert "autocollimator reading" in out


@pytest.mark.parametrize("argv, words", [
    (["sun_sensor_2axis_diaphragm", "--pose", "X=400", "--screenshot", "a.png"], ["--pose X = 400", "-360 to 360"]),
    (["sun_sensor_2axis_diaphragm", "--pose", "X=1,Z=2", "--screenshot", "a.png"], ["axis 'Z'", "['X', 'Y']"]),
    (["sun_sensor_2axis_diaphragm", "--pose", "X=1,Y", "--screenshot", "a.png"], ["LABEL=DEGREES"]),
    (["sun_sensor_2axis_diaphragm", "--face=-Z", "--screenshot", "a.png"], ["--face = '-Z'", "'+Z', '+Y'"]),
    (["sun_sensor_2axis_diaphragm", "--size", "12x900", "--screenshot", "a.png"], ["width = 12", "64 to 8192"]),
    (["sun_sensor_2axis_diaphragm", "--size", "big", "--screenshot", "a.png"], ["--size = 'big'", "WIDTHxHEIGHT"]),
    (["sun_sensor_2axis_diaphragm", "--screenshot", "a.jpg"], ["--screenshot = 'a.jpg'", ".png"]),
    (["sun_sensor_2axis_diaphragm", "--export", "a.stl"], ["--export = 'a.stl'", ".gltf, .vtkjs, .vtm"]),
    (["no_such_rig", "--screenshot", "a.png"], ["no such rig file", "sun_sensor_2axis_diaphragm"]),
    (["star_sensor", "--pose", "X=3", "--screenshot", "a.png"], ["--pose = X=3", "no turntable"]),
])
def test_view_bad_input_is_one_clear_line(tmp_path, capsys, monkeypatch, argv, words):
    monkeypatch.chdir(tmp_path)
    rc, out, err = _run(capsys, *argv)
    assert rc == 2
    line = err.strip()
    assert line.startswith("rigsim: error:") and "\n" not in line and "Traceback" not in err
    for w in words:
        assert w in line
    assert not (tmp_path / "a.png").exists()


def test_window_and_html_need_what_they_need(capsys, monkeypatch):
    from rigsim.view.plot import html_available

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    import sys

    if sys.platform in ("win32", "darwin"):
        pytest.skip("always has a display")
    rc, _, err = _run(capsys, "sun_sensor_2axis_diaphragm", "--window")
    assert rc == 2 and "needs a display" in err and "--screenshot" in err
    rc, _, err = _run(capsys, "sun_sensor_2axis_diaphragm")
    assert rc == 2 and "needs a display" in err
    if not html_available():
        rc, _, err = _run(capsys, "sun_sensor_2axis_diaphragm", "--html", "x.html")
        assert rc == 2 and "trame-pyvista" in err and ".gltf" in err
