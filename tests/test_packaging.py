"""The wheel ships the default rigs: built from this tree, installed in a clean virtualenv outside
the repository (its dependencies borrowed from the project's environment, rigsim itself only from
the wheel), `rigsim rig list` and the analytic campaign run from an unrelated folder."""

import os
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_wheel_ships_the_default_rigs(tmp_path):
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q", "-w", str(wheels)], check=True,
                   capture_output=True, timeout=600)
    whl = next(wheels.glob("rigsim-*.whl"))
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    py = venv / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "--no-deps", "-q", str(whl)], check=True, capture_output=True,
                   timeout=300)
    # the dependencies (mitsuba, numpy, …) from this environment, without its editable rigsim
    deps = sysconfig.get_paths()["purelib"]
    target = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                            capture_output=True, text=True, check=True).stdout.strip()
    Path(target, "zz_rigsim_test_deps.pth").write_text(deps + "\n" + "\n".join(site.getsitepackages()) + "\n")
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    where = subprocess.run([str(py), "-c", "import rigsim; print(rigsim.__file__)"], cwd=work, env=env,
                           capture_output=True, text=True, check=True).stdout
    assert str(venv) in where, where
    rigsim = venv / "bin" / "rigsim"
    out = subprocess.run([str(rigsim), "rig", "list"], cwd=work, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    for name in ("sun_sensor_2axis_diaphragm", "sun_sensor_3axis_autocollimator", "dual_line_array_prism", "star_sensor"):
        assert name in out.stdout
    # doctor and --help point at what the wheel installed, not at a repository's scenes/ the user does not have
    import json as _json

    doc = _json.loads(subprocess.run([str(rigsim), "doctor", "--json"], cwd=work, env=env, capture_output=True, text=True,
                                     timeout=300, check=True).stdout)
    assert doc["default rigs"].startswith(str(venv)) and Path(doc["default rigs"].split(" (")[0], "star_sensor.toml").is_file()
    assert "rigsim rig list" in subprocess.run([str(rigsim), "--help"], cwd=work, env=env, capture_output=True, text=True,
                                               timeout=300).stdout
    run = subprocess.run([str(rigsim), "run", "cube-mirror", "--analytic", "--no-budget"], cwd=work, env=env,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "R(cube←sun) composed" in run.stdout
    # a rig file of the same name in the current folder wins over the packaged one
    (work / "sun_sensor_2axis_diaphragm.toml").write_text("name = 'broken'\n")
    bad = subprocess.run([str(rigsim), "rig", "check", "sun_sensor_2axis_diaphragm"], cwd=work, env=env,
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and str(work) in bad.stderr
