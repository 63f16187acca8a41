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
