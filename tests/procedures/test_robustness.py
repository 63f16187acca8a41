"""The robustness summary and verdict on known numbers, and `rigsim run robustness` on a short star rig."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from rigsim.cli import main
from rigsim.files import read_table
from rigsim.files.tables import Column
from rigsim.procedures.robustness import (
    ALL,
    IDEAL,
    Quantity,
    RobustnessResult,
    summarise,
    verdicts,
    write_robustness_files,
)

Q = (Quantity("a_px", "a", "px"), Quantity("n_count", "stars", "count", kind="count"))


def _result(shift, extra_noise, lost):
    rng = np.random.default_rng(0)
    ideal = rng.normal(0.0, 0.1, 50)
    d = shift + rng.normal(0.0, extra_noise, 50)
    values = {IDEAL: {"a_px": ideal, "n_count": np.full(50, 100.0)},
              "fx": {"a_px": ideal + d, "n_count": np.full(50, 100.0 - lost)},
              ALL: {"a_px": ideal + d, "n_count": np.full(50, 100.0 - lost)}}
    return RobustnessResult("test", "rig", 0, 50, Q, (IDEAL, "fx", ALL), values, {c: 1.0 for c in values}), ideal, d


def test_added_error_is_the_rms_of_the_paired_difference():
    res, ideal, d = _result(0.02, 0.01, 0)
    rows = {(r["config"], r["quantity"]): r for r in summarise(res)}
    r = rows[("fx", "a_px")]
    assert r["added_rms"] == pytest.approx(math.sqrt(np.mean(d**2)), rel=1e-12)
    assert r["reference"] == pytest.approx(math.sqrt(np.mean(ideal**2)), rel=1e-12)
    assert r["mean"] == pytest.approx(np.mean(ideal + d), rel=1e-12)
    assert rows[(IDEAL, "a_px")]["added_rms"] == 0.0
    assert verdicts(res)["fx"]["level"] == "none"                      # adds ~0.02 of ~0.1


def test_verdict_levels_follow_the_limits():
    res, _, _ = _result(0.1 * 0.75, 0.0, 0)                               # adds 0.75× the ideal rms
    v = verdicts(res)["fx"]
    assert v["level"] == "marginal" and not v["must_handle"] and v["reasons"][0].startswith("[marginal] a:")
    res, _, _ = _result(0.1 * 1.5, 0.0, 0)                                # 1.5×
    assert verdicts(res)["fx"]["level"] == "must"
    res, _, _ = _result(0.0, 0.0, 3)                                      # 3 % of the stars lost
    v = verdicts(res)["fx"]
    assert v["level"] == "marginal" and v["reasons"] == ["[marginal] stars: -3 per trial (-3.0 %)"]
    res, _, _ = _result(0.0, 0.0, 6)
    assert verdicts(res)["fx"]["must_handle"]


def test_files_carry_units_in_the_column_names(tmp_path):
    res, _, _ = _result(0.02, 0.01, 0)
    files = write_robustness_files(tmp_path, res)
    t = read_table(files["csv"], [Column("a_added_rms", "px"), Column("n_count_mean", "")])
    assert t["a_added_rms_px"][0] == 0.0 and t["n_count_mean"][1] == 100.0
    d = json.loads(files["json"].read_text())
    assert d["pipelines"][0]["verdict"]["fx"]["must_handle"] is False
    assert "## Verdict" in files["report"].read_text()


@pytest.fixture(scope="module")
def short_star_rig(tmp_path_factory):
    """The default star rig with a 6-frame sequence and a storm of particles (fast enough for a test)."""
    src = Path(__file__).resolve().parents[2] / "scenes" / "star_sensor.toml"
    text = src.read_text().replace("n_frames = 20 ", "n_frames = 6  ").replace("flux_per_cm2_s = 1.2 ", "flux_per_cm2_s = 400.0")
    assert "n_frames = 6" in text and "flux_per_cm2_s = 400.0" in text
    p = tmp_path_factory.mktemp("rig") / "short_star.toml"
    p.write_text(text)
    return p


@pytest.mark.slow  # the command and its files are read by default below (a resumed run), the filter and the pattern
def test_run_robustness_measures_what_hot_pixels_do_to_each_pipeline(short_star_rig, tmp_path):  # in test_cosmetics.py
    out = tmp_path / "rob"
    rc = main(["run", "robustness", str(short_star_rig), "--trials", "2", "--effects", "hot_pixels",
               "--workers", "1", "--out", str(out), "--quiet"])
    assert rc == 0
    for name in ("robustness.md", "robustness.json", "robustness.csv", "robustness.png", "frames.png"):
        assert (out / name).stat().st_size > 0
    assert not (out / "robustness-trials").exists()                    # the kept trials go once the report is written
    d = json.loads((out / "robustness.json").read_text())
    assert d["configs"] == [IDEAL, "hot_pixels"]
    conf, no_filter, no_pattern, poor_kept, poor_frame, mapped, gauss = d["pipelines"]
    rejected, cm = "poor fits rejected against the model", "centroids: model"
    assert conf["pipeline"] == f"as configured (single-pixel filter on, fixed pattern: sequence, {rejected}, {cm})"
    assert no_filter["pipeline"] == f"single-pixel filter off, fixed pattern: sequence, {rejected}, {cm}"
    assert no_pattern["pipeline"] == f"single-pixel filter on, fixed pattern: none, {rejected}, {cm}"
    assert poor_kept["pipeline"] == f"single-pixel filter on, fixed pattern: sequence, poor fits kept, {cm}"
    assert poor_frame["pipeline"] == f"single-pixel filter on, fixed pattern: sequence, poor fits rejected against the frame, {cm}"
    assert mapped["pipeline"] == (f"single-pixel filter on, fixed pattern: sequence, {rejected}, ground centroid map of the "
                                  f"traced lens, {cm}")
    assert gauss["pipeline"] == f"single-pixel filter on, fixed pattern: sequence, {rejected}"  # the Gaussian fit

    def mean(p, c, key):
        return np.mean(p["trials_values"][c][key])

    ideal_n, ideal_c = mean(conf, IDEAL, "identified_count"), mean(conf, IDEAL, "centroid_rms_px")
    # 0.5 % hot pixels put one in a third of the stars' 9×9 windows. Without the pattern from the sequence
    # the filter repairs the isolated ones, the poor-fit test drops the stars a hot pixel spoils, and a few
    # per cent of the stars are lost; with the pattern, with or without the filter, nothing is.
    assert 0.90 * ideal_n < mean(no_pattern, "hot_pixels", "identified_count") < 0.97 * ideal_n
    assert mean(no_pattern, "hot_pixels", "centroid_rms_px") > mean(conf, "hot_pixels", "centroid_rms_px")
    for p in (conf, no_filter):
        assert mean(p, "hot_pixels", "identified_count") > 0.98 * ideal_n
        assert mean(p, "hot_pixels", "centroid_rms_px") < 1.05 * ideal_c
    # the ideal frames are the same for every pipeline: neither the filter nor the pattern finds anything on them
    assert conf["trials_values"][IDEAL] == no_filter["trials_values"][IDEAL] == no_pattern["trials_values"][IDEAL]
    assert poor_kept["trials_values"][IDEAL]["identified_count"] >= conf["trials_values"][IDEAL]["identified_count"]
    # judged against the frame, a poor fit must also stand out of its frame: never fewer stars than the model test
    for c in (IDEAL, "hot_pixels"):
        assert mean(poor_frame, c, "identified_count") >= mean(conf, c, "identified_count")


def test_run_robustness_refuses_what_it_cannot_do(short_star_rig, capsys):
    from rigsim.errors import CliError
    from rigsim.procedures.robustness_commands import family_module

    with pytest.raises(CliError, match="no effects are modelled for dict rigs"):
        family_module({})
    assert main(["run", "robustness", str(short_star_rig), "--effects", "ghosts"]) == 2
    assert "--effects = 'ghosts'" in capsys.readouterr().err


def test_a_fixed_pattern_from_a_staring_sequence_is_refused(star_rig):
    from rigsim.errors import InputError
    from rigsim.procedures.star.pipeline import StarObservation, sequence_pattern

    nominal = star_rig.nominal_rig()
    dn = np.full((8, 8), 100, np.uint16)
    stare = [StarObservation(k, 10.0 * k, dn, np.eye(3)) for k in range(5)]
    with pytest.raises(InputError, match=r"fixed_pattern = 'sequence': the stars move 0.00 px between frames"):
        sequence_pattern(stare, nominal)
    from scipy.spatial.transform import Rotation

    slew = [StarObservation(k, 10.0 * k, dn, Rotation.from_euler("y", 0.1 * k, degrees=True).as_matrix())
            for k in range(5)]
    assert not sequence_pattern(slew, nominal).any()                   # 5 px per frame: allowed; a flat frame


def _square_trial(config, seed):
    return {"v": float(seed) ** 2 + len(config)}


def test_run_configs_gives_the_same_results_in_worker_processes():
    from rigsim.procedures.robustness import run_configs

    one = run_configs(_square_trial, ("ideal", "fx"), [0, 1, 2], workers=1)
    two = run_configs(_square_trial, ("ideal", "fx"), [0, 1, 2], workers=2)
    assert one == two and one[("fx", 2)] == {"v": 6.0}


class _Crash(Exception):
    pass


def _crashing_trial(calls, crash_at):
    def trial(config, seed):
        calls.append((config, seed))
        if len(calls) == crash_at:
            raise _Crash
        return _square_trial(config, seed)
    return trial


def test_a_killed_run_resumes_from_its_stored_trials(tmp_path):
    from rigsim.procedures.robustness import run_configs
    from rigsim.procedures.trial_store import TrialStore

    store = TrialStore(tmp_path / "trials", "key-1")
    calls: list = []
    with pytest.raises(_Crash):
        run_configs(_crashing_trial(calls, 4), ("ideal", "fx"), [0, 1, 2], store=store)
    assert store.count(("ideal", "fx"), [0, 1, 2]) == 3                 # the three runs before the crash
    calls.clear()
    again = run_configs(_crashing_trial(calls, 0), ("ideal", "fx"), [0, 1, 2], store=store)
    assert calls == [("fx", 0), ("fx", 1), ("fx", 2)]                   # only what was not finished
    assert again == run_configs(_square_trial, ("ideal", "fx"), [0, 1, 2])
    # another rig, source or version: nothing is reused, and the files are overwritten
    other = TrialStore(tmp_path / "trials", "key-2")
    assert other.count(("ideal", "fx"), [0, 1, 2]) == 0
    (tmp_path / "trials" / "ideal-seed0.json").write_text("{not json")
    assert store.get("ideal", 0) is None and store.get("ideal", 1) == {"v": 1.0 + 5}
    store.clear()
    assert not (tmp_path / "trials").exists()


def test_an_edited_kept_trial_is_run_again_never_reused(tmp_path):
    """A kept trial carries its own checksum: a value changed by hand (the file still valid JSON, same rig key)
    is not reused; the trial is run again and its true value is what the summary gets."""
    from rigsim.procedures.robustness import run_configs
    from rigsim.procedures.trial_store import TrialStore

    store = TrialStore(tmp_path / "trials", "key-1")
    truth = run_configs(_square_trial, ("ideal", "fx"), [0, 1], store=store)
    p = tmp_path / "trials" / "fx-seed1.json"
    doc = json.loads(p.read_text())
    doc["values"]["v"] += 2.5  # a published mean moved by an edit
    p.write_text(json.dumps(doc))
    assert store.get("fx", 1) is None and store.get("fx", 0) is not None
    calls: list = []
    again = run_configs(_crashing_trial(calls, 0), ("ideal", "fx"), [0, 1], store=store)
    assert calls == [("fx", 1)] and again == truth
    assert store.get("fx", 1) == truth[("fx", 1)]  # rewritten with its checksum


def test_the_trial_store_never_writes_through_a_link(tmp_path):
    from rigsim.errors import InputError
    from rigsim.procedures.trial_store import TrialStore

    outside = tmp_path / "outside"
    outside.mkdir()
    (tmp_path / "report").mkdir()
    (tmp_path / "report" / "trials").symlink_to(outside)
    store = TrialStore(tmp_path / "report" / "trials", "k")
    with pytest.raises(InputError, match="is a link"):
        store.put("ideal", 0, {"v": 1.0})
    with pytest.raises(InputError, match="is a link"):
        store.clear()
    with pytest.raises(InputError, match="is a link"):
        store.create()
    assert store.get("ideal", 0) is None and list(outside.iterdir()) == [] and outside.is_dir()


def test_the_run_key_changes_with_the_rig_and_the_effects(short_star_rig):
    from rigsim.procedures.star.robustness import run_robustness
    from rigsim.procedures.trial_store import run_key
    from rigsim.rig.load import load_any_rig

    rig = load_any_rig(short_star_rig)
    k = run_key(rig, ("hot_pixels",), run_robustness)
    assert k == run_key(load_any_rig(short_star_rig), ("hot_pixels",), run_robustness)
    assert k != run_key(rig, ("hot_pixels", "stray_light"), run_robustness)
    assert k != run_key(rig.model_copy(update={"name": "another"}), ("hot_pixels",), run_robustness)


def test_the_command_resumes_from_the_trials_an_interrupted_run_kept(short_star_rig, tmp_path, capsys):
    from rigsim.procedures.star.robustness import QUANTITIES, pipeline_variants, run_robustness
    from rigsim.procedures.trial_store import FOLDER, TrialStore, run_key
    from rigsim.rig.load import load_any_rig

    rig = load_any_rig(short_star_rig)
    out = tmp_path / "rob"
    store = TrialStore(out / FOLDER, run_key(rig, ("hot_pixels",), run_robustness))
    for c in (IDEAL, "hot_pixels"):
        for s in (5, 6):  # every trial, as an interrupted run would have kept them: nothing is rendered again
            values = {v: {q.key: 100.0 * s + (c == IDEAL) for q in QUANTITIES} for v in pipeline_variants(rig)}
            store.put(c, s, values | {"_render_ms_per_frame": 7.0})
    rc = main(["run", "robustness", str(short_star_rig), "--trials", "2", "--seed", "5", "--effects", "hot_pixels",
               "--workers", "1", "--out", str(out), "--quiet"])
    assert rc == 0
    assert "resuming: 4 of 4 runs kept by an interrupted run" in capsys.readouterr().out
    d = json.loads((out / "robustness.json").read_text())
    assert d["pipelines"][0]["trials_values"]["hot_pixels"]["identified_count"] == [500.0, 600.0]
    assert d["pipelines"][0]["trials_values"][IDEAL]["identified_count"] == [501.0, 601.0]
    assert d["render_ms_per_frame"] == {IDEAL: 7.0, "hot_pixels": 7.0}
    assert not (out / FOLDER).exists()
