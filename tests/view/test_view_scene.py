"""rigsim.view scenes: expected content, beams equal to the analytic traces, pose/face handling.

No rendering here (scenes are meshes and numbers); see test_view_render.py for pictures.
"""

import math

import numpy as np
import pytest

pytest.importorskip("pyvista")

from rigsim.optics.autocollimator import AutocollimatorOptics
from rigsim.optics.cube import reflect
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.autocollimator import autocollimator_layout, mirror_target
from rigsim.truth.cube_mirror.placement import diaphragm_layout, face_in_rot, trace_return_spot
from rigsim.truth.cube_mirror.realization import realization_from_rig
from rigsim.view import ViewError, build_scene
from rigsim.view.cube_mirror import resolve_pose_deg

RIG000 = "sun_sensor_2axis_diaphragm"
RIG001 = "sun_sensor_3axis_autocollimator"
TOL_MM = 1e-9


@pytest.fixture(scope="module")
def rig000():
    return load_rig(RIG000)


@pytest.fixture(scope="module")
def rig001():
    return load_rig(RIG001)


@pytest.fixture(scope="module")
def scene000(rig000):
    return build_scene(rig000)


@pytest.fixture(scope="module")
def scene001(rig001):
    return build_scene(rig001)


def _rad(pose_deg):
    return {k: math.radians(v) for k, v in pose_deg.items()}


# ------------------------------------------------------------------------------ content

def test_seed000_scene_has_every_part(scene000):
    names = set(scene000.item_names)
    expected = {
        "turntable:outer_ring", "turntable:inner_ring", "turntable:outer_axis", "turntable:inner_axis",
        "sensor:body", "sensor:frame:z", "cube", "screen", "screen:hole_rim", "screen:spot",
        "sun_simulator:housing", "aiming_camera:body", "aiming_camera:field", "beam:incident", "beam:reflected",
        "rot_frame:x", "rot_frame:y", "rot_frame:z",
    } | {f"cube:normal{f}" for f in ("+X", "-X", "+Y", "-Y", "+Z", "-Z")}
    assert expected <= names, expected - names
    assert [v.name for v in scene000.views] == ["overview", "cube", "screen"]
    texts = " | ".join(lab.text for lab in scene000.labels)
    for word in ("outer axis X'", "inner axis Y'", "mirror cube", "diaphragm screen", "aiming camera", "sun simulator",
                 "hole", "n +Z (XY face)"):
        assert word in texts
    # the cube is the renderer's own mesh, at cube_pose: its centre is the cube centre at this pose
    cube = scene000.item("cube").mesh
    pose = _rad(scene000.pose_deg)
    real = realization_from_rig(load_rig(RIG000))
    from rigsim.truth.cube_mirror.placement import cube_pose

    assert np.allclose(np.asarray(cube.points).mean(0), cube_pose(load_rig(RIG000), real, pose).t, atol=0.05)


def test_seed001_scene_has_every_part(scene001):
    names = set(scene001.item_names)
    expected = {"turntable:outer_ring", "turntable:middle_ring", "turntable:inner_ring", "sensor:body", "cube",
                "autocollimator:objective", "autocollimator:detector", "autocollimator:housing", "plane_mirror",
                "sun_simulator:housing", "beam:incident", "beam:reflected"}
    assert expected <= names, expected - names
    assert [v.name for v in scene001.views] == ["overview", "cube", "detector"]


def test_star_and_boresight_scenes():
    star = build_scene("star_sensor")
    assert {"sensor:detector", "fov:outline", "stars:all"} <= set(star.item_names)
    assert len(star.beams) == 6 and all(b.name.startswith("star_HIP") for b in star.beams)
    bs = build_scene("dual_line_array_prism")
    names = set(bs.item_names)
    assert {"forward:M1", "forward:M2", "backward:M1", "prism:body", "prism:facet_forward_1"} <= names
    assert len(bs.beams) == 8


# ------------------------------------------------------------------------------ beams = analytic trace

def test_seed000_beams_equal_trace_return_spot(rig000, scene000):
    real = realization_from_rig(rig000)
    lay = diaphragm_layout(rig000, real, 0)
    sp = trace_return_spot(rig000, real, lay, _rad(scene000.pose_deg))
    inc = np.asarray(scene000.item("beam:incident").mesh.points, float)
    refl = np.asarray(scene000.item("beam:reflected").mesh.points, float)
    np.testing.assert_allclose(inc, np.vstack([lay.simulator_exit_mm, lay.hole_centre_mm, sp.hit_on_face_mm]),
                               rtol=0, atol=TOL_MM)
    np.testing.assert_allclose(refl, np.vstack([sp.hit_on_face_mm, sp.spot_mm]), rtol=0, atol=TOL_MM)
    assert inc.dtype == np.float64
    # and the physics: the hit is on the face plane, the reflection law holds about the true normal
    centre, n = face_in_rot(rig000, real, "+Z", _rad(scene000.pose_deg))
    assert abs((inc[2] - centre) @ n) < 1e-9
    d_in = (inc[2] - inc[1]) / np.linalg.norm(inc[2] - inc[1])
    d_out = (refl[1] - refl[0]) / np.linalg.norm(refl[1] - refl[0])
    np.testing.assert_allclose(d_out, reflect(d_in, n), atol=1e-12)


def test_seed000_null_pose_returns_onto_the_hole(rig000):
    sc = build_scene(rig000, pose="null", face="+Y")
    refl = np.asarray(sc.item("beam:reflected").mesh.points)
    assert np.linalg.norm(refl[-1] - sc.info["hole_centre_mm"]) < 1e-9
    assert sc.info["face"] == "+Y"


