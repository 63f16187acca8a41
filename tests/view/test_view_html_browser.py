"""`rigsim view --html`: the interactive export (vtk.js, self-contained) renders in headless Chromium."""

import shutil
import subprocess
import sys

import numpy as np
import pytest

from rigsim.view.plot import html_available

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed (./dev test installs it)")
@pytest.mark.skipif(not html_available(), reason="trame-pyvista is not installed")
def test_html_export_draws_the_rig_in_a_browser(tmp_path):
    import cv2

    html = tmp_path / "rig.html"
    r = subprocess.run([sys.executable, "-m", "rigsim.cli", "view", "sun_sensor_2axis_diaphragm", "--html", str(html)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    text = html.read_text()
    assert "<script" in text and len(text) > 200_000  # vtk.js and the scene are inlined: works offline
    assert "<title>rigsim — sun-sensor-2axis-diaphragm (seed 000)" in text  # not vtk.js's "VTK.js | Example"
    dom = subprocess.run([CHROMIUM, "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                          "--enable-unsafe-swiftshader", "--virtual-time-budget=8000", "--dump-dom",
                          html.resolve().as_uri()], capture_output=True, text=True, timeout=180).stdout
    # the title, legend and notes of the PNG lie over the 3D view once the viewer has started
    assert 'id="rigsim-title"' in dom and "reflected beam" in dom and "exact null of face +Z" in dom
    shot = tmp_path / "shot.png"
    subprocess.run([CHROMIUM, "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                    "--enable-unsafe-swiftshader", "--virtual-time-budget=10000", "--window-size=1000,700",
                    f"--screenshot={shot}", html.resolve().as_uri()], capture_output=True, timeout=180)
    img = cv2.imread(str(shot))
    assert img is not None
    # not a blank page: a good part of the view is drawn (not white), and the incident beam's
    # orange (B low, G mid, R high) is there
    nonwhite = np.mean(np.any(img < 230, axis=2))
    assert nonwhite > 0.05, nonwhite
    b, g, rr = (img[..., k].astype(int) for k in range(3))
    assert np.count_nonzero((rr > 180) & (g > 100) & (g < 200) & (b < 80)) > 50
