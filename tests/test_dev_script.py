"""`./dev run` (the main job) writes into runs/, which git ignores: a clone stays clean after it. renders/ changes
only through scripts/refresh-renders. The dev script runs here against a stand-in virtualenv whose `rigsim` prints
its arguments (the job itself is not run)."""

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _fake_clone(tmp_path) -> Path:
    d = tmp_path / "clone"
    d.mkdir()
    shutil.copy(ROOT / "dev", d / "dev")
    shutil.copy(ROOT / "pyproject.toml", d / "pyproject.toml")
    b = d / ".venv" / "bin"
    b.mkdir(parents=True)
    (b / "python").symlink_to(sys.executable)
    (b / "rigsim").write_text('#!/bin/sh\nprintf "%s\\n" "$@"\n')
    (b / "rigsim").chmod(0o755)
    stamp = subprocess.run(["bash", "-c", 'printf "%s" "$("$0" -c "import sys;print(sys.version)")$(cat pyproject.toml)" '
                            "| sha256sum | cut -c1-16", sys.executable], cwd=d, capture_output=True, text=True,
                           check=True).stdout.strip()
    (d / ".venv" / ".rigsim-stamp").write_text(stamp)
    return d


def _args(d, *argv):
    r = subprocess.run(["./dev", "run", *argv], cwd=d, capture_output=True, text=True, timeout=60,
                       env={"PATH": "/usr/bin:/bin", "PYTHON": sys.executable})
    assert r.returncode == 0, r.stderr
    return r.stdout.splitlines()


def test_dev_run_writes_into_the_ignored_runs_folder(tmp_path):
    d = _fake_clone(tmp_path)
    assert _args(d) == ["run", "cube-mirror", "--out", "runs/cube_mirror_sun_sensor_2axis_diaphragm"]
    a = _args(d, "--rig", "sun_sensor_3axis_autocollimator", "--quiet")
    assert a[:4] == ["run", "cube-mirror", "--out", "runs/cube_mirror_sun_sensor_3axis_autocollimator"]
    assert _args(d, "--out", "mine")[-2:] == ["--out", "mine"]  # the user's --out comes last: argparse takes it
    ignored = subprocess.run(["git", "check-ignore", "-q", "runs/cube_mirror_x/report.md"], cwd=ROOT)
    assert ignored.returncode == 0
    tracked = subprocess.run(["git", "check-ignore", "-q", "renders/boresight/report.md"], cwd=ROOT)
    assert tracked.returncode == 1
