"""A command that works longer than 2 s without a progress bar of its own says so on a terminal, and erases
the line at the end; off a terminal it writes nothing."""

import io
import time

from rigsim.cli import _Heartbeat


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_a_long_command_shows_its_seconds_on_a_terminal_and_erases_them():
    s = _Tty()
    with _Heartbeat("autocollimator read", delay=0.1, interval=0.05, stream=s):
        time.sleep(0.4)
    out = s.getvalue()
    assert "rigsim autocollimator read: working, 0 s" in out and out.endswith("\r\x1b[K")


def test_a_short_command_or_a_pipe_shows_nothing():
    s = _Tty()
    with _Heartbeat("triad", delay=1.0, stream=s):
        time.sleep(0.05)
    assert s.getvalue() == ""
    p = io.StringIO()
    with _Heartbeat("autocollimator read", delay=0.0, interval=0.01, stream=p):
        time.sleep(0.1)
    assert p.getvalue() == ""


def test_off_a_terminal_a_long_command_writes_a_note_line_at_each_interval():
    """A log file or a pipe gets whole lines (no carriage return, no escape codes), every interval, while it runs."""
    p = io.StringIO()
    with _Heartbeat("run robustness", stream=p, log_interval=0.05):
        time.sleep(0.3)
    lines = p.getvalue().splitlines()
    assert len(lines) >= 3 and all(ln.startswith("rigsim: note: rigsim run robustness still working (") for ln in lines)
    assert "\r" not in p.getvalue() and "\x1b" not in p.getvalue()
    q = io.StringIO()
    with _Heartbeat("run robustness", stream=q, log_interval=0):  # RIGSIM_HEARTBEAT_S=0: none
        time.sleep(0.1)
    assert q.getvalue() == ""


def test_a_command_run_into_a_log_says_it_is_alive(tmp_path):
    import os
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "rigsim.cli", "run", "cube-mirror", "--analytic", "--no-budget", "--quiet",
                        "--out", str(tmp_path / "r")], capture_output=True, text=True, timeout=300,
                       env={**os.environ, "RIGSIM_HEARTBEAT_S": "0.2"})
    assert r.returncode == 0, r.stderr
    beats = [ln for ln in r.stderr.splitlines() if "still working" in ln]
    assert beats and all(ln.startswith("rigsim: note: rigsim run cube-mirror still working") for ln in beats), r.stderr
