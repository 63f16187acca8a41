"""Every typed option of every subcommand, fuzzed: a value is either parsed into a finite number in its
range (or a safe file stem) or refused with exit status 2 and exactly one line, never a traceback; and
bad rig files are one line with exit 2 from the real command."""

import argparse
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rigsim.cli import build_parser, main
from rigsim.files.names import STEM
from file_chain import rigsim_in_process


def _typed_options():
    out = []

    def walk(p, path):
        positionals = [a for a in p._actions if not a.option_strings and a.nargs is None
                       and not isinstance(a, argparse._SubParsersAction)]
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, sp in a.choices.items():
                    walk(sp, [*path, name])
            elif a.type is not None and a.option_strings:
                out.append((tuple(path), len(positionals), a.option_strings[0], a.dest))

    walk(build_parser(), [])
    return out


OPTIONS = _typed_options()
PARSER = build_parser()  # parse_args keeps no state between calls: one parser serves every example (600 builds took ~10 s)
NASTY = ["nan", "inf", "-inf", "1e308", "-1e308", "0", "-0", "-1", "4**12", "0x10", "", " ", "1_000", "\x1b[31m",
         "../x", "a/b", ".hidden", "x" * 300, "9" * 40, "-9" * 20, "1e-320", "２", "\n"]
VALUES = st.one_of(st.sampled_from(NASTY), st.integers(-2**70, 2**70).map(str),
                   st.floats(allow_nan=True, allow_infinity=True).map(repr), st.text(max_size=12))


def test_the_walk_finds_every_typed_option():
    names = {o for _, _, o, _ in OPTIONS}
    assert {"--seed", "--spp", "--frames", "--name", "--trials", "--sweep-step", "--threshold-dn"} <= names
    assert len(OPTIONS) >= 45


@settings(max_examples=600, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.sampled_from(OPTIONS), VALUES)
def test_a_typed_option_is_parsed_in_range_or_refused_in_one_line(capsys, opt, value):
    path, n_pos, flag, dest = opt
    argv = [*path, *(["x.toml"] * n_pos), f"{flag}={value}"]
    try:
        ns = PARSER.parse_args(argv)
    except SystemExit as e:
        err = capsys.readouterr().err
        assert e.code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, (argv, err)
        assert flag in err or "argument" in err
        return
    v = getattr(ns, dest)
    if flag == "--name":
        assert isinstance(v, str) and STEM.fullmatch(v), (argv, v)
    else:
        items = v if isinstance(v, list) else [v]
        assert all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in items), (argv, v)


def _run(args, cwd, subprocess_run: bool = True):
    """The command as a lab runs it (a subprocess), or through :func:`rigsim.cli.main` in this process for the
    cases after a test's first (the same body without the interpreter's start-up, ~0.8 s a run)."""
    if not subprocess_run:
        return rigsim_in_process(*args, cwd=cwd, ok=range(256))
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    return subprocess.run([sys.executable, "-m", "rigsim.cli", *args], capture_output=True, text=True, timeout=120,
                          cwd=cwd, env=env)


BAD_RIGS = {
    "not_utf8.toml": b"name = \"\xff\xfe\"\n",
    "duplicate.toml": b"name = \"a\"\nname = \"b\"\n",
    "nested.toml": b"a" + b"={a" * 20000 + b"}" * 20000 + b"\n",
    "empty.toml": b"",
    "binary.toml": bytes(range(256)),
}


@pytest.mark.parametrize("command", [["rig", "check"], ["dataset", "generate", "--frames", "2", "--out", "OUT"]])
@pytest.mark.parametrize("bad", [*BAD_RIGS, "a_folder.toml", "a_fifo.toml", "missing.toml"])
def test_a_bad_rig_file_is_one_line_and_exit_2(tmp_path, command, bad):
    p = tmp_path / bad
    if bad in BAD_RIGS:
        p.write_bytes(BAD_RIGS[bad])
    elif bad == "a_folder.toml":
        p.mkdir()
    elif bad == "a_fifo.toml":
        os.mkfifo(p)
    argv = [tmp_path / "OUT" if a == "OUT" else a for a in command]
    before = sorted(Path(tmp_path).rglob("*"))
    r = _run([*map(str, argv[:2]), str(p), *map(str, argv[2:])], tmp_path, subprocess_run=bad == "not_utf8.toml")
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
    assert str(p.name) in r.stderr
    assert sorted(Path(tmp_path).rglob("*")) == before  # nothing written


def test_control_characters_from_a_rig_are_escaped_on_the_terminal(tmp_path, capsys):
    src = Path(__file__).resolve().parents[1] / "scenes" / "sun_sensor_2axis_diaphragm.toml"
    text = src.read_text().replace('name = "sun-sensor-2axis-diaphragm"', 'name = "evil\\u001b[2Jname"', 1)
    assert "evil" in text
    p = tmp_path / "evil.toml"
    p.write_text(text)
    main(["rig", "check", str(p)])
    out = capsys.readouterr().out
    assert "\x1b" not in out and "evil\\x1b[2Jname" in out


@pytest.mark.parametrize("extra,expect", [
    (["--sweep", "dX=0:inf:1"], "must be START:STOP:STEP (finite"),
    (["--sweep", "dX=nan,1"], "comma list of finite numbers"),
    (["--sweep", "dX=0:99999:1 dY=0:99999:1"], "the grid has 10000000000 poses (at most 10000000"),
    (["--sweep", "dX=0:1:0"], "STEP > 0"),
    (["--frames", "2", "--scheduler", "garbage"], "expected a Dask scheduler address"),
    (["--frames", "2", "--generator", "nope"], "argument --generator: invalid choice: 'nope'"),
])
def test_bad_dataset_options_are_one_line_and_write_nothing(tmp_path, extra, expect):
    gen = [] if "--generator" in extra else ["--generator", "aiming-camera"]
    r = _run(["dataset", "generate", "sun_sensor_2axis_diaphragm", "--out", str(tmp_path / "ds"), *gen, *extra], tmp_path,
             subprocess_run="inf" in extra[1])
    assert r.returncode == 2 and expect in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "ds").exists()
