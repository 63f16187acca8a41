"""The shared verdict of every command that estimates from a user's files: a poor fit raises PoorFitError
(exit status 3 through the CLI) naming the alternatives under which the data fit, equal fits named
together; --accept-poor-fit lets it through, marked; composed results carry their inputs' verdicts."""

import math

import pytest

from rigsim.errors import POOR_FIT_EXIT, PoorFitError
from rigsim.estimation.fit_quality import judge_chi2
from rigsim.procedures.fit_verdict import diagnose, inherited, judge

POOR = judge_chi2(1e6, 100, "σ")
GOOD = judge_chi2(100.0, 100, "σ")


def _fails():
    raise ValueError("a non-physical camera")


ALTS = [("units", lambda: judge_chi2(105.0, 100, "σ")), ("sign", lambda: judge_chi2(300.0, 100, "σ")),
        ("mirror", lambda: judge_chi2(105.0000001, 100, "σ")), ("still poor", lambda: POOR),
        ("fails", _fails), ("no refit", lambda: None)]


def test_a_poor_fit_is_refused_with_its_causes():
    with pytest.raises(PoorFitError) as e:
        judge(POOR, ALTS, accept=False, what="a calibration")
    msg = str(e.value)
    assert e.value.exit_status == POOR_FIT_EXIT == 3
    assert "a calibration: the data do not fit the model: χ²/dof 1.00e+04" in msg
    # units and mirror are the same fit (to 6 digits): named together, before sign (χ²/dof 3)
    assert "one of units or mirror (χ²/dof 1.05 each: the same fit" in msg and "; or sign (χ²/dof 3)" in msg
    assert "still poor" not in msg.split("read as:")[1] and "Nothing was written" in msg


def test_no_cause_that_fits_names_those_tested():
    with pytest.raises(PoorFitError) as e:
        judge(POOR, ALTS[3:], accept=False, what="x")
    assert "None of the causes rigsim can test makes them fit (still poor, fails, no refit)" in str(e.value)


def test_diagnose_needs_a_real_improvement():
    barely = judge_chi2(3000.0, 100, "σ")  # χ²/dof 30, poor
    assert [c.name for c in diagnose(barely, [("small", lambda: judge_chi2(2000.0, 100, "σ"))])] == []
    assert [c.name for c in diagnose(barely, [("big", lambda: judge_chi2(200.0, 100, "σ"))])] == ["big"]


def test_accepted_poor_fit_is_marked_and_good_fits_pass_without_refits():
    v = judge(POOR, ALTS, accept=True, what="a calibration")
    b = v.block()
    assert b["verdict"] == "poor" and b["accepted_poor_fit"] and b["causes_tested"][0] == "units"
    assert [c["cause"] for c in b["causes_that_fit"]] == ["units", "mirror", "sign"]
    assert any(line.startswith("POOR FIT ACCEPTED") for line in v.lines())
    called = []
    v = judge(GOOD, [("x", lambda: called.append(1))], accept=False, what="y")
    assert not called and v.block()["verdict"] == "good" and "causes_tested" not in v.block()


def test_composed_results_inherit_their_inputs_verdicts():
    ok = {"verdict": "good", "chi2_dof": 0.9}
    v = inherited({"a": ok, "b": None}, accept=False, what="compose")
    assert v.quality.verdict == "not judged" and v.block()["inputs"]["a"] == ok
    assert "a good (χ²/dof 0.9); b not judged (no fit block)" in v.lines()[0]
    poor = {"verdict": "poor", "chi2_dof": 1e5}
    with pytest.raises(PoorFitError, match="b is a poor fit"):
        inherited({"a": ok, "b": poor}, accept=False, what="compose")
    v = inherited({"a": ok, "b": poor}, accept=True, what="compose")
    assert v.block()["verdict"] == "poor" and v.block()["accepted_poor_fit"]
    assert math.isnan(v.quality.chi2_dof)
