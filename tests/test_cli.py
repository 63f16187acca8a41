import json
import subprocess
import sys

import numpy as np
import pytest

import rigsim
from file_chain import rigsim_in_process
from rigsim.cli import main


def run(*args, subprocess_run: bool = True):
    """``python -m rigsim.cli ARGS`` as a user runs it, or (``subprocess_run`` False: the cases after a test's
    first) through :func:`rigsim.cli.main` in this process, the same body without the interpreter's start-up."""
    if not subprocess_run:
        return rigsim_in_process(*args, ok=range(256))
    return subprocess.run([sys.executable, "-m", "rigsim.cli", *args], capture_output=True, text=True, timeout=300)


def test_version_and_help():
    r = run("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"rigsim {rigsim.__version__}"
    r = run("--help")
    assert r.returncode == 0 and "run" in r.stdout and "triad" in r.stdout and "doctor" in r.stdout and "examples:" in r.stdout
    r = run("run", "cube-mirror", "--help")
    assert r.returncode == 0 and "--analytic" in r.stdout and "--seed" in r.stdout


def test_triad_table1(capsys):
    assert main(["triad", "181.398", "0.528", "91.386", "-0.048", "--json"]) == 0
    out = capsys.readouterr().out
    data = json.loads(out.strip().splitlines()[-1])
    R = np.array(data["R_cube_from_rot"]["matrix"])
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert data["axis_order"] == "XY"
    assert data["normal_angle_deg"] == pytest.approx(90.0121, abs=1e-4)
    assert "the other reading (YX) differs by 1.05" in out
    assert data["eq8"] == "beam" and not data["triad_conditioning"]["degenerate"] and "DEGENERATE" not in out


def test_triad_printed_eq8_reports_its_degeneracy(capsys):
    assert main(["triad", "181.398", "0.528", "91.386", "-0.048", "--eq8", "printed", "--json"]) == 0
    out = capsys.readouterr().out
    data = json.loads(out.strip().splitlines()[-1])
    assert data["eq8"] == "printed" and data["triad_conditioning"]["degenerate"]
    assert data["normal_angle_deg"] == pytest.approx(0.576, abs=1e-3)
    assert "DEGENERATE: r1 and r2 are 0.576° apart" in out and "amplified ×99" in out
    assert "rigsim's reading (beam) differs by 88.799" in out


@pytest.mark.parametrize("args,expected", [
    (["triad", "181.398", "0.528", "91.386", "500"], "θ4 = 500.0: allowed range is -360 to 360 degrees"),
    (["triad", "1", "2", "3", "4", "--axis-order", "ZX"], "--axis-order = 'ZX': allowed for this 2-axis table: XY, YX"),
    (["run", "cube-mirror", "--rig", "nope"], "no such rig file"),
    (["run", "cube-mirror", "--trials", "1"], "--trials = 1: allowed range is 2 to 100000"),
    (["run", "cube-mirror", "--axis-order", "XZ", "--no-budget"], "--axis-order = 'XZ': must be a permutation"),
])
def test_bad_cli_input_is_a_clear_error(args, expected):
    r = run(*args, subprocess_run=args[0] == "triad")
    assert r.returncode == 2
    assert expected in r.stderr
    assert "Traceback" not in r.stderr


def test_bad_rig_file_via_cli(tmp_path):
    p = tmp_path / "r.toml"
    p.write_text((rigsim.rig.load.SCENES_DIR / "sun_sensor_2axis_diaphragm.toml").read_text().replace("edge_mm = 25.0", "edge_mm = -25.0"))
    r = run("rig", "check", str(p))
    assert r.returncode == 2 and "field `cube.edge_mm` = -25.0" in r.stderr and "> 0" in r.stderr


def test_run_ideal_analytic_prints_truth_vs_recovered(tmp_path):
    out = tmp_path / "res.json"
    r = run("run", "cube-mirror", "--analytic", "--ideal", "--no-budget", "--json-out", str(out))
    assert r.returncode == 0, r.stderr
    assert "Truth vs recovered" in r.stdout and "R(cube←sun) composed" in r.stdout
    res = json.loads(out.read_text())
    assert np.abs(res["error_arcsec"]).max() < 1e-6


def test_run_with_budget_is_reproducible(tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    for p, sub in ((a, True), (b, False)):  # as a subprocess, then through the same body in this process
        r = run("run", "cube-mirror", "--analytic", "--trials", "20", "--seed", "5", "--quiet", "--json-out", str(p),
                subprocess_run=sub)
        assert r.returncode == 0, r.stderr
    ja, jb = json.loads(a.read_text()), json.loads(b.read_text())
    assert ja == jb
    names = [row["source"] for row in ja["budget"]]
    assert names[0].startswith("σ1") and names[-1] == "all sources together"
    assert "Error budget by Monte Carlo" in r.stdout


def test_doctor_never_crashes():
    r = run("doctor", "--json")
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["rigsim"] == rigsim.__version__ and "python" in info


def test_render_sun_sensor_cli(tmp_path):
    r = run("render", "sun-sensor", "--pose", "X=10,Y=-5", "--spp", "256", "--out", str(tmp_path), "--preview", str(tmp_path / "p.png"))
    assert r.returncode == 0, r.stderr
    side = json.loads((tmp_path / "sun_sensor.json").read_text())
    assert side["pose"] == {"X": 10.0, "Y": -5.0} and side["render"]["spp"] == 256
    assert (tmp_path / "sun_sensor.png").exists() and (tmp_path / "p.png").exists()
    # the frame itself: its spot where the rig file's sun sensor sees the sun at that pose (the truth layer's
    # realisation, projected by OpenCV), to the rendering and detector noise
    import cv2

    from rigsim.rig import load_rig
    from rigsim.truth.cube_mirror.realization import realization_from_rig

    rig = load_rig("sun_sensor_2axis_diaphragm")
    real = realization_from_rig(rig)
    pose = {"X": np.radians(10.0), "Y": np.radians(-5.0)}
    s = real.R_sun_from_mount @ (real.turntable.R_rot_from_mount(pose).T @ real.d_sun_rot)
    cam = rig.sun_sensor.camera()
    uv, _ = cv2.projectPoints(s.reshape(1, 1, 3), np.zeros(3), np.zeros(3), cam.camera_matrix(), cam.dist_coeffs())
    dn = cv2.imread(str(tmp_path / "sun_sensor.png"), cv2.IMREAD_UNCHANGED).astype(float) - rig.sun_sensor.detector.offset_dn
    u0, v0 = (int(round(x)) - 8 for x in uv.ravel())
    w = dn[v0:v0 + 17, u0:u0 + 17]
    w[w < 20] = 0
    vv, uu = np.indices(w.shape)
    got = np.array([(uu * w).sum() / w.sum() + u0, (vv * w).sum() / w.sum() + v0])
    assert np.hypot(*(got - uv.ravel())) < 0.15, (got, uv)  # the disk's pixel-phase bias on a 2.5 px spot < 0.1 px


@pytest.mark.parametrize("args,expected", [
    (["render", "sun-sensor", "--pose", "Q=3"], "--pose axis 'Q': this turntable has axes ['X', 'Y']"),
    (["render", "sun-sensor", "--pose", "X=1000"], "--pose X = 1000.0: allowed range is -360.0 to 360.0 degrees"),
    (["render", "sun-sensor", "--pose", "X10"], "expected LABEL=DEGREES"),
    (["render", "sun-sensor", "--spp", "100"], "--spp = 100: must be a power of 4"),
])
def test_bad_render_arguments(args, expected):
    r = run(*args, subprocess_run="Q=3" in args)
    assert r.returncode == 2 and expected in r.stderr and "Traceback" not in r.stderr


def test_broken_pipe_ends_quietly():
    """`rigsim rig list | head -1`: the reader closes the pipe; rigsim stops with the shell's SIGPIPE
    status (141) and no traceback."""
    import subprocess
    import sys

    p = subprocess.Popen([sys.executable, "-c", "import sys; from rigsim.cli import main; sys.exit(main(['rig', 'list']))"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()  # nobody reads: the first write fails with EPIPE
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141 and err == ""
