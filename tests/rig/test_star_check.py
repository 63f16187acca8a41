"""`rig check` on a star rig: a `!` line when [nominal] and [sensor] disagree by more than the nominal's
stated σ, saying by how many σ (computed here from the file's numbers), and none on the packaged rig."""

from __future__ import annotations

import pytest

from rigsim import cli
from rigsim.rig.load import SCENES_DIR

PACKAGED = (SCENES_DIR / "star_sensor.toml").read_text()


def _check(tmp_path, capsys, text):
    p = tmp_path / "r.toml"
    p.write_text(text)
    capsys.readouterr()
    rc = cli.main(["rig", "check", str(p)])
    return rc, capsys.readouterr().out.splitlines()


def test_the_packaged_star_rig_has_no_warning(tmp_path, capsys):
    rc, lines = _check(tmp_path, capsys, PACKAGED)
    assert rc == 0 and lines[-1].endswith("(seed 004, family star)")
    f = next(ln for ln in lines if "nominal f" in ln)
    # [nominal] 43.345 mm, [sensor] 43.3 mm, 15 µm pixels, σ 10 px: 3.0 px = 0.3σ
    assert f.startswith(" ") and "+3.0 px, 0.3σ" in f
    assert not any(ln.startswith("!") for ln in lines)


def test_a_focal_length_pasted_into_sensor_alone_is_a_warning_in_sigma(tmp_path, capsys):
    """[sensor] took a calibration (f = 47.63 mm) and [nominal] kept the old design (43.345 mm)."""
    text = PACKAGED.replace("focal_length_mm = 43.3  ", "focal_length_mm = 47.63")
    assert "focal_length_mm = 47.63" in text
    rc, lines = _check(tmp_path, capsys, text)
    k = abs(43.345 - 47.63) * 1000 / 15.0 / 10.0                  # |Δf| in px over focal_length_sigma_px
    warn = [ln for ln in lines if ln.startswith("!")]
    assert rc == 0 and len(warn) == 1, lines
    assert "nominal f" in warn[0] and f"{k:.1f}σ" in warn[0] and "more than the stated σ" in warn[0]


@pytest.mark.parametrize("pp,sigma,warned,k", [
    ("[541.5, 481.5]", "10.0", True, 3.0),     # 30 px off on both axes over σ 10 px
    ("[541.5, 481.5]", "40.0", False, 0.75),   # the same offset inside a σ of 40 px
    ("[511.5, 520.0]", "5.0", True, 1.7),      # one axis: 8.5 px over 5 px
])
def test_a_principal_point_off_by_more_than_its_sigma_is_a_warning(tmp_path, capsys, pp, sigma, warned, k):
    text = PACKAGED.replace("principal_point_px = [514.3, 508.6]", f"principal_point_px = {pp}")
    text = text.replace("principal_point_sigma_px = 10.0", f"principal_point_sigma_px = {sigma}")
    rc, lines = _check(tmp_path, capsys, text)
    centre = next(ln for ln in lines if "nominal centre" in ln)
    assert rc == 0 and centre.startswith("!") == warned, centre
    assert f"{k:.1f}σ" in centre


def test_a_rig_without_nominal_is_compared_as_the_design(tmp_path, capsys):
    head, _, tail = PACKAGED.partition("\n[nominal]")
    text = head + "\n[sky]" + tail.partition("\n[sky]")[2]
    assert "\n[nominal]" not in text and "\n[sky]" in text
    text = text.replace("focal_length_mm = 43.3  ", "focal_length_mm = 43.5  ")  # the design: the nominal follows it
    rc, lines = _check(tmp_path, capsys, text)
    f = next(ln for ln in lines if "nominal f" in ln)
    assert rc == 0 and "no [nominal]: the design" in f and "+0.0 px, 0.0σ" in f and not f.startswith("!")
