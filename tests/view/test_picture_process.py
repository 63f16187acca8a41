"""The rig picture rendered in a child process (rigsim.view.picture_process): the same picture as in
this process, and a failure comes back as one line, never as an exception or a traceback."""

import numpy as np
import pytest

pytest.importorskip("pyvista")

from rigsim.rig import load_rig
from rigsim.view import rig_picture
from rigsim.view.picture_process import picture_in_child

RIG000 = load_rig("sun_sensor_2axis_diaphragm")


def _pixels(path):
    import matplotlib.image as mpimg

    return np.asarray(mpimg.imread(str(path)))


def test_child_writes_the_same_picture_as_this_process(tmp_path):
    here = rig_picture(RIG000, tmp_path / "here.png", pose_deg="null", size=(480, 320))
    there, why = picture_in_child(RIG000, tmp_path / "child.png", pose_deg="null", size=(480, 320))
    assert why == "" and there == tmp_path / "child.png"
    a, b = _pixels(here), _pixels(there)
    assert a.shape == b.shape == (320, 480, 3)
    assert a.std() > 0.05  # a picture, not a blank frame
    # the same scene, pose and OpenGL: identical pixels
    assert np.array_equal(a, b), float(np.abs(a - b).max())


def test_child_takes_a_pose_in_degrees(tmp_path):
    pose = {"X": 181.0, "Y": 0.5}
    there, why = picture_in_child(RIG000, tmp_path / "p.png", pose_deg=pose, size=(320, 240))
    assert why == "" and there.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("name, size", [("rig.jpg", (480, 320)), ("rig.png", (10, 10))])
def test_a_failure_in_the_child_is_one_line(tmp_path, name, size):
    path, why = picture_in_child(RIG000, tmp_path / name, pose_deg="null", size=size)
    assert path is None
    assert why.startswith("ViewError: ") and "\n" not in why and "Traceback" not in why, why
    assert not (tmp_path / name).exists()


def test_a_child_that_cannot_start_is_one_line(tmp_path, monkeypatch):
    import sys

    monkeypatch.setattr(sys, "executable", str(tmp_path / "no-python"))
    path, why = picture_in_child(RIG000, tmp_path / "rig.png", pose_deg="null", size=(480, 320))
    assert path is None and "cannot start the picture process" in why and "\n" not in why
