"""rigsim readings: the registry is complete and consistent with the commands it names; its evaluation
recomputes the documents' own numbers; check-matrix analyses a printed matrix."""

import argparse
import json
import re

import pytest

from rigsim.cli import build_parser, main
from rigsim.procedures.readings import READINGS, evaluate, find


def _subparser(parser, words):
    for w in words:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[w]
    return parser


def test_every_reading_is_complete():
    assert {r.seed for r in READINGS} == {"000", "001", "003", "004"}
    assert len({(r.seed, r.key) for r in READINGS}) == len(READINGS)
    for r in READINGS:
        assert len(r.options) >= 2 and r.printed and r.why and r.select and r.title, r.key
        assert r.default in r.options or r.default.startswith("see "), (r.key, r.default)


def test_every_command_option_a_reading_names_exists():
    """Each 'rigsim CMD --option' in a reading's 'select' is a real option of that command."""
    parser = build_parser()
    checked = 0
    for r in READINGS:
        for cmd, opt in re.findall(r"rigsim ((?:[a-z][a-z-]* )+?)(--[a-z0-9-]+)", r.select):
            sp = _subparser(parser, cmd.split())
            assert opt in sp._option_string_actions, (r.seed, r.key, cmd, opt)
            checked += 1
    assert checked >= 8


def test_evaluation_recomputes_table1_and_the_printed_matrix():
    e = evaluate()
    t = {(x["axis_order"], x["eq8"]): x for x in e["seed000_table1"]}
    assert t[("YX", "beam")]["deg_from_default"] == pytest.approx(1.057, abs=0.001)
    assert t[("XY", "printed")]["angle_r_deg"] == pytest.approx(0.576, abs=0.001) and t[("XY", "printed")]["degenerate"]
    assert t[("XY", "beam")]["angle_r_deg"] == pytest.approx(90.0121, abs=1e-4)
    m = e["seed001_printed_matrix"]
    assert m["improper"] and m["sign_repair"]["change"] == "element (2,2)"


def test_readings_command(tmp_path, capsys):
    assert main(["readings", "--seed", "001"]) == 0
    out = capsys.readouterr().out
    assert "seed 001 · printed_matrix" in out and "* repaired" in out and "seed 000 ·" not in out
    assert main(["readings", "000:eq8", "--evaluate", "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert "XY          printed     0.5760°" in out
    js = json.loads((tmp_path / "r.json").read_text())
    assert [r["key"] for r in js["readings"]] == ["eq8"] and len(js["evaluation"]["seed000_table1"]) == 4
    assert main(["readings", "000:nope"]) == 2
    assert "reading '000:nope': unknown; known: 000:axis_order" in capsys.readouterr().err
    assert find(key="eq8")[0].seed == "000"


def test_check_matrix_command(capsys):
    assert main(["check-matrix"]) == 0
    out = capsys.readouterr().out
    assert "determinant -0.995549" in out and "flipping the sign of element (2,2)" in out
    assert main(["check-matrix", "[[1, 0, 0], [0, 0, -1], [0, 1, 0]]", "--json"]) == 0
    a = json.loads(capsys.readouterr().out)
    assert a["proper"] and a["sign_repair"] is None
    for bad in ("1 2 3; 4 5 6", "1 2 3; 4 5 6; 7 8 x", "nan 0 0; 0 1 0; 0 0 1"):
        assert main(["check-matrix", bad]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "expected" in err


def test_seed000_budget_under_each_sigma1_reading():
    """Eq 14 with the printed σ1 = 2.34″ gives the paper's RSS 3.69″; the text's 15 µm/65 cm give σ1 = 2.380″ (RSS
    3.72″); Table 1's implied ~30 µm pixel doubles σ1 and the < 4″ claim fails (5.55″)."""
    from rigsim.procedures.readings import seed000_budget_readings
    from rigsim.rig import load_rig

    b = {r["sigma1_reading"].split(" ")[0]: r for r in seed000_budget_readings()}
    assert b["printed"]["rss_arcsec"] == pytest.approx(3.69, abs=0.005) and b["printed"]["claim_holds"]
    assert b["derived"]["sigma1_arcsec"] == pytest.approx(2.380, abs=1e-3) and b["derived"]["rss_arcsec"] == pytest.approx(3.72, abs=0.005)
    assert b["Table"]["rss_arcsec"] == pytest.approx((4.760**2 + 8.16) ** 0.5, abs=0.002) and not b["Table"]["claim_holds"]
    rig = seed000_budget_readings(load_rig("sun_sensor_2axis_diaphragm"))
    assert rig[1]["sigma1_arcsec"] == pytest.approx(b["derived"]["sigma1_arcsec"], rel=1e-9)  # the default rig is the text's
