"""`rigsim render star-field`: a star-sensor frame with its truth; the isolated stars' centroids sit on
the exact positions on both renderers."""

import json
import re

import numpy as np
import pytest

from rigsim.cli import main
from rigsim.files import Column, read_image, read_table


@pytest.mark.render
@pytest.mark.parametrize("renderer", ["mitsuba", "analytic"])
def test_render_star_field_centroids_on_the_truth(tmp_path, capsys, renderer):
    """Noise-free: a Gaussian fit on the isolated stars finds the exact centres to 0.019 px rms on both
    renderers (the fit's own limit on a sampled, quantised PSF; the two renderers agree to 0.0004 px)."""
    assert main(["render", "star-field", "--renderer", renderer, "--spp", "64", "--noiseless", "--out", str(tmp_path),
                 "--fits"]) == 0
    out = capsys.readouterr().out
    rms = float(re.search(r"error vs exact rms ([0-9.]+) px", out).group(1))
    n = int(re.search(r"(\d+) isolated stars matched", out).group(1))
    assert n > 50 and rms < 0.03, out
    side = json.loads((tmp_path / "star_field.json").read_text())
    t = read_table(tmp_path / "star_field_stars.csv", [Column("hip", kind="int"), Column("u", "px"), Column("v", "px")])
    assert list(t["hip"]) == side["truth"]["hip"] and side["render"]["renderer"] == renderer
    assert np.array_equal(read_image(tmp_path / "star_field.fits"), read_image(tmp_path / "star_field.png"))


def test_bad_attitude_is_one_line(capsys):
    assert main(["render", "star-field", "--attitude", "ra=10,dec=91"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == "rigsim: error: --attitude dec = 91.0: allowed -90 to 90 degrees"
    assert main(["render", "star-field", "--attitude", "ra=10"]) == 2
    assert "give both ra and dec" in capsys.readouterr().err
