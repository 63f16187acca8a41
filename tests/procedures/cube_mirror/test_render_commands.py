"""`rigsim render aiming-camera` and `rigsim render autocollimator`: the frames the campaign renders,
written with their truth; what the file stages measure on them agrees with that truth."""

import json

import numpy as np
import pytest

from rigsim.cli import main
from rigsim.files import read_image


@pytest.mark.render
def test_render_aiming_camera_and_autocollimator(tmp_path, capsys):
    from rigsim.procedures.cube_mirror.null_files import measure_concentricity, read_autocollimator
    from rigsim.rig.load import load_rig

    assert main(["render", "aiming-camera", "--pose", "X=181.398,Y=0.528", "--out", str(tmp_path), "--spp", "4"]) == 0
    hole, spot = read_image(tmp_path / "aiming_camera_hole.png"), read_image(tmp_path / "aiming_camera_spot.png")
    side = json.loads((tmp_path / "aiming_camera_spot.json").read_text())
    rig = load_rig("sun_sensor_2axis_diaphragm")
    exact = np.asarray(side["truth"]["offset_mm"]) / rig.aiming_camera.object_pixel_mm
    m = measure_concentricity(rig, hole, spot)
    assert hole.shape == (1200, 1600) and np.hypot(*(m["offset_px"] - exact)) < 0.2  # rendered vs exact, px

    assert main(["render", "autocollimator", "--out", str(tmp_path), "--spp", "64"]) == 0
    out = capsys.readouterr().out
    rig = load_rig("sun_sensor_3axis_autocollimator")
    r, sig, sm = read_autocollimator(rig, read_image(tmp_path / "autocollimator.png"))
    ex = [float(x.rstrip("″,")) for x in out.split("exact reading: θx ")[1].split()[0:3:2]]
    assert sm.ok and np.all(np.abs(r - ex) < 0.2)  # arcsec: rendered + centroided vs the exact reflection


@pytest.mark.render
def test_render_aiming_camera_collimated_beam(tmp_path):
    """--beam collimated: one pencil (167 px across on the screen). Clear of the hole (215 px away) the
    measured offset is the exact one (measured 0.01 px), and the lit disk is the pencil's size."""
    from rigsim.procedures.cube_mirror.null_files import measure_concentricity
    from rigsim.rig.load import load_rig

    assert main(["render", "aiming-camera", "--beam", "collimated", "--pose", "X=181.54,Y=0.528", "--noiseless",
                 "--out", str(tmp_path), "--spp", "4"]) == 0
    hole, spot = read_image(tmp_path / "aiming_camera_hole.png"), read_image(tmp_path / "aiming_camera_spot.png")
    side = json.loads((tmp_path / "aiming_camera_spot.json").read_text())
    rig = load_rig("sun_sensor_2axis_diaphragm")
    exact = np.asarray(side["truth"]["offset_mm"]) / rig.aiming_camera.object_pixel_mm
    m = measure_concentricity(rig, hole, spot)
    assert np.hypot(*(m["offset_px"] - exact)) < 0.1 and np.hypot(*exact) > 200
    lit = (spot.astype(float) - hole) > 0.5 * (spot.max() - np.median(spot))
    assert abs(2 * np.sqrt(lit.sum() / np.pi) - 2.5 / 0.015) < 10  # the 2.5 mm pencil on 15 µm object pixels


def test_wrong_rig_family_is_one_line(capsys):
    assert main(["render", "aiming-camera", "--rig", "sun_sensor_3axis_autocollimator"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "this frame needs the diaphragm (seed 000)" in err
    assert main(["render", "autocollimator", "--face", "+Q"]) == 2
    assert "--face = '+Q': the procedure's faces are +Z, +Y" in capsys.readouterr().err
