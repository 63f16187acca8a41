"""A dataset on a real Dask cluster, started as docs/datasets.md says (a `dask scheduler` and `dask worker`
processes of their own), with the workers in other folders: a relative --out is resolved before it reaches them,
so the frames land in the client's folder; a worker that cannot reach the folder (here: a worker in its own mount
namespace, where a different, empty file system covers the folder's path, as on a node without the shared file
system) is refused at the start with one line, before any task is sent."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rigsim.cli import main

DASK = str(Path(sys.executable).parent / "dask")


def _start(argv, cwd, log):
    return subprocess.Popen(argv, cwd=cwd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
                            env={**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False"})


def _stop(procs):
    for p in procs:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def _wait_for(path: Path, timeout=60.0):
    t0 = time.time()
    while not (path.exists() and path.stat().st_size):
        if time.time() - t0 > timeout:
            raise TimeoutError(path)
        time.sleep(0.2)


@pytest.fixture
def cluster(tmp_path):
    if shutil.which("unshare") is None or os.geteuid() != 0:
        pytest.skip("the unreachable worker needs unshare and root (a private mount namespace)")
    (tmp_path / "s").mkdir()
    log = open(tmp_path / "cluster.log", "ab")
    sched = _start([DASK, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file",
                    str(tmp_path / "s" / "scheduler.json")], tmp_path / "s", log)
    procs = [sched]
    try:
        _wait_for(tmp_path / "s" / "scheduler.json")
        addr = json.loads((tmp_path / "s" / "scheduler.json").read_text())["address"]
        yield tmp_path, addr, procs, log
    finally:
        _stop(procs)
        log.close()


def _worker(addr, cwd, log, extra=()):
    return _start([*extra, DASK, "worker", addr, "--nworkers", "1", "--nthreads", "1", "--no-dashboard",
                   "--name", Path(cwd).name], cwd, log)


def _workers_joined(addr, n, timeout=60.0):
    from distributed import Client

    with Client(addr, timeout="10s") as c:
        c.wait_for_workers(n, timeout=timeout)


@pytest.mark.slow  # about 15 s: a scheduler and three worker processes start
def test_a_relative_out_on_a_cluster_whose_workers_run_elsewhere(cluster, capsys, monkeypatch):
    tmp, addr, procs, log = cluster
    for name in ("wa", "wb"):
        (tmp / name).mkdir()
        procs.append(_worker(addr, tmp / name, log))
    _workers_joined(addr, 2)
    (tmp / "client").mkdir()
    monkeypatch.chdir(tmp / "client")
    rc = main(["dataset", "generate", "sun_sensor_2axis_diaphragm", "--out", "ds", "--frames", "2", "--spp", "1",
               "--scheduler", addr, "--quiet"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert sorted(p.name for p in (tmp / "client" / "ds" / "frames").iterdir()) == [
        "frame_000000.json", "frame_000000.png", "frame_000001.json", "frame_000001.png"]
    assert not (tmp / "wa" / "ds").exists() and not (tmp / "wb" / "ds").exists()  # nothing in the workers' folders
    assert not list((tmp / "client" / "ds").glob(".rigsim-worker-probe*"))
    # a third worker that sees another file system at the dataset's path: refused before any task
    shield = ["unshare", "--mount", "--propagation", "private", "sh", "-c",
              f'mount -t tmpfs tmpfs "{tmp}" && mkdir -p "{tmp / "client" / "ds2" / "frames"}" && exec "$0" "$@"']
    procs.append(_worker(addr, "/", log, extra=shield))
    _workers_joined(addr, 3)
    t0 = time.perf_counter()
    rc = main(["dataset", "generate", "sun_sensor_2axis_diaphragm", "--out", "ds2", "--frames", "2", "--spp", "1",
               "--scheduler", addr, "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert "cannot reach --out" in err and "not the client's folder" in err and "ds2" in err, err
    assert time.perf_counter() - t0 < 20
    assert not (tmp / "client" / "ds2" / "frames").exists() or not any((tmp / "client" / "ds2" / "frames").iterdir())


def test_the_worker_probe_tells_a_shared_folder_from_another_of_the_same_name(tmp_path):
    """What each worker runs before any task: the client's token file must be visible at the absolute path."""
    from rigsim.dataset.runner import PROBE_PREFIX, probe_folder

    (tmp_path / "ds").mkdir()
    (tmp_path / "ds" / f"{PROBE_PREFIX}abc.tmp").write_text("abc")
    assert probe_folder(str(tmp_path / "ds"), "abc") is None
    assert "not the client's folder" in probe_folder(str(tmp_path / "ds"), "other")
    assert "no folder" in probe_folder(str(tmp_path / "nope"), "abc")
    assert "not an absolute path" in probe_folder("ds", "abc")
    assert [p.name for p in (tmp_path / "ds" / "frames").iterdir()] == []  # the write test leaves nothing
