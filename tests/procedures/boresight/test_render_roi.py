"""`rigsim render boresight-roi`: one CMOS ROI at a camera state; the boresight centroid stage finds the
exact spot centre the sidecar holds."""

import json
import re

import numpy as np
import pytest

from rigsim.cli import main


@pytest.mark.render
def test_render_boresight_roi_centroid_on_the_exact_spot(tmp_path, capsys):
    """α = 30″, Δf = 5 µm on M1 and β = −40″ on the backward camera's M2: the thresholded centre of mass
    lands within 0.02 px of the exact spot (the rendering + detector noise: 0.006 px measured)."""
    for extra in (["--alpha", "30", "--df-um", "5"], ["--camera", "backward", "--detector", "M2", "--beta", "-40"]):
        assert main(["render", "boresight-roi", *extra, "--out", str(tmp_path)]) == 0
        out = capsys.readouterr().out
        err = [float(x) for x in re.search(r"error ([-+0-9.]+), ([-+0-9.]+) px", out).groups()]
        assert np.hypot(*err) < 0.02, out
    side = json.loads((tmp_path / "boresight_backward_m2.json").read_text())
    ex = side["extra"]
    assert ex["camera"] == "backward" and ex["detector"] == "M2" and len(ex["roi_origin_uv"]) == 2


def test_bad_state_is_one_line(capsys):
    assert main(["render", "boresight-roi", "--alpha", "nan"]) == 2
    assert capsys.readouterr().err.strip() == ("rigsim render boresight-roi: error: argument --alpha: 'nan' is not a number "
                                               "from -3600 to 3600 (see rigsim render boresight-roi --help)")
    assert main(["render", "boresight-roi", "--camera", "sideways"]) == 2
    assert "has cameras forward, backward" in capsys.readouterr().err
