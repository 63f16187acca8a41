"""Lab-frame geometry of the diaphragm rig: exact trace vs the 2·tilt·distance closed form."""

import numpy as np
import pytest

from rigsim.frames import from_arcsec
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.placement import diaphragm_layout, face_in_rot, trace_return_spot
from rigsim.truth.cube_mirror.realization import realization_from_rig

RIG = load_rig("sun_sensor_2axis_diaphragm")
REAL = realization_from_rig(RIG, ideal=True)


def test_null_pose_returns_the_spot_into_the_hole():
    lay = diaphragm_layout(RIG, REAL, 0)
    sp = trace_return_spot(RIG, REAL, lay, lay.null_pose_rad)
    assert sp.on_face
    np.testing.assert_allclose(sp.offset_mm, 0.0, atol=1e-9)
    c, n = face_in_rot(RIG, REAL, "+Z", lay.null_pose_rad)
    np.testing.assert_allclose(n, [0, 0, 1], atol=1e-12)
    assert lay.z_screen_mm - c[2] == pytest.approx(650.0)


@pytest.mark.parametrize("axis", ["X", "Y"])
@pytest.mark.parametrize("tilt_arcsec", [2.0, 30.0, 300.0])
def test_offset_is_two_tilt_times_distance(axis, tilt_arcsec):
    lay = diaphragm_layout(RIG, REAL, 0)
    pose = dict(lay.null_pose_rad)
    pose[axis] += from_arcsec(tilt_arcsec)
    sp = trace_return_spot(RIG, REAL, lay, pose)
    # closed form for a small tilt t: the return beam is deviated by 2t over the face→screen path
    # (650 mm plus the few µm the face moves along the beam); exact up to O(t²)·L
    path = lay.z_screen_mm - sp.hit_on_face_mm[2]
    expected = np.tan(2 * sp.tilt_rad) * path
    assert np.linalg.norm(sp.offset_mm) == pytest.approx(expected, rel=1e-6, abs=1e-9)
    assert sp.tilt_rad == pytest.approx(from_arcsec(tilt_arcsec), rel=1e-3)
    # a 1-px (15 µm) offset is a 2.38″ tilt (σ1)
    assert np.linalg.norm(sp.offset_mm) / (2 * 650.0) == pytest.approx(from_arcsec(tilt_arcsec), rel=2e-3)


def test_beam_missing_the_face_is_reported():
    lay = diaphragm_layout(RIG, REAL, 0)
    pose = dict(lay.null_pose_rad)
    pose["X"] += np.radians(10.0)  # the face swings 10° away: the pencil misses the 25 mm face
    sp = trace_return_spot(RIG, REAL, lay, pose)
    assert not sp.on_face
