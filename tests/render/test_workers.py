"""The worker pools' start (rigsim.render.workers): a forkserver that never loads the renderer, workers in their
caller's environment, spawn on request."""

import os
import subprocess
import sys

import pytest

from rigsim.errors import InputError
from rigsim.render.workers import START_METHOD_ENV, pool_context, process_pool


def test_the_forkserver_preload_loads_no_renderer_and_no_truth():
    code = ("import sys, rigsim._worker; print(sorted(m for m in ('mitsuba', 'drjit', 'rigsim.render', 'rigsim.truth', "
            "'rigsim.dataset', 'rigsim.procedures') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "[]", (r.stdout, r.stderr)


def test_a_worker_runs_in_the_callers_environment_of_the_moment(monkeypatch):
    """The forkserver keeps the environment it started with; each new pool's workers take the caller's current one
    (a variable set, one removed), and they are not this process's children but the server's."""
    monkeypatch.delenv(START_METHOD_ENV, raising=False)
    with process_pool(1) as ex:  # the server starts here (or already has)
        assert ex.submit(os.getenv, "RIGSIM_TEST_WORKER_ENV").result(timeout=120) is None
        parent = ex.submit(os.getppid).result(timeout=120)
    if pool_context().get_start_method() == "forkserver":
        assert parent != os.getpid()
    monkeypatch.setenv("RIGSIM_TEST_WORKER_ENV", "set after the server started")
    monkeypatch.delenv("HOME", raising=False)
    with process_pool(1) as ex:
        assert ex.submit(os.getenv, "RIGSIM_TEST_WORKER_ENV").result(timeout=120) == "set after the server started"
        assert ex.submit(os.getenv, "HOME").result(timeout=120) is None


def test_spawn_on_request_and_a_bad_method_named(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv(START_METHOD_ENV, "spawn")
    assert pool_context().get_start_method() == "spawn"
    with process_pool(1) as ex:
        assert ex.submit(os.getppid).result(timeout=120) == os.getpid()
    monkeypatch.setenv(START_METHOD_ENV, "fork")
    with pytest.raises(InputError, match=r"environment variable RIGSIM_START_METHOD='fork': allowed forkserver, spawn"):
        pool_context()
    from rigsim.cli import main

    assert main(["dataset", "generate", "star_sensor", "--out", str(tmp_path / "ds"), "--frames", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "RIGSIM_START_METHOD='fork'" in err, err
    assert not (tmp_path / "ds").exists()
