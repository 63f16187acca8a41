"""Seed-003 rig file: Table 2 defaults, loader errors name file/field/value/allowed range."""

import copy
import tomllib

import pytest

from rigsim.errors import RigError
from rigsim.optics.line_camera import CameraGeometry
from rigsim.rig.load import SCENES_DIR, load_boresight_rig, parse_boresight_rig

BASE = tomllib.loads((SCENES_DIR / "dual_line_array_prism.toml").read_text())


def test_default_rig_is_table_2():
    rig = load_boresight_rig()
    assert rig.seed_document == "003" and len(rig.cameras) == 2
    for cam in rig.cameras:
        assert (cam.pixel_pitch_um, cam.off_axis_deg, cam.telecentric_factor) == (10.0, 6.0, 0.5)
        assert (cam.m1_tilt_deg, cam.m2_tilt_deg) == (0.0, 0.0)
        assert cam.m1_reference_px == [0.0, 0.0] and cam.m2_reference_px == [0.0, 0.0]
        assert (cam.focal_length_mm, cam.m1_center_y_mm, cam.m2_center_y_mm) == (6000.0, 500.0, -500.0)
        assert (cam.detector_width_px, cam.detector_height_px) == (5120, 3840)
    g = CameraGeometry.from_rig(rig.cameras[0])
    assert g.L_mm == 1000.0  # L = Lc1 - Lc2 (the paper's Lc1 + Lc2 is 0 with Table 2's signed values)
    assert rig.study.monte_carlo_runs == 1200 and rig.orbit.measurements == 19


def _mut(path, value):
    d = copy.deepcopy(BASE)
    cur = d
    for k in path[:-1]:
        cur = cur[k]
    cur[path[-1]] = value
    return d


@pytest.mark.parametrize("path,value,expect", [
    (("cameras", 0, "focal_length_mm"), -5.0, ["cameras[0].focal_length_mm", "-5.0", "≥ 100"]),
    (("cameras", 1, "telecentric_factor"), 0.0, ["cameras[1].telecentric_factor", "0.0", "≥ 0.05"]),
    (("cameras", 0, "m1_center_y_mm"), -600.0, ["m1_center_y_mm", "greater than m2_center_y_mm"]),
    (("cameras", 0, "m2_center_y_mm"), 480.0, ["overlap"]),
    (("laser", "core_radius_um"), 1e4, ["laser.core_radius_um", "10000.0", "≤ 500"]),
    (("orbit", "measurements"), 1, ["orbit.measurements", "≥ 3"]),
    (("detector", "quantum_efficiency"), 1.5, ["detector.quantum_efficiency", "1.5"]),
    (("cameras", 0, "m1_reference_px"), [3000.0, 0.0], ["m1_reference_px", "edge"]),
])
def test_bad_values_name_field_value_and_range(path, value, expect):
    with pytest.raises(RigError) as ei:
        parse_boresight_rig(_mut(path, value), "scenes/x.toml")
    msg = str(ei.value)
    assert msg.startswith("scenes/x.toml: invalid rig file")
    for s in expect:
        assert s in msg, (s, msg)


def test_unknown_key_lists_allowed_keys():
    d = _mut(("laser", "wavelength_nm"), 633.0)
    with pytest.raises(RigError) as ei:
        parse_boresight_rig(d, "f.toml")
    assert "unknown key `laser.wavelength_nm`" in str(ei.value) and "core_radius_um" in str(ei.value)


def test_wrong_document_and_missing_file(tmp_path):
    p = tmp_path / "r.toml"
    p.write_text((SCENES_DIR / "sun_sensor_2axis_diaphragm.toml").read_text())
    with pytest.raises(RigError, match="not a seed-003 rig"):
        load_boresight_rig(p)
    with pytest.raises(RigError, match="no such rig file"):
        load_boresight_rig("no_such_rig")
