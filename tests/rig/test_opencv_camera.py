"""An OpenCV camera (cv2.FileStorage) pasted into a rig: rigsim's own OpenCV export of a rig's camera, read back
into another rig, gives the same camera matrix and distortion; bad files are one line."""

import numpy as np
import pytest

from rigsim import cli
from rigsim.rig.load import load_any_rig, load_rig, load_star_rig


def _write(path, K, D, size=(1024, 1024)):
    import cv2

    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", size[0])
    fs.write("image_height", size[1])
    fs.write("camera_matrix", np.asarray(K, float))
    fs.write("distortion_coefficients", np.asarray(D, float).reshape(1, -1))
    fs.release()
    return path


@pytest.mark.parametrize("suffix", [".yml", ".json", ".xml"])
def test_a_rigs_camera_round_trips_through_opencv_filestorage(tmp_path, suffix):
    from rigsim.procedures.cube_mirror.files import write_opencv_camera

    rig = load_rig("sun_sensor_3axis_autocollimator")
    cam = rig.sun_sensor.camera()
    f = write_opencv_camera(tmp_path / f"cam{suffix}", cam)
    out = tmp_path / "new.toml"
    assert cli.main(["rig", "import-camera", str(f), "--rig", "sun_sensor_2axis_diaphragm", "--out", str(out)]) == 0
    new = load_any_rig(out).sun_sensor
    # the diaphragm rig's pitch (11 µm) differs from the autocollimator rig's: the mm focal length follows it,
    # the pixel camera is the same
    got = new.camera()
    for k in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "width", "height"):
        assert getattr(got, k) == pytest.approx(getattr(cam, k), rel=1e-9, abs=1e-12), k
    assert new.focal_length_mm == pytest.approx(cam.fx * new.pixel_pitch_um * 1e-3, rel=1e-9)
    assert "# " in out.read_text()  # the rig file's comments are kept


def test_a_star_sensor_takes_a_square_pixel_camera_and_refuses_fy_not_fx(tmp_path, capsys):
    star = load_star_rig().sensor
    K = [[2900.0, 0, 515.0], [0, 2900.0, 507.5], [0, 0, 1]]
    f = _write(tmp_path / "c.yml", K, [-0.05, 0.08, 0.0, 0.0])
    out = tmp_path / "s.toml"
    assert cli.main(["rig", "import-camera", str(f), "--rig", "star_sensor", "--out", str(out)]) == 0
    new = load_any_rig(out).sensor
    assert new.f_px == pytest.approx(2900.0) and new.k1 == -0.05 and new.principal_point_px == [515.0, 507.5]
    assert new.pixel_pitch_um == star.pixel_pitch_um
    f2 = _write(tmp_path / "c2.yml", [[2900.0, 0, 515.0], [0, 2910.0, 507.5], [0, 0, 1]], [0, 0, 0, 0])
    capsys.readouterr()
    assert cli.main(["rig", "import-camera", str(f2), "--rig", "star_sensor", "--out", str(tmp_path / "t.toml")]) == 2
    err = capsys.readouterr().err
    assert "fy/fx = 1.003448276" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "t.toml").exists()


@pytest.mark.parametrize("content,msg", [
    (None, "k4 = 0.01: rigsim's camera has k1, k2, p1, p2, k3 only"),
    ("%YAML:1.0\n---\nfoo: 1\n", "no camera matrix"),
    ("garbage: [", "not an OpenCV FileStorage file"),
    (b"\xff\xfe\x00", "not UTF-8 text"),
    ("%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 2\n   cols: 2\n   dt: d\n   data: [1., 0., 0., 1.]\n",
     "expected a finite 3×3 matrix"),
])
def test_bad_camera_files_are_one_line_and_write_nothing(tmp_path, capsys, content, msg):
    f = tmp_path / "c.yml"
    if content is None:
        _write(f, [[275.0, 0, 511.5], [0, 275.0, 511.5], [0, 0, 1]], [-0.02, 0.001, 0, 0, 0, 0.01, 0, 0])
    elif isinstance(content, bytes):
        f.write_bytes(content)
    else:
        f.write_text(content)
    rc = cli.main(["rig", "import-camera", str(f), "--out", str(tmp_path / "n.toml")])
    err = capsys.readouterr().err
    assert rc == 2 and msg in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "n.toml").exists()


