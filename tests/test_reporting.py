"""Self-contained HTML reports, opened in headless Chromium (Debian's chromium package)."""

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from rigsim.reporting import markdown_to_html

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed (./dev installs it)")


def _open_in_chromium(html: Path) -> str:
    r = subprocess.run([CHROMIUM, "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                        "--virtual-time-budget=5000", "--dump-dom", html.resolve().as_uri()],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout


def _images_ok(dom: str) -> tuple[int, int]:
    m = re.search(r'data-images-ok="(\d+)/(\d+)"', dom)
    assert m, "the page's load script did not run"
    return int(m.group(1)), int(m.group(2))


def _png(path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(2, 2))
    plt.plot([0, 1], [0, 1])
    fig.savefig(path)
    plt.close(fig)


def test_markdown_becomes_one_self_contained_file(tmp_path):
    _png(tmp_path / "plot.png")
    (tmp_path / "r.md").write_text("# T\n\n| a | b |\n|---|---:|\n| 1 | 2.5 |\n\n![a plot](plot.png)\n")
    h = markdown_to_html(tmp_path / "r.md")
    text = h.read_text()
    assert "<table>" in text and 'src="data:image/png;base64,' in text and "plot.png" not in text.replace('alt="a plot"', "")
    (tmp_path / "plot.png").unlink()  # self-contained: nothing else is needed


@needs_chromium
def test_chromium_renders_the_page_with_its_images(tmp_path):
    _png(tmp_path / "plot.png")
    (tmp_path / "r.md").write_text("# T\n\n![one](plot.png)\n\n![two](plot.png)\n")
    h = markdown_to_html(tmp_path / "r.md")
    (tmp_path / "plot.png").unlink()
    assert _images_ok(_open_in_chromium(h)) == (2, 2)


@needs_chromium
@pytest.mark.parametrize("report", sorted(str(p.relative_to(ROOT)) for p in ROOT.glob("renders/*/report.html")))
def test_committed_reports_render_in_chromium(report):
    dom = _open_in_chromium(ROOT / report)
    ok, n = _images_ok(dom)
    assert n >= 3 and ok == n, (ok, n)
    assert "<table>" in dom


def test_every_procedure_has_a_committed_html_report():
    """The browser test above is parametrised over renders/*/report.html: make sure it has them all."""
    for d in ("cube_mirror_sun-sensor-2axis-diaphragm", "cube_mirror_sun-sensor-3axis-autocollimator", "boresight",
              "star_calibration"):
        assert (ROOT / "renders" / d / "report.html").is_file(), d