def test_seed001_beams_equal_the_autocollimator_trace(rig001, scene001):
    real = realization_from_rig(rig001)
    pose = _rad(scene001.pose_deg)
    lay = autocollimator_layout(rig001, real, "face", "+Z")
    opt = AutocollimatorOptics(rig001.autocollimator)
    m = mirror_target(rig001, real, lay, pose)
    inc = np.asarray(scene001.item("beam:incident").mesh.points, float)
    refl = np.asarray(scene001.item("beam:reflected").mesh.points, float)
    to_A = lay.to_A
    # the axial ray leaves the reticle along the axis and meets the mirror plane (A frame)
    np.testing.assert_allclose(to_A(inc[0]), opt.source_position, atol=TOL_MM)
    assert abs((to_A(inc[2]) - m.centre) @ m.normal) < TOL_MM
    assert bool(m.inside(to_A(inc[2])))
    # reflection law about the target's true normal
    d_in = to_A(inc[2]) - to_A(inc[1])
    d_out = to_A(refl[1]) - to_A(refl[0])
    np.testing.assert_allclose(d_out / np.linalg.norm(d_out), reflect(d_in / np.linalg.norm(d_in), m.normal), atol=1e-12)
    # the landing point is the exact return trace of that ray (AutocollimatorOptics._return)
    xy, _, ok = opt._return(to_A(inc[2])[None], (d_out / np.linalg.norm(d_out))[None])
    assert ok[0]
    np.testing.assert_allclose(to_A(refl[-1])[:2], xy[0], atol=TOL_MM)
    np.testing.assert_allclose(to_A(refl[-1])[2], opt.z_detector, atol=TOL_MM)
    # sanity: the spot offset is about 2·tilt·EFL
    tilt = np.hypot(*m.tilt_rad())
    assert np.hypot(*xy[0]) == pytest.approx(2 * tilt * opt.efl_mm, rel=0.05)


def test_star_beams_equal_the_field_truth():
    from rigsim.rig.load import load_star_rig
    from rigsim.truth.star import StarSky
    from rigsim.view.star import RAY_LENGTH_MM, first_attitude, image_point_mm

    rig = load_star_rig("star_sensor")
    sc = build_scene(rig)
    f = StarSky(rig).field(first_attitude(rig))
    for b in sc.beams:
        i = int(np.flatnonzero(f.hip == int(b.name.split("HIP")[1]))[0])
        pts = np.asarray(sc.item(f"beam:{b.name}").mesh.points)
        np.testing.assert_allclose(pts[0], RAY_LENGTH_MM * f.dirs_cam[i], atol=TOL_MM)
        np.testing.assert_allclose(pts[1], 0.0, atol=0)
        np.testing.assert_allclose(pts[2], image_point_mm(rig.sensor, f.uv[i]), atol=TOL_MM)


def test_boresight_loops_land_where_loop_trace_says():
    from rigsim.optics.line_camera import CameraGeometry, loop_trace
    from rigsim.view.api import load_view_rig
    from rigsim.view.boresight import camera_placement, laser_loops

    rig = load_view_rig("dual_line_array_prism")
    sc = build_scene(rig)
    for i, cam in enumerate(rig.cameras):
        g = CameraGeometry.from_rig(cam)
        R, O = camera_placement(g, i)
        land = loop_trace(g)
        for j in range(2):
            pts = np.asarray(sc.item(f"beam:{cam.name}_M{j + 1}_back").mesh.points)
            local = (pts - O) @ R
            np.testing.assert_allclose(local[-1, :2], land[j], atol=TOL_MM)
        # a perturbed camera: the returned beam lands where loop_trace says
        from rigsim.optics.line_camera import rotation_xyz

        E = rotation_xyz(*np.radians(np.array([10.0, -20.0, 30.0]) / 3600.0))
        go, back = laser_loops(g, E, 0.01)[0]
        np.testing.assert_allclose(back[-1, :2], loop_trace(g, E, 0.01)[0], atol=TOL_MM)


# ------------------------------------------------------------------------------ pose / face handling

def test_pose_keywords_and_overrides(rig000):
    real = realization_from_rig(rig000)
    p, kind = resolve_pose_deg(rig000, real, None, 0)
    assert p == {"X": 181.4, "Y": 0.55} and "start" in kind
    p, _ = resolve_pose_deg(rig000, real, "nominal", 1)
    assert p == {"X": 90.0, "Y": 0.0}
    p, _ = resolve_pose_deg(rig000, real, {"Y": "0.6"}, 0)
    assert p == {"X": 181.4, "Y": 0.6}
    p, _ = resolve_pose_deg(rig000, real, "null", 0)
    assert p["X"] == pytest.approx(181.398, abs=1e-3) and p["Y"] == pytest.approx(0.528, abs=1e-3)


@pytest.mark.parametrize("pose, words", [
    ({"X": "400"}, ["X = 400", "-360 to 360"]),
    ({"Q": 1.0}, ["axis 'Q'", "['X', 'Y']"]),
    ({"X": "abc"}, ["X = 'abc'", "not a number"]),
    ("upside-down", ["start, null, nominal"]),
])
def test_bad_pose_is_rejected_with_field_value_range(rig000, pose, words):
    with pytest.raises(ViewError) as ei:
        build_scene(rig000, pose=pose)
    for w in words:
        assert w in str(ei.value)


def test_bad_face_and_family_options(rig000):
    with pytest.raises(ViewError, match=r"--face = '\+X': allowed one of \['\+Z', '\+Y'\]"):
        build_scene(rig000, face="+X")
    with pytest.raises(ViewError, match="no turntable"):
        build_scene("star_sensor", pose={"X": 1})
    with pytest.raises(ViewError, match="no mirror cube"):
        build_scene("dual_line_array_prism", face="+Z")
