"""`rigsim run robustness` for the boresight rig: its quantities, a short paired run of every effect
against the ideal frames (signs and sizes the physics predicts), and the frames figure."""

import numpy as np
import pytest

from rigsim.procedures.boresight import robustness as rb
from rigsim.procedures.robustness import ALL, IDEAL, summarise, verdicts, write_robustness_files
from rigsim.rig.load import load_boresight_rig

RIG = load_boresight_rig()


def test_family_module_and_quantities():
    from rigsim.procedures.robustness_commands import family_module

    assert family_module(RIG) is rb
    assert rb.effect_names(RIG) == ("gaussian_beam", "prism_glass", "objective_aberrations")
    qs = {q.key: q for q in rb.quantities(RIG)}
    for m in ("dvad", "simplified"):
        for a in ("roll", "pitch", "yaw"):
            assert qs[f"{m}_rel_{a}_arcsec"].budget == 0.1 and qs[f"{m}_rel_{a}_arcsec"].unit == "arcsec"
        assert qs[f"{m}_delta_f_um"].budget is None
    assert qs["centroid_bias_u_px"].budget == RIG.study.centroid_sigma_px
    assert qs["failed_runs_count"].lower_is_better


@pytest.mark.render
def test_frames_figure(tmp_path):
    out = rb.frames_figure(RIG, tmp_path / "frames.png", seed=1, names=("prism_glass",))
    assert out.exists() and out.stat().st_size > 10_000


@pytest.mark.slow
@pytest.mark.render
def test_short_run_effects_against_ideal(tmp_path):
    """2 trials of a 3-measurement orbit (2 reference frames, 64 spp). Expected: the ghosts of the
    prism glass pull the centroid towards the brighter one (−v, the Fresnel-weighted closed form gives
    −0.061 px); the objective's coma moves it by the Seidel centroid shift (−0.50 px in u on both
    CMOS, ±0.39 px in v, which cancels in the mean of M1 and M2); the Gaussian beam's wider spot
    scatters the centroids more; every effect is constant at the spot's scale, so the reference spots
    absorb it and the relative angle stays within the paper's 0.1″ precision."""
    rig = RIG.model_copy(update={"orbit": RIG.orbit.model_copy(update={"measurements": 3, "reference_frames": 2,
                                                                        "spp": 64})})
    res = rb.run_robustness(rig, trials=2, seed=0)
    r, peak = res
    assert r.pipeline.startswith("as configured (thresholded centroid of the ROI)")
    assert peak.pipeline == "thresholded centroid of the peak's blob" and peak.configs == r.configs
    assert r.configs == (IDEAL, "gaussian_beam", "prism_glass", "objective_aberrations", ALL)
    v = {c: {k: np.asarray(x) for k, x in d.items()} for c, d in r.values.items()}
    for c in r.configs:
        assert (v[c]["failed_runs_count"] == 0).all(), c
    ideal = v[IDEAL]
    assert np.abs(ideal["centroid_bias_u_px"]).max() < 0.01 and np.abs(ideal["centroid_bias_v_px"]).max() < 0.01
    pull = v["prism_glass"]["centroid_bias_v_px"]
    assert ((pull > -0.09) & (pull < -0.03)).all(), pull
    coma = v["objective_aberrations"]
    assert np.allclose(coma["centroid_bias_u_px"], -0.496, atol=0.06), coma["centroid_bias_u_px"]
    assert np.abs(coma["centroid_bias_v_px"]).max() < 0.03
    # the full report (4 trials, 256 spp) measured +9 %; at 64 spp the photon-noise share is larger
    assert v["gaussian_beam"]["centroid_scatter_px"].mean() > ideal["centroid_scatter_px"].mean()
    for c in r.configs:
        for m in ("dvad", "simplified"):
            for a in ("roll", "pitch", "yaw"):
                assert v[c][f"{m}_rel_{a}_arcsec"].max() < 0.1, (c, m, a)
    # the same frames through the peak's blob: the ghosts are separated from the spot by the threshold and
    # no longer pull it (measured on one frame: −0.044 → −0.005 px); coma stays (it is the spot's own shape)
    vp = {c: {k: np.asarray(x) for k, x in d.items()} for c, d in peak.values.items()}
    assert np.abs(vp["prism_glass"]["centroid_bias_v_px"]).max() < 0.02, vp["prism_glass"]["centroid_bias_v_px"]
    assert np.allclose(vp["objective_aberrations"]["centroid_bias_u_px"], coma["centroid_bias_u_px"], atol=0.01)
    assert np.allclose(vp[IDEAL]["centroid_bias_u_px"], ideal["centroid_bias_u_px"], atol=0.01)
    rows = summarise(r)
    verdict = verdicts(r, rows)
    assert verdict["objective_aberrations"]["must_handle"]     # the centroid bias is 5× its 0.1-px budget
    files = write_robustness_files(tmp_path, res)
    assert all(p.exists() for p in files.values())
