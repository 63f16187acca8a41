"""FitQuality: χ²/dof, its p-value and the verdicts against closed forms (χ² with 2 dof: P(χ² ≥ x) = e^(−x/2))
and Gaussian draws of known σ."""

import math

import numpy as np
import pytest

from rigsim.estimation.fit_quality import CHANCE_P, POOR_CHI2_DOF, judge_chi2, judge_residuals, not_judged


def test_noise_alone_is_good_and_not_scaled():
    r = np.random.default_rng(0).normal(0.0, 0.02, (1000, 2))
    q = judge_residuals(r, 0.02, 11, "σ")
    assert q.dof == 1989 and abs(q.chi2_dof - 1.0) < 4 * math.sqrt(2 / q.dof)
    assert q.verdict == "good" and q.covariance_scale == 1.0 and not q.poor
    assert q.residual_rms == pytest.approx(0.02, rel=0.05) and q.noise_rms == pytest.approx(0.02)


def test_p_value_against_the_closed_form_for_two_dof():
    for x in (0.5, 3.0, 14.0):
        q = judge_chi2(x, 2, "σ")
        assert q.p_value == pytest.approx(math.exp(-x / 2), rel=1e-12)
    # 2 dof: χ²/dof 7 is beyond chance (p = e^-7 < 1e-3), 3 is not (p = e^-3 = 0.05)
    assert judge_chi2(14.0, 2, "σ").verdict == "scaled" and judge_chi2(6.0, 2, "σ").verdict == "good"
    assert math.exp(-7) < CHANCE_P < math.exp(-3)


def test_three_sigma_residuals_scale_six_sigma_residuals_are_poor():
    rng = np.random.default_rng(1)
    q3 = judge_residuals(rng.normal(0.0, 3.0, 4000), 1.0, 0, "σ")
    assert q3.verdict == "scaled" and q3.covariance_scale == q3.chi2_dof == pytest.approx(9.0, rel=0.1)
    q6 = judge_residuals(rng.normal(0.0, 6.0, 4000), 1.0, 0, "σ")
    assert q6.verdict == "poor" and q6.chi2_dof > POOR_CHI2_DOF and "POOR FIT" in q6.describe()
    d = q6.as_dict()
    assert d["verdict"] == "poor" and d["covariance_scaled"] and d["dof"] == 4000


def test_non_finite_residuals_and_failed_checks_are_poor():
    assert judge_residuals([1.0, math.inf, 0.0], 1.0, 0, "σ").verdict == "poor"
    q = judge_residuals([0.1, -0.1, 0.05], 1.0, 0, "σ", problems=("a spot outside its window",))
    assert q.verdict == "poor" and "a spot outside its window" in q.describe()
    nj = not_judged("one frame")
    assert nj.verdict == "not judged" and nj.covariance_scale == 1.0 and nj.as_dict()["chi2_dof"] is None
    assert not_judged("one frame", problems=("noise 9× the model",)).verdict == "poor"
    with pytest.raises(ValueError):
        judge_residuals([0.1], 0.0, 0, "σ")
