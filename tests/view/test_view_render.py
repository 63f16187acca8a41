"""rigsim.view pictures off screen (EGL here), exports, and the drawn beams in the plotter."""

import numpy as np
import pytest

pytest.importorskip("pyvista")

from rigsim.view import ViewError, build_scene, export_scene, rig_picture
from rigsim.view.plot import html_available, make_plotter

RIG000 = "sun_sensor_2axis_diaphragm"


@pytest.fixture(scope="module")
def scene000():
    return build_scene(RIG000)


def _display_xy(renderer, p):
    renderer.SetWorldPoint(float(p[0]), float(p[1]), float(p[2]), 1.0)
    renderer.WorldToDisplay()
    x, y, _ = renderer.GetDisplayPoint()
    return x, y


def test_screenshot_off_screen_is_not_blank_and_shows_the_cube(scene000):
    from rigsim.view.display import render_window_class

    w, h = 720, 480
    pl = make_plotter(scene000, off_screen=True, size=(w, h))
    try:
        img = pl.screenshot(return_img=True)
        assert render_window_class(pl) in ("vtkEGLRenderWindow", "vtkXOpenGLRenderWindow", "vtkOSOpenGLRenderWindow",
                                           "vtkCocoaRenderWindow", "vtkWin32OpenGLRenderWindow")
        assert img.shape == (h, w, 3)
        # not blank: many distinct colours, real contrast
        flat = img.reshape(-1, 3).astype(int)
        assert len(np.unique(flat[::7], axis=0)) > 200
        assert img.std() > 20
        # the cube's centre, projected through the close-up's camera, is not background
        pl.subplot(1, 0)
        ren = pl.renderer
        c = np.asarray(scene000.item("cube").mesh.points).mean(0)
        x, y = _display_xy(ren, c)
        row, col = int(round(h - 1 - y)), int(round(x))
        vp = ren.GetViewport()
        assert vp[0] * w <= col < vp[2] * w and (1 - vp[3]) * h <= row < (1 - vp[1]) * h
        patch = img[row - 2:row + 3, col - 2:col + 3].reshape(-1, 3).astype(float)
        bg = img[int((1 - vp[1]) * h) - 3, int(vp[0] * w) + 3].astype(float)  # a corner of that viewport
        assert np.min(np.abs(patch - bg).sum(axis=1)) > 40, (patch, bg)
        # the return spot is drawn where the trace puts it, in the screen close-up
        pl.subplot(1, 1)
        x, y = _display_xy(pl.renderer, scene000.info["spot_mm"])
        px = img[int(round(h - 1 - y)), int(round(x))].astype(int)
        assert px[0] > px[1] + 60 and px[0] > px[2]  # crimson
    finally:
        pl.close()


def test_drawn_beam_actors_hold_the_traced_points(scene000):
    pl = make_plotter(scene000, off_screen=True, size=(400, 300), views=["overview"], labels=False)
    try:
        for name in ("beam:incident", "beam:reflected"):
            from vtkmodules.util.numpy_support import vtk_to_numpy

            actor = pl.renderer.actors[name]
            pts = vtk_to_numpy(actor.GetMapper().GetInput().GetPoints().GetData())
            assert pts.dtype == np.float64
            np.testing.assert_allclose(pts, scene000.beam(name.split(":")[1]).points, rtol=0, atol=1e-9)
    finally:
        pl.close()


def test_rig_picture_writes_a_png(tmp_path):
    out = rig_picture("star_sensor", tmp_path / "star.png", size=(480, 320))
    assert out.exists() and out.stat().st_size > 10_000
    import cv2

    img = cv2.imread(str(out))
    assert img.shape == (320, 480, 3) and img.std() > 15
    with pytest.raises(ViewError, match="must be a .png"):
        rig_picture("star_sensor", tmp_path / "star.jpg")
    with pytest.raises(ViewError, match="64 to 8192"):
        rig_picture("star_sensor", tmp_path / "s.png", size=(10, 10))


@pytest.mark.parametrize("suffix", [".gltf", ".vtkjs", ".vtm"])
def test_exports_write_files(scene000, tmp_path, suffix):
    out = export_scene(scene000, tmp_path / f"rig{suffix}")
    assert out.exists() and out.stat().st_size > (100 if suffix == ".vtm" else 10_000)
    if suffix == ".gltf":
        import json

        d = json.loads(out.read_text())
        assert d["asset"]["version"] == "2.0" and len(d["meshes"]) == len(scene000.items)
        assert all(b["uri"].startswith("data:") for b in d["buffers"])  # self-contained
    if suffix == ".vtkjs":
        import zipfile

        assert "scene/index.json" in zipfile.ZipFile(out).namelist()
    if suffix == ".vtm":
        import pyvista as pv

        mb = pv.read(out)
        assert set(mb.keys()) == set(scene000.item_names)
        np.testing.assert_allclose(mb["beam:incident"].points, scene000.beam("incident").points, atol=1e-9)


def test_html_export_says_what_is_missing(scene000, tmp_path):
    if html_available():
        out = export_scene(scene000, tmp_path / "rig.html")
        assert out.exists()
        return
    with pytest.raises(ViewError, match="trame-pyvista.*--export FILE.gltf|trame-pyvista.*gltf"):
        export_scene(scene000, tmp_path / "rig.html")
    with pytest.raises(ViewError, match=r"allowed suffixes are \.gltf"):
        export_scene(scene000, tmp_path / "rig.obj")


@pytest.mark.parametrize("rig", ["sun_sensor_2axis_diaphragm", "sun_sensor_3axis_autocollimator", "star_sensor",
                                 "dual_line_array_prism"])
def test_every_default_rig_renders_full_size(rig, tmp_path):
    out = rig_picture(rig, tmp_path / "rig.png", size=(1200, 800))
    import cv2

    img = cv2.imread(str(out))
    assert img.shape == (800, 1200, 3) and img.std() > 15
