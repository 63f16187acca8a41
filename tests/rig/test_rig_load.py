import copy
import tomllib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rigsim.errors import RigError
from rigsim.rig import default_rigs, load_rig, parse_rig
from rigsim.rig.cube_mirror import CubeMirrorRig

SCENES = Path(__file__).resolve().parents[2] / "scenes"
BASE = tomllib.loads((SCENES / "sun_sensor_2axis_diaphragm.toml").read_text())
BASE3 = tomllib.loads((SCENES / "sun_sensor_3axis_autocollimator.toml").read_text())


def test_default_rigs_load():
    names = {p.stem for p in default_rigs()}
    assert {"sun_sensor_2axis_diaphragm", "sun_sensor_3axis_autocollimator"} <= names
    r0 = load_rig("sun_sensor_2axis_diaphragm")
    r1 = load_rig(SCENES / "sun_sensor_3axis_autocollimator.toml")
    assert r0.seed_document == "000" and r0.turntable.kind == "2-axis"
    assert r0.diaphragm_screen.hole_diameter_mm == 2.5 and r0.diaphragm_screen.distance_to_cube_mm == 650.0
    assert r1.autocollimator.resolution_arcsec == 0.1 and r1.sun_simulator.collimation_full_angle_arcmin == 32.0
    assert [a.label for a in r1.turntable.axes] == ["Y", "X", "Z"]


def _mutate(base, path, value):
    d = copy.deepcopy(base)
    cur = d
    for k in path[:-1]:
        cur = cur[k]
    if value is _DELETE:
        del cur[path[-1]]
    else:
        cur[path[-1]] = value
    return d


_DELETE = object()

BAD = [
    # (data, expected substrings in the message)
    (_mutate(BASE, ["turntable", "wobble"], 1.0), ["unknown key", "turntable.wobble", "allowed keys"]),
    (_mutate(BASE, ["sun_sensor", "pixel_pitch_um"], "eleven"), ["sun_sensor.pixel_pitch_um", "'eleven'", "number"]),
    (_mutate(BASE, ["sun_sensor", "pixel_pitch_um"], -11.0), ["sun_sensor.pixel_pitch_um", "-11.0", "> 0"]),
    (_mutate(BASE, ["cube", "edge_mm"], 0.0), ["cube.edge_mm", "0.0", "> 0"]),
    (_mutate(BASE, ["diaphragm_screen", "width_mm"], 2.0), ["diaphragm_screen", "hole_diameter_mm = 2.5", "smaller than the screen", "2.0"]),
    (_mutate(BASE, ["cube", "R_cube_from_sun", "euler_deg"], [0.0, 400.0, 0.0]), ["cube.R_cube_from_sun.euler_deg[1]", "400", "360"]),
    (_mutate(BASE, ["cube", "R_cube_from_sun", "euler_seq"], "xxy"), ["euler_seq", "'xxy'", "Euler sequence"]),
    (_mutate(BASE, ["turntable", "axes", 1, "encoder_sigma_arcsec"], -0.4), ["turntable.axes[1].encoder_sigma_arcsec", "-0.4", "≥ 0"]),
    (_mutate(BASE, ["turntable", "axes", 1, "label"], "W"), ["turntable.axes[1].label", "'W'", "'X'"]),
    (_mutate(BASE, ["turntable", "kind"], "3-axis"), ["3-axis", "exactly 3"]),
    (_mutate(BASE, ["aiming_camera", "view_angle_deg"], 95.0), ["aiming_camera.view_angle_deg", "95", "< 80"]),
    (_mutate(BASE, ["sun_sensor", "principal_point_px"], [2000.0, 10.0]), ["principal_point_px", "must lie on the detector"]),
    (_mutate(BASE, ["aiming_camera"], _DELETE), ["aiming_camera", "needs"]),
    (_mutate(BASE, ["procedure", "faces"], ["+Z", "-Z"]), ["table `[procedure]`", "non-parallel", "+Z"]),
    (_mutate(BASE, ["procedure", "nominal_poses_deg"], [{"X": 180.0, "Q": 0.0}, {"X": 90.0}]), ["nominal_poses_deg[0]", "'Q'"]),
    (_mutate(BASE, ["turntable", "axes", 0, "misalignment_arcsec"], [0.0, 0.0, 9000.0]), ["misalignment_arcsec[2]", "9000", "3600"]),
    (_mutate(BASE3, ["plane_mirror", "perpendicularity_spec_arcsec"], -10.0), ["plane_mirror.perpendicularity_spec_arcsec", "-10.0", "≥ 0"]),
    (_mutate(BASE, ["sun_sensor", "resolution_px"], [1024]), ["sun_sensor.resolution_px", "at least 2"]),
]


@pytest.mark.parametrize("data,expected", BAD, ids=[e[0] for _, e in BAD])
def test_bad_input_gets_one_clear_error(data, expected):
    with pytest.raises(RigError) as ei:
        parse_rig(data, "scenes/bad.toml")
    msg = str(ei.value)
    assert msg.startswith("scenes/bad.toml: invalid rig file")
    for piece in expected:
        assert piece in msg, f"{piece!r} not in {msg!r}"
    assert "Traceback" not in msg and "pydantic" not in msg.lower()
    assert ei.value.__cause__ is None  # no chained traceback from deep inside


def test_file_level_errors(tmp_path):
    p = tmp_path / "broken.toml"
    p.write_text("name = \n")
    with pytest.raises(RigError, match="broken.toml.*TOML syntax error"):
        load_rig(p)
    with pytest.raises(RigError, match="no such rig file.*sun_sensor_2axis_diaphragm"):
        load_rig(tmp_path / "missing.toml")
    p.write_bytes(b"\xff\xfe")
    with pytest.raises(RigError, match="not UTF-8"):
        load_rig(p)


def test_rig_is_immutable():
    r = load_rig("sun_sensor_2axis_diaphragm")
    with pytest.raises(Exception):
        r.cube.edge_mm = 3.0


_leaf_values = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8), st.lists(st.floats(-1e4, 1e4), max_size=4), st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
)


def _paths(d, prefix=()):
    if isinstance(d, dict):
        for k, v in d.items():
            yield prefix + (k,)
            yield from _paths(v, prefix + (k,))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            yield prefix + (i,)
            yield from _paths(v, prefix + (i,))


ALL_PATHS = list(_paths(BASE))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.sampled_from(ALL_PATHS), _leaf_values), min_size=1, max_size=4))
def test_fuzz_loader_only_ever_returns_a_rig_or_a_rig_error(mutations):
    data = copy.deepcopy(BASE)
    for path, value in mutations:
        cur = data
        try:
            for k in path[:-1]:
                cur = cur[k]
            cur[path[-1]] = value
        except (KeyError, IndexError, TypeError):
            continue
    try:
        rig = parse_rig(data, "fuzz.toml")
    except RigError as exc:
        msg = str(exc)
        assert msg.startswith("fuzz.toml: invalid rig file") and len(exc.problems) >= 1
        assert all(("`" in p) or p.startswith("in the rig: ") for p in exc.problems), msg
    else:
        assert isinstance(rig, CubeMirrorRig)


def test_rig_families_dispatch_and_refuse_clearly():
    from rigsim.rig.load import load_any_rig

    assert load_any_rig("star_sensor").seed_document == "004"
    assert isinstance(load_any_rig("sun_sensor_2axis_diaphragm"), CubeMirrorRig)
    with pytest.raises(RigError, match="seed_document` = '004': this command needs a turntable/cube-mirror rig"):
        load_rig("star_sensor")
