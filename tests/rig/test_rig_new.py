"""`rigsim rig new star-sensor` (a complete star rig from what a user knows of the camera) and `rigsim rig
copy` (a packaged rig as a starting point). The written file loads, `rig check` passes, the focal length
and the field of view follow their closed forms, a frame renders with the real camera's DN grid; bad
arguments are one line and exit 2 with nothing written."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rigsim import cli
from rigsim.rig.load import SCENES_DIR, load_star_rig

BLACKFLY = ["--resolution", "1024x768", "--pixel-pitch-um", "6.9"]


def _new(tmp_path, *args, name="my.toml"):
    out = tmp_path / name
    rc = cli.main(["rig", "new", "star-sensor", *args, "--out", str(out)])
    return rc, out


def test_a_rig_from_the_focal_length_is_complete_and_consistent(tmp_path, capsys):
    rc, out = _new(tmp_path, *BLACKFLY, "--focal-length-mm", "35", "--f-number", "1.9", "--adc-bits", "12",
                   "--container-bits", "16", "--offset-dn", "100")
    assert rc == 0, capsys.readouterr().err
    rig = load_star_rig(out)
    s, n, d = rig.sensor, rig.nominal, rig.sensor.detector
    f_px = 35.0 * 1000.0 / 6.9                                   # the closed form: f (mm) / pitch
    assert s.f_px == pytest.approx(f_px, rel=1e-12) and s.resolution_px == [1024, 768]
    assert s.aperture_diameter_mm == pytest.approx(35.0 / 1.9, rel=1e-6)
    assert s.principal_point_px == [511.5, 383.5] and (s.k1, s.k2, s.p1, s.p2) == (0, 0, 0, 0)
    # [nominal]: the same design, with σ of a few % of f and of the width
    assert n.focal_length_mm == s.focal_length_mm and n.principal_point_px == [511.5, 383.5]
    assert (n.k1, n.k2, n.p1, n.p2) == (0, 0, 0, 0)
    assert 0.01 <= n.focal_length_sigma_px / f_px <= 0.05
    assert 0.01 <= n.principal_point_sigma_px / 1024 <= 0.05
    assert (d.adc_bits, d.container_bits, d.offset_dn, d.code_step_dn, d.saturation_dn) == (12, 16, 100.0, 16, 65520)
    assert d.gain_dn_per_e * d.full_well_e == pytest.approx(4095 - 100, rel=1e-3)  # the ADC's top code at the full well
    # the identification's search radius covers 4× the prior's error, as the packaged rig's 60 px does its 15 px
    err_px = f_px * math.tan(math.radians(rig.identification.attitude_error_deg))
    assert 4 * err_px <= rig.identification.search_radius_px <= 4 * err_px + 5
    text = out.read_text()
    for key, note in (("resolution_px", "given"), ("focal_length_mm", "given"), ("aperture_diameter_mm", "derived"),
                      ("quantum_efficiency", "default"), ("adc_bits", "given"), ("magnitude_limit", "derived")):
        line = next(ln for ln in text.splitlines() if ln.startswith(key + " "))
        assert f"# {note}" in line, line
    capsys.readouterr()
    assert cli.main(["rig", "check", str(out)]) == 0
    checked = capsys.readouterr().out
    assert "OK" in checked and not any(ln.startswith("!") for ln in checked.splitlines())


def test_a_rig_from_the_field_of_view_round_trips_to_it(tmp_path):
    rc, out = _new(tmp_path, *BLACKFLY, "--fov-deg", "11.4")
    assert rc == 0
    s = load_star_rig(out).sensor
    assert 2 * math.degrees(math.atan(1024 / 2 / s.f_px)) == pytest.approx(11.4, abs=1e-7)
    assert 2 * math.degrees(math.atan(768 / 2 / s.f_px)) == pytest.approx(s.fov_deg[1], abs=1e-12)
    assert s.focal_length_mm == pytest.approx(512 / math.tan(math.radians(5.7)) * 6.9e-3, rel=1e-9)
    assert s.f_number == pytest.approx(2.0) and "default f/2" in out.read_text()


def test_a_new_rig_renders_frames_on_the_cameras_dn_grid(tmp_path, capsys):
    rc, out = _new(tmp_path, *BLACKFLY, "--focal-length-mm", "35", "--adc-bits", "12", "--container-bits", "16")
    assert rc == 0
    assert cli.main(["render", "star-field", "--rig", str(out), "--renderer", "analytic", "--out", str(tmp_path / "f"),
                     "--name", "a", "--attitude", "ra=83.8,dec=-5.4"]) == 0
    import cv2

    dn = cv2.imread(str(tmp_path / "f" / "a.png"), cv2.IMREAD_UNCHANGED)
    assert dn.shape == (768, 1024) and np.all(dn % 16 == 0)
    d = load_star_rig(out).sensor.detector
    dark_codes = d.offset_dn + d.gain_dn_per_e * d.dark_current_e_per_s * d.exposure_s  # + the faint sky
    assert 16 * dark_codes <= np.median(dn) <= 16 * (dark_codes + 2)
    assert "isolated stars matched within 1 px" in capsys.readouterr().out


@pytest.mark.parametrize("args,msg", [
    (["--resolution", "1024", "--pixel-pitch-um", "6.9", "--fov-deg", "10"], "argument --resolution: '1024' is not WxH"),
    (["--resolution", "1024x9000", "--pixel-pitch-um", "6.9", "--fov-deg", "10"], "each from 16 to 8192"),
    ([*BLACKFLY, "--fov-deg", "0"], "argument --fov-deg: '0' is not a number from 0.1 to 120"),
    (["--resolution", "1024x768", "--pixel-pitch-um", "-1", "--fov-deg", "10"], "argument --pixel-pitch-um: '-1'"),
    ([*BLACKFLY, "--fov-deg", "nan"], "argument --fov-deg: 'nan'"),
    ([*BLACKFLY], "one of the arguments --focal-length-mm --fov-deg is required"),
    ([*BLACKFLY, "--fov-deg", "10", "--focal-length-mm", "35"], "not allowed with argument"),
    ([*BLACKFLY, "--fov-deg", "10", "--container-bits", "10"], "--container-bits 10 is narrower than the ADC's 12 bits"),
    ([*BLACKFLY, "--fov-deg", "10", "--adc-bits", "10", "--offset-dn", "1023"], "leaves no room in a 10-bit ADC"),
    ([*BLACKFLY, "--focal-length-mm", "1.6", "--resolution", "16x16", "--pixel-pitch-um", "100"], None),
])
def test_bad_arguments_are_one_line_and_write_nothing(tmp_path, capsys, args, msg):
    rc, out = _new(tmp_path, *args)
    err = capsys.readouterr().err
    if msg is None:  # an extreme but valid camera: written and checked
        assert rc == 0 and load_star_rig(out).sensor.resolution_px == [16, 16]
        return
    assert rc == 2 and msg in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


def test_an_existing_file_is_kept_unless_forced(tmp_path, capsys):
    out = tmp_path / "my.toml"
    out.write_text("mine\n")
    rc, _ = _new(tmp_path, *BLACKFLY, "--fov-deg", "11.4")
    err = capsys.readouterr().err
    assert rc == 2 and "exists; give --force" in err and out.read_text() == "mine\n"
    assert cli.main(["rig", "new", "star-sensor", *BLACKFLY, "--fov-deg", "11.4", "--out", str(out), "--force"]) == 0
    assert load_star_rig(out).sensor.resolution_px == [1024, 768]
    (tmp_path / "d.toml").mkdir()
    rc, _ = _new(tmp_path, *BLACKFLY, "--fov-deg", "11.4", name="d.toml")
    assert rc == 2 and "is a folder; rigsim replaces only regular files" in capsys.readouterr().err


def test_rig_copy_writes_the_packaged_rig_and_refuses_to_overwrite(tmp_path, capsys):
    dest = tmp_path / "s.toml"
    assert cli.main(["rig", "copy", "star_sensor", str(dest)]) == 0
    assert dest.read_bytes() == (SCENES_DIR / "star_sensor.toml").read_bytes()
    assert load_star_rig(dest).name == "star-sensor-20deg"
    dest.write_text("edited\n")
    capsys.readouterr()
    assert cli.main(["rig", "copy", "star_sensor", str(dest)]) == 2
    err = capsys.readouterr().err
    assert "exists; give --force" in err and len(err.strip().splitlines()) == 1 and dest.read_text() == "edited\n"
    assert cli.main(["rig", "copy", "star_sensor.toml", str(dest), "--force"]) == 0
    assert dest.read_bytes() == (SCENES_DIR / "star_sensor.toml").read_bytes()


@pytest.mark.parametrize("name,dest,msg", [
    ("nope", "x.toml", "no packaged rig 'nope'; the packaged rigs are dual_line_array_prism, star_sensor"),
    ("../scenes/star_sensor", "x.toml", "no packaged rig"),
    ("star_sensor", "x.txt", "'x.txt': the name must end in .toml"),
    ("star_sensor", "sub", "'sub': the name must end in .toml"),
])
def test_rig_copy_bad_arguments_are_one_line(tmp_path, capsys, monkeypatch, name, dest, msg):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    assert cli.main(["rig", "copy", name, dest]) == 2
    err = capsys.readouterr().err
    assert msg in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x.toml").exists() and not (tmp_path / "x.txt").exists()


def test_the_documented_example_is_what_the_command_writes(tmp_path):
    """docs/custom-rig.md's star sensor (docs/examples/star_blackfly.toml) is the command's output today."""
    from pathlib import Path

    doc = Path(__file__).resolve().parents[2] / "docs" / "examples" / "star_blackfly.toml"
    rc, out = _new(tmp_path, *BLACKFLY, "--focal-length-mm", "35", "--f-number", "1.9", "--adc-bits", "12",
                   "--container-bits", "16")
    assert rc == 0 and out.read_text() == doc.read_text()


@pytest.mark.slow
def test_the_star_calibration_runs_on_a_new_rig(tmp_path, capsys):
    """The seed-004 run on the documented camera (analytic frames, no study; ~12 s): every frame identified,
    none wrong, the batch fit's χ²/dof near 1 and its f error within 4σ of its own σ."""
    import re

    rc, out = _new(tmp_path, *BLACKFLY, "--focal-length-mm", "35", "--f-number", "1.9", "--adc-bits", "12",
                   "--container-bits", "16")
    assert rc == 0
    assert cli.main(["run", "star-calibration", "--rig", str(out), "--no-study", "--quiet", "--out", str(tmp_path / "r")]) == 0
    text = capsys.readouterr().out
    assert "identification: 20/20 frames" in text and "(0 wrong)" in text, text
    m = re.search(r"f ([+-][\d.]+)±([\d.]+) px.*\(χ²/dof ([\d.]+)\)", text)
    assert m and abs(float(m[1])) < 4 * float(m[2]) and 0.7 < float(m[3]) < 1.4, text
