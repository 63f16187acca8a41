"""A user's rig with another autocollimator: the centroid window, the render window and the
diffraction kernel follow its geometry (rigsim.optics.autocollimator.spot_extent_px), so the
rendered frames are measured as well as the default rig's.

The rigs are written as TOML files (the default rig's file with one autocollimator field changed)
and loaded like a user's. Tolerances are the default rig's (tests/procedures/cube_mirror/
test_autocollimation.py, docs/autocollimation.md): READ_TOL = 0.03″ per frame near null (≈ 5σ of
the measured 0.006″ rms), rms < 0.012″ over the frames; the command's 0.2″ at 64 spp.

With the fixed 49 px centroid window of before, the half-pitch rig read 0.04-0.05″ off near null
(the window, centred on the brightest pixel of the ring, cut the cross of its 18 px spot).
"""

import json
import warnings

import numpy as np
import pytest

from rigsim.frames import RAD_PER_ARCSEC
from rigsim.rig.load import SCENES_DIR, load_rig

READ_TOL = 0.03  # ″, as for the default rig
RMS_TOL = 0.012  # ″, 2 × the default rig's measured ≈ 0.006″ rms
DEFAULT = load_rig("sun_sensor_3axis_autocollimator")


def _rig_file(tmp_path, old: str, new: str):
    text = (SCENES_DIR / "sun_sensor_3axis_autocollimator.toml").read_text()
    assert text.count(old) == 1
    path = tmp_path / "my_autocollimator_rig.toml"
    path.write_text(text.replace(old, new))
    return path


CHANGES = {
    "focal length x2": ("focal_length_mm = 550.0", "focal_length_mm = 1100.0"),
    "pitch / 2": ("pixel_pitch_um = 5.3", "pixel_pitch_um = 2.65"),
}


@pytest.mark.render
# twice the focal length in the slow stage: the default stage renders it through `rigsim render autocollimator` below
@pytest.mark.parametrize("change", [pytest.param(c, marks=pytest.mark.slow) if c == "focal length x2" else c
                                    for c in CHANGES])
def test_rendered_reading_near_null_on_a_modified_autocollimator(tmp_path, change):
    from rigsim.procedures.cube_mirror.autocollimation import FaceReadingMeasurer
    from rigsim.procedures.cube_mirror.null_files import autocollimator_roi_px
    from rigsim.truth.cube_mirror.autocollimator import reference_axis_rot
    from rigsim.truth.cube_mirror.realization import realization_from_rig

    rig = load_rig(_rig_file(tmp_path, *CHANGES[change]))
    assert rig.autocollimator != DEFAULT.autocollimator
    real = realization_from_rig(rig)
    m = FaceReadingMeasurer(rig, real, "+Z", reference_axis_rot(rig, real), seed=21)
    # the windows grew with the diffraction pattern (f x2) or the spot in pixels (pitch / 2)
    assert m.roi_px == autocollimator_roi_px(rig, "face") > autocollimator_roi_px(DEFAULT, "face") == 59
    assert m.renderer.diffraction_half_px > 39
    ref = m.renderer.layout.reference_pose_rad
    rng = np.random.default_rng(5)
    errs = []
    for _ in range(4):
        p = dict(ref)
        off = rng.uniform(-0.5, 0.5, 2) * RAD_PER_ARCSEC
        p["Y"] += off[0]
        p["X"] += off[1]
        meas, ex, info = m(p)
        assert np.all(np.abs(ex) < 1.0) and info["truth_flags"] == ["none"] and info["background_rms_dn"] > 1.0
        errs.append(meas - ex)
    e = np.array(errs)
    assert np.max(np.abs(e)) < READ_TOL, e
    assert np.sqrt(np.mean(e ** 2)) < RMS_TOL, e


@pytest.mark.render
def test_render_command_on_a_rig_file_with_twice_the_focal_length(tmp_path, capsys):
    """`rigsim render autocollimator --rig FILE` renders and measures the frame (as the default
    rig's command test: rendered + centroided vs the exact reading within 0.2″ at 64 spp)."""
    from rigsim.cli import main
    from rigsim.files import read_image
    from rigsim.procedures.cube_mirror.null_files import read_autocollimator

    path = _rig_file(tmp_path, *CHANGES["focal length x2"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no geometry warning (spot larger than the window, cut, ...)
        assert main(["render", "autocollimator", "--rig", str(path), "--out", str(tmp_path), "--spp", "64"]) == 0
    out = capsys.readouterr().out
    assert "not measurable" not in out
    side = json.loads((tmp_path / "autocollimator.json").read_text())
    assert not any(v is True for v in side["flags"].values()), side["flags"]
    assert side["render"]["window_px"] == 32
    rig = load_rig(path)
    r, _sig, sm = read_autocollimator(rig, read_image(tmp_path / "autocollimator.png"))
    ex = np.array(side["truth"]["true_tilt_arcsec"])
    assert sm.ok and np.all(np.abs(r - ex) < 0.2), (r, ex)
    printed = [float(x.rstrip("″,")) for x in out.split("exact reading: θx ")[1].split()[0:3:2]]
    np.testing.assert_allclose(printed, ex, atol=1e-4)
