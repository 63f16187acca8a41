"""The campaign report with its rig picture made beforehand (``write_report(picture=...)``, as
``rigsim run cube-mirror`` does): the PNG is written as given, and a missing picture is one line in
the report, which is written all the same."""

import warnings

import pytest

from rigsim.procedures.cube_mirror.rendered_campaign import run_rendered_campaign
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.realization import Noise, realization_from_rig


@pytest.fixture(scope="module")
def coarse_ideal_000():
    """A cheap campaign to report on (no number of it is checked here): the ±60° sweep every 30° at 16 spp, as the
    file chain's, and the aiming camera with 1/16 of the pixels over the same field (400 × 300 px of 60 µm)."""
    rig = load_rig("sun_sensor_2axis_diaphragm")
    rig = rig.model_copy(update={
        "procedure": rig.procedure.model_copy(update={"command_resolution_deg": 0.0}),
        "aiming_camera": rig.aiming_camera.model_copy(update={"resolution_px": [400, 300], "pixel_pitch_um": 60.0})})
    real = realization_from_rig(rig, ideal=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = run_rendered_campaign(rig, real, seed=3, noise=Noise(), noiseless=True, sweep_step_deg=30.0, sweep_spp=16,
                                  repeat_frames=0)
    return rig, c


@pytest.mark.render
def test_report_writes_the_picture_made_beforehand(coarse_ideal_000, tmp_path):
    pytest.importorskip("pyvista")
    from rigsim.procedures.cube_mirror.report import write_report
    from rigsim.view.picture_process import picture_in_child

    rig, c = coarse_ideal_000
    png, why = picture_in_child(rig, tmp_path / "made.png", pose_deg="null", size=(480, 320))
    assert why == ""
    files = write_report(tmp_path / "report", c, rig, picture=(png.read_bytes(), ""))
    assert files["rig_picture"].read_bytes() == png.read_bytes()
    md = files["report"].read_text()
    assert "![the rig at the first face's exact null (rigsim view)](rig.png)" in md
    assert "unavailable" not in md


@pytest.mark.render
def test_a_missing_picture_is_one_line_and_the_report_goes_on(coarse_ideal_000, tmp_path):
    from rigsim.procedures.cube_mirror.report import write_report

    rig, c = coarse_ideal_000
    files = write_report(tmp_path, c, rig, picture=(None, "ViewError: no off-screen OpenGL"))
    md = files["report"].read_text()
    assert "(rig picture unavailable: ViewError: no off-screen OpenGL)" in md
    assert "rig_picture" not in files and not (tmp_path / "rig.png").exists()
    for k in ("calibration_residuals", "search_path", "json", "html"):
        assert files[k].is_file()