def test_a_camera_that_breaks_the_rigs_geometry_is_refused(tmp_path, capsys):
    """f = 40 px on a ±60° sweep: the sun image is under 2 px, refused as `rig check` would."""
    f = _write(tmp_path / "c.yml", [[40.0, 0, 511.5], [0, 40.0, 511.5], [0, 0, 1]], [0, 0, 0, 0, 0])
    rc = cli.main(["rig", "import-camera", str(f), "--out", str(tmp_path / "n.toml")])
    err = capsys.readouterr().err
    assert rc == 2 and "sun_sensor" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "n.toml").exists()


def test_a_star_camera_goes_into_sensor_and_nominal_and_rig_check_agrees(tmp_path, capsys):
    """A calibration of a 1024×768 camera of 6.9 µm pixels into the 20° sensor's rig (1024² of 15 µm): [sensor]
    and [nominal] both take it (before, [nominal] kept f = 2889.7 px against the camera's 5119.3 px and
    `rig check` said nothing); the output names what changed and what it left."""
    K = [[5119.3, 0, 515.2], [0, 5119.3, 381.9], [0, 0, 1]]
    f = _write(tmp_path / "c.yml", K, [-0.12, 0.5, 0.0, 0.0], size=(1024, 768))
    out = tmp_path / "s.toml"
    capsys.readouterr()
    assert cli.main(["rig", "import-camera", str(f), "--rig", "star_sensor", "--out", str(out), "--pixel-pitch-um", "6.9"]) == 0
    printed = capsys.readouterr().out
    rig = load_star_rig(out)
    s, n = rig.sensor, rig.nominal
    assert s.resolution_px == [1024, 768] and s.pixel_pitch_um == 6.9 and s.f_px == pytest.approx(5119.3, rel=1e-9)
    assert n.focal_length_mm * 1000 / 6.9 == pytest.approx(5119.3, rel=1e-9)
    assert n.principal_point_px == s.principal_point_px == [515.2, 381.9]
    assert (n.k1, n.k2, n.p1, n.p2) == (s.k1, s.k2, s.p1, s.p2) == (-0.12, 0.5, 0.0, 0.0)
    assert "nominal.focal_length_mm: 43.345 → 35.32317" in printed and "nominal.principal_point_px" in printed
    left = printed.partition("left as it was:")[2]
    assert "sensor.detector: 12-bit ADC, offset 100" in left and "focal_length_sigma_px 10 px" in left
    assert "now f/1.77" in left                                  # 35.32 mm behind the rig's Ø 20 mm aperture
    assert cli.main(["rig", "check", str(out)]) == 0
    assert not any(ln.startswith("!") for ln in capsys.readouterr().out.splitlines())


def test_a_star_rig_without_nominal_gets_one_and_a_new_image_size_needs_the_pitch(tmp_path, capsys):
    from rigsim.rig.load import SCENES_DIR

    text = (SCENES_DIR / "star_sensor.toml").read_text()
    head, _, tail = text.partition("\n[nominal]")
    src = tmp_path / "design.toml"
    src.write_text(head + "\n[sky]" + tail.partition("\n[sky]")[2])
    assert load_star_rig(src).nominal is None
    f = _write(tmp_path / "c.yml", [[2900.0, 0, 515.0], [0, 2900.0, 507.5], [0, 0, 1]], [-0.05, 0.08, 0.0, 0.0])
    out = tmp_path / "s.toml"
    assert cli.main(["rig", "import-camera", str(f), "--rig", str(src), "--out", str(out)]) == 0
    n = load_star_rig(out).nominal
    assert n is not None and n.focal_length_mm * 1000 / 15.0 == pytest.approx(2900.0) and n.principal_point_px == [515.0, 507.5]
    assert (n.k1, n.k2) == (-0.05, 0.08) and "nominal: a new table" in capsys.readouterr().out
    g = _write(tmp_path / "g.yml", [[2900.0, 0, 515.0], [0, 2900.0, 383.0], [0, 0, 1]], [0, 0, 0, 0], size=(1024, 768))
    assert cli.main(["rig", "import-camera", str(g), "--rig", "star_sensor", "--out", str(tmp_path / "t.toml")]) == 2
    err = capsys.readouterr().err
    assert "1024×768 px, the rig's sensor 1024×1024 px: give --pixel-pitch-um" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "t.toml").exists()
