"""`rigsim scene export`: the XML renders with the plain mitsuba command, spot where expected."""

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rigsim.errors import ExportError
from rigsim.render.export import perspective_from_intrinsics, scene_dict_to_xml

MITSUBA = Path(sys.executable).with_name("mitsuba")


def test_xml_rejects_python_plugins():
    with pytest.raises(ExportError, match="rigsim_pinhole.*Python plugins"):
        scene_dict_to_xml({"type": "scene", "sensor": {"type": "rigsim_pinhole"}})


def test_principal_point_offsets_are_zero_at_the_film_centre():
    p = perspective_from_intrinsics(500.0, 500.0, 511.5, 383.5, 1024, 768)
    assert p["principal_point_offset_x"] == 0.0 and p["principal_point_offset_y"] == 0.0
    assert p["fov"] == pytest.approx(math.degrees(2 * math.atan(512 / 500)))


@pytest.mark.skipif(not MITSUBA.exists(), reason="no mitsuba command next to the interpreter")
def test_exported_sun_sensor_scene_renders_with_plain_mitsuba(tmp_path):
    r = subprocess.run([sys.executable, "-m", "rigsim.cli", "scene", "export", "sun_sensor_2axis_diaphragm",
                        "--xml", str(tmp_path), "--pose", "X=20,Y=-10", "--spp", "64"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    xml = tmp_path / "sun_sensor.xml"
    text = xml.read_text()
    m = re.search(r"u=([-\d.]+), v=([-\d.]+)", text)
    expected = np.array([float(m.group(1)), float(m.group(2))])
    out = tmp_path / "sun.exr"
    r = subprocess.run([str(MITSUBA), "-o", str(out), str(xml)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    import mitsuba as mi

    from rigsim.render.backend import ensure_variant

    ensure_variant()
    img = np.array(mi.Bitmap(str(out)), dtype=float)
    img = img[..., 0] if img.ndim == 3 else img
    v, u = np.indices(img.shape)
    c = np.array([(img * u).sum(), (img * v).sum()]) / img.sum()
    # independent sampler at 64 spp on a ~2.7 px disk (black elsewhere): each edge pixel's coverage is binomial,
    # sigma(centroid) ~ sqrt(17 edge px * 0.25 * 2.7^2/2 / 64) / (pi 2.7^2) ~ 0.02 px per axis, plus the disk's bias
    assert np.linalg.norm(c - expected) < 0.15


def test_nested_objects_with_equal_keys_export_and_load_back():
    xml = scene_dict_to_xml({
        "type": "scene",
        "a": {"type": "disk", "emitter": {"type": "area", "radiance": {"type": "uniform", "value": 1.0}}},
        "b": {"type": "disk", "emitter": {"type": "area", "radiance": {"type": "uniform", "value": 2.0}}},
    }, comments=["hello"])
    assert xml.startswith("<!-- hello -->")
    import mitsuba as mi

    scene = mi.load_string(xml[xml.index("<scene"):])
    assert len(scene.emitters()) == 2 and len(scene.shapes()) == 2


def test_every_default_rig_exports_scenes_that_load(tmp_path):
    import mitsuba as mi

    from rigsim.render.cube_mirror.export import export_rig
    from rigsim.rig import load_rig

    names = {}
    for rig_name in ("sun_sensor_2axis_diaphragm", "sun_sensor_3axis_autocollimator"):
        out = tmp_path / rig_name
        written = export_rig(load_rig(rig_name), out, spp=4)
        names[rig_name] = sorted(p.name for p in written)
        for p in written:
            scene = mi.load_file(str(p))  # meshes resolve relative to the XML
            assert len(scene.shapes()) >= 1
    assert names["sun_sensor_2axis_diaphragm"] == ["diaphragm_screen.xml", "sun_sensor.xml"]
    assert names["sun_sensor_3axis_autocollimator"] == ["autocollimator.xml", "sun_sensor.xml"]
