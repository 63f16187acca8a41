"""The star-sensor rig file: defaults load; bad input names file, field, value, range."""

import tomllib

import pytest

from rigsim.errors import RigError
from rigsim.rig.load import SCENES_DIR, load_star_rig, parse_star_rig


def test_default_rig(star_rig):
    s = star_rig.sensor
    assert s.f_px == pytest.approx(43.3e3 / 15.0)
    assert 20.0 < s.fov_deg[0] < 20.3
    # σ = (defocus / N / 2) / 2 ⊕ 0.42 λ N, in pixels: (100/2.165/4 ⊕ 0.55) µm / 15 µm
    N = 43.3 / 20.0
    assert s.psf_sigma_px == pytest.approx(((100 / N / 4) ** 2 + (0.42 * 0.6 * N) ** 2) ** 0.5 / 15.0)


def test_errors_name_field_value_and_range(tmp_path):
    data = tomllib.loads((SCENES_DIR / "star_sensor.toml").read_text())
    data["sensor"]["pixel_pitch_um"] = -3
    with pytest.raises(RigError) as e:
        parse_star_rig(data, "x.toml")
    msg = str(e.value)
    assert "x.toml" in msg and "sensor.pixel_pitch_um" in msg and "-3" in msg and "> 0.5" in msg
    data = tomllib.loads((SCENES_DIR / "star_sensor.toml").read_text())
    data["calibration"]["wieghting"] = "x"
    with pytest.raises(RigError, match="unknown key `calibration.wieghting`.*weighting"):
        parse_star_rig(data)
    data = tomllib.loads((SCENES_DIR / "star_sensor.toml").read_text())
    data["sensor"]["k1"], data["sensor"]["k2"] = -2.0, -20.0  # folds back at r_d ≈ 0.20 < corner 0.25
    with pytest.raises(RigError, match="folds back"):
        parse_star_rig(data)
    with pytest.raises(RigError, match="no such rig file"):
        load_star_rig(tmp_path / "missing.toml")
