"""Seeds 000/001 on a user's files: the frames of a rendered campaign, copied out as bare renamed
files with the turntable readings as CSV, go through `rigsim centroid`, `calibrate sun-sensor`,
`triad` and `compose` and give the in-process campaign's rotations to 1e-9 relative. Also a
user's centroider inside the campaign, and one-line errors for bad files."""

import json
import shutil
import sys

import numpy as np
import pytest

from rigsim.cli import main
from rigsim.files import Column, read_table, write_table

RIGS = {"000": "sun_sensor_2axis_diaphragm", "001": "sun_sensor_3axis_autocollimator"}


def _rename(src, dst):
    """The exported frames under new names (img_<k>.png) with the logs rewritten: no sidecars."""
    dst.mkdir()
    t = read_table(src / "angles.csv", [Column("frame", kind="str")])
    names = {f: f"img_{k:03d}{f[-4:]}" for k, f in enumerate(reversed(list(t["frame"])))}
    cols = {k: v for k, v in t.items() if k != "__line__"}
    for f, g in names.items():
        shutil.copy(src / f, dst / g)
    cols["frame"] = [names[f] for f in cols["frame"]]
    write_table(dst / "angles.csv", cols)
    shutil.copy(src / "nulls.csv", dst / "nulls.csv")
    return dst


def _assert_rel(a, b, rel=1e-9):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert np.max(np.abs(a - b)) <= rel * np.max(np.abs(b)), np.max(np.abs(a - b))


def _file_route(d, rig, capsys):
    frames = sorted(str(p) for p in d.glob("img_*"))
    assert main(["centroid", *frames, "--rig", rig, "--angles", str(d / "angles.csv"), "--out", str(d / "c.csv"),
                 "--quiet"]) == 0
    assert main(["calibrate", "sun-sensor", "--rig", rig, "--angles", str(d / "angles.csv"), "--centroids",
                 str(d / "c.csv"), "--out", str(d / "sun.json"), "--opencv", str(d / "cam.yml")]) == 0
    assert main(["triad", "--nulls", str(d / "nulls.csv"), "--rig", rig, "--out", str(d / "cube.json")]) == 0
    assert main(["compose", "--cube-from-rot", str(d / "cube.json"), "--sun-from-rot", str(d / "sun.json"),
                 "--out", str(d / "cs.json")]) == 0
    capsys.readouterr()
    out = {k: json.loads((d / f).read_text()) for k, f in (("sun", "sun.json"), ("cube", "cube.json"), ("cs", "cs.json"))}
    _validate_stages(out)
    return out


def _validate_stages(out):
    """Each stage's JSON against the packaged schema; a stage's block missing is caught."""
    from importlib.resources import files

    import jsonschema

    schema = json.loads(files("rigsim").joinpath("schemas/cube-mirror-stages.schema.json").read_text())
    for rec in out.values():
        jsonschema.validate(rec, schema)
    assert [r["format"] for r in out.values()] == ["rigsim.sun-sensor-calibration/1", "rigsim.triad/1", "rigsim.compose/1"]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({k: v for k, v in out["cube"].items() if k != "R_cube_from_rot"}, schema)


def _null_frames_round_trip(exp, tmp_path, rig, capsys):
    """Every null-search frame, renamed, through `concentricity` / `autocollimator read`: the campaign's
    measured offset (px) or reading (arcsec) to 1e-9 relative."""
    t = read_table(exp / "null_frames.csv", [Column("frame", kind="str"), Column("kind", kind="str"),
                                             Column("face", kind="str", required=False)])
    assert len(t["frame"]) >= 4
    d = tmp_path / "nulls"
    d.mkdir()
    for i, (f, kind) in enumerate(zip(t["frame"], t["kind"])):
        shutil.copy(exp / f, d / f"n{i:03d}.png")
    unit = "px" if "measured_x_px" in t else "arcsec"
    want = np.column_stack([t[f"measured_x_{unit}"].astype(float), t[f"measured_y_{unit}"].astype(float)])
    flats = [str(d / f"n{i:03d}.png") for i, kind in enumerate(t["kind"]) if kind == "aiming-flat"]  # the screen's
    i = 0
    while i < len(t["frame"]):
        if t["kind"][i] == "aiming-flat":
            i += 1
            continue
        if t["kind"][i] == "aiming-hole":
            assert main(["concentricity", str(d / f"n{i:03d}.png"), str(d / f"n{i + 1:03d}.png"), "--rig", rig,
                         "--face", str(t["face"][i]), "--json", str(d / "r.json"), "--flat", *flats]) == 0
            got = json.loads((d / "r.json").read_text())["offset_px"]
            i += 2
        else:
            assert main(["autocollimator", "read", str(d / f"n{i:03d}.png"), "--rig", rig, "--json", str(d / "r.json")]) == 0
            got = json.loads((d / "r.json").read_text())["reading_arcsec"]
            i += 1
        _assert_rel(got, want[i - 1])
    capsys.readouterr()


def _round_trip(tmp_path, seed, capsys, extra=()):
    """The campaign at 64 spp: the forward-model centroids' σ is the detector's bound, and at 16 spp the
    renderer's own sampling noise exceeds it (the sweep fit would be judged poor and refused)."""
    rig = RIGS[seed]
    exp, rep = tmp_path / "export", tmp_path / "report"
    # seed 001's rig: the turntable's errors the nominal model leaves out are 3–4× the forward-model
    # centroids' σ; a 15° sweep judges that poor (χ²/dof above 25), the procedure's 5° sweep "scaled" (15)
    step = "15" if seed == "000" else "5"
    assert main(["run", "cube-mirror", "--rig", rig, "--sweep-step", step, "--sweep-spp", "64", "--no-budget",
                 "--repeat-frames", "0", "--export-frames", str(exp), "--out", str(rep), "--quiet", *extra]) == 0
    camp = json.loads((rep / "campaign.json").read_text())
    out = _file_route(_rename(exp, tmp_path / "bare"), rig, capsys)
    _assert_rel(out["sun"]["R_sun_from_rot"]["matrix"], camp["R_sun_from_rot"]["matrix"])
    _assert_rel(out["cube"]["R_cube_from_rot"]["matrix"], camp["R_cube_from_rot"]["matrix"])
    _assert_rel(out["cs"]["R_cube_from_sun"]["matrix"], camp["R_cube_from_sun"]["matrix"])
    _null_frames_round_trip(exp, tmp_path, RIGS[seed], capsys)
    i = out["sun"]["intrinsics"]
    _assert_rel([i["fx_px"], i["fy_px"], i["cx_px"], i["cy_px"]], [camp["intrinsics"][k] for k in ("fx", "fy", "cx", "cy")])
    # the propagated covariance: R(cube←sun)'s is the sum of the two inputs' (the rotation preserves the trace)
    tr = [np.trace(np.array(out[k][b]["covariance"]["matrix"]))
          for k, b in (("cube", "R_cube_from_rot"), ("sun", "R_sun_from_rot"), ("cs", "R_cube_from_sun"))]
    assert tr[2] == pytest.approx(tr[0] + tr[1], rel=1e-12)
    # the campaign's own JSON carries the same rotations with the same covariances as the file stages
    for k, b in (("cube", "R_cube_from_rot"), ("sun", "R_sun_from_rot"), ("cs", "R_cube_from_sun")):
        _assert_rel(camp[b]["covariance"]["matrix"], out[k][b]["covariance"]["matrix"], rel=1e-6)
    assert camp["format"] == "rigsim.cube-mirror-campaign/1" and camp["mode"] == "rendered"
    return out, camp, rep


@pytest.mark.slow
@pytest.mark.render
@pytest.mark.parametrize("seed", ["000", "001"])
def test_campaign_frames_round_trip_through_the_commands(tmp_path, seed, capsys):
    _round_trip(tmp_path, seed, capsys)


@pytest.mark.slow
@pytest.mark.render
def test_user_centroider_in_the_campaign(tmp_path, capsys, monkeypatch):
    """A user's centroider (a plain thresholded first moment) on the same frames: its centroid error
    and end-to-end error appear beside rigsim's in the report, and --import-centroids of the same
    numbers gives the same result."""
    (tmp_path / "mycent.py").write_text(
        "import numpy as np\n"
        "def com(img):\n"
        "    a = img.astype(float) - 64.0\n"
        "    a[a < 10] = 0\n"
        "    v, u = np.indices(a.shape)\n"
        "    return (u * a).sum() / a.sum(), (v * a).sum() / a.sum()\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop("mycent", None)
    out, camp, rep = _round_trip(tmp_path, "000", capsys, extra=("--centroider", "mycent:com"))
    user = json.loads((rep / "campaign.json").read_text())["user_centroider"]
    assert "## Your centroider beside rigsim's" in (rep / "report.md").read_text()
    # the plain first moment is biased by the disk's pixel phase: worse than the S-curve corrected one
    assert user["user"]["centroids"]["n"] == user["rigsim"]["centroids"]["n"] > 40
    assert np.mean(user["user"]["centroids"]["rms_px"]) > np.mean(user["rigsim"]["centroids"]["rms_px"])
    # the same centroids imported as a table give the same end-to-end numbers
    import mycent

    from rigsim.files import read_image

    exp = tmp_path / "export"
    t = read_table(exp / "angles.csv", [Column("frame", kind="str")])
    uv = [mycent.com(read_image(exp / f)) for f in t["frame"]]
    write_table(tmp_path / "mine.csv", {"frame": list(t["frame"]), "u_px": [p[0] for p in uv], "v_px": [p[1] for p in uv]})
    rep2 = tmp_path / "report2"
    assert main(["run", "cube-mirror", "--sweep-step", "15", "--sweep-spp", "16", "--no-budget", "--repeat-frames", "0",
                 "--import-centroids", str(tmp_path / "mine.csv"), "--out", str(rep2), "--quiet"]) == 0
    user2 = json.loads((rep2 / "campaign.json").read_text())["user_centroider"]
    _assert_rel(user2["user"]["R_cube_from_sun_error_arcsec"], user["user"]["R_cube_from_sun_error_arcsec"], 1e-9)


@pytest.mark.parametrize("edit, message", [
    (lambda d: (d / "angles.csv").write_text((d / "angles.csv").read_text().replace("x_deg", "x_rad")),
     r"angles\.csv: column x_rad: expected x_deg \(degrees\), got radians"),
    (lambda d: (d / "c.csv").write_text((d / "c.csv").read_text().replace("img_000.png", "ghost.png")),
     r"c\.csv: line \d+, column frame: 'ghost\.png' has no row in the angle log"),
    (lambda d: (d / "angles.csv").write_text((d / "angles.csv").read_text().replace("img_003.png,", "img_003.png,abc")),
     r"angles\.csv: line 5, column x_deg: 'abc-13\.3+2' is not a number"),
    (lambda d: (d / "angles.csv").write_text((d / "angles.csv").read_text().replace("img_003.png,", "img_004.png,")),
     r"angles\.csv: line 6, column frame: 'img_004\.png' already on line 5; one row per frame"),
    (lambda d: (d / "c.csv").write_text((d / "c.csv").read_text().replace("u_px", "u_mm")),
     r"c\.csv: column u_mm: expected u_px \(pixels\), got millimetres"),
    (lambda d: write_table(d / "c.csv", {"frame": [f"img_{k:03d}.png" for k in range(10)], "u_px": np.linspace(100, 900, 10),
                                         "v_px": np.full(10, 511.5), "sigma_u_px": np.r_[np.full(9, 0.01), -0.5],
                                         "sigma_v_px": np.full(10, 0.01)}),
     r"c\.csv: line 11, column sigma_u_px: -0\.5; expected ≥ 0 px or empty"),
])
def test_bad_logs_one_line(tmp_path, capsys, edit, message):
    d = tmp_path
    write_table(d / "angles.csv", {"frame": [f"img_{k:03d}.png" for k in range(10)], "x_deg": np.linspace(-40, 40, 10),
                                   "y_deg": np.zeros(10)})
    write_table(d / "c.csv", {"frame": [f"img_{k:03d}.png" for k in range(10)], "u_px": np.linspace(100, 900, 10),
                              "v_px": np.full(10, 511.5)})
    edit(d)
    rc = main(["calibrate", "sun-sensor", "--angles", str(d / "angles.csv"), "--centroids", str(d / "c.csv"),
               "--out", str(d / "sun.json")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1
    import re

    assert re.search(message, err), err


def test_triad_3axis_and_compose_covariance(tmp_path, capsys):
    """TRIAD on a 3-axis table from a null log, its covariance against a Monte Carlo of the same
    reading errors, and compose's propagation against a Monte Carlo of both inputs."""
    from scipy.spatial.transform import Rotation

    from rigsim.estimation.cube_attitude import cube_from_rot_triad
    from rigsim.frames import ARCSEC_PER_RAD
    from rigsim.rig.turntable import TurntableReading

    # two nulls of one cube (their normals 90° apart within the readings' σ: TRIAD's fit is judged)
    write_table(tmp_path / "nulls.csv", {"face": ["+X", "+Y"], "y_deg": [-90.2, 0.0], "x_deg": [0.1, 89.7], "z_deg": [5.0, 5.0]})
    assert main(["triad", "--nulls", str(tmp_path / "nulls.csv"), "--rig", RIGS["001"], "--out", str(tmp_path / "c.json"),
                 "--sigma-arcsec", "10"]) == 0
    res = json.loads((tmp_path / "c.json").read_text())
    R = np.array(res["R_cube_from_rot"]["matrix"])
    C = np.array(res["R_cube_from_rot"]["covariance"]["matrix"])
    rng = np.random.default_rng(0)
    base = [{"Y": np.radians(-90.2), "X": np.radians(0.1), "Z": np.radians(5.0)},
            {"Y": np.radians(0.0), "X": np.radians(89.7), "Z": np.radians(5.0)}]
    d = []
    for _ in range(3000):
        rr = [TurntableReading({k: v + rng.normal(0, 10 / ARCSEC_PER_RAD) for k, v in b.items()}) for b in base]
        Ri, _, _ = cube_from_rot_triad(rr, ["+X", "+Y"], "YXZ")
        d.append(Rotation.from_matrix(Ri @ R.T).as_rotvec() * ARCSEC_PER_RAD)
    S = np.cov(np.array(d).T)
    # 3000 samples: each variance within ±8 % (5σ of a sample variance is ±13 %)
    np.testing.assert_allclose(np.diag(S), np.diag(C), rtol=0.13)
    # compose: the sun calibration as a second input with its own covariance
    # a sun calibration whose covariance dominates and is anisotropic: its rotation into the cube frame matters
    Cs = np.diag([400.0, 2500.0, 25.0])
    sun = {"R_sun_from_rot": {"matrix": Rotation.from_euler("xz", [30, 12], degrees=True).as_matrix().tolist(),
                              "covariance": {"matrix": Cs.tolist()}}}
    (tmp_path / "s.json").write_text(json.dumps(sun))
    assert main(["compose", "--cube-from-rot", str(tmp_path / "c.json"), "--sun-from-rot", str(tmp_path / "s.json"),
                 "--out", str(tmp_path / "cs.json")]) == 0
    cs = json.loads((tmp_path / "cs.json").read_text())["R_cube_from_sun"]
    Rs = np.array(sun["R_sun_from_rot"]["matrix"])
    L1, L2 = np.linalg.cholesky(C), np.linalg.cholesky(Cs)
    Rcs = R @ Rs.T
    d = []
    for _ in range(3000):
        a = Rotation.from_rotvec(L1 @ rng.normal(size=3) / ARCSEC_PER_RAD).as_matrix() @ R
        b = Rotation.from_rotvec(L2 @ rng.normal(size=3) / ARCSEC_PER_RAD).as_matrix() @ Rs
        d.append(Rotation.from_matrix(a @ b.T @ Rcs.T).as_rotvec() * ARCSEC_PER_RAD)
    got = np.array(cs["covariance"]["matrix"])
    S = np.cov(np.array(d).T)
    # 3000 draws: a variance is known to ±2.6 % (1σ); 10 % is 4σ. Off-diagonals within 10 % of the scale.
    np.testing.assert_allclose(np.diag(S), np.diag(got), rtol=0.10)
    np.testing.assert_allclose(S, got, atol=0.10 * np.sqrt(np.outer(np.diag(got), np.diag(got))).max())
    capsys.readouterr()
    (tmp_path / "bad.json").write_text(json.dumps({"R_sun_from_rot": {"matrix": np.diag([1, 1, -1]).tolist(),
                                                                       "covariance": {"matrix": np.eye(3).tolist()}}}))
    assert main(["compose", "--cube-from-rot", str(tmp_path / "c.json"), "--sun-from-rot", str(tmp_path / "bad.json")]) == 2
    assert "R_sun_from_rot.matrix is not a rotation (det -1.000000)" in capsys.readouterr().err


def test_compose_returns_a_known_cube_from_sun(tmp_path):
    """A known answer: R(cube←sun) chosen, R(sun←rot) chosen, and R(cube←rot) = R(cube←sun)·R(sun←rot) built from
    them (scipy's composition); `compose` must give back the chosen R(cube←sun) and, with exact inputs, a
    covariance Σ_cube + R·Σ_sun·Rᵀ whose trace is the two traces' sum. The rotations do not commute (the
    product in the wrong order, R(sun←rot)ᵀ·R(cube←rot), is 23° away), and a vector of the sun sensor's frame
    lands where both rotations applied one after the other put it."""
    from scipy.spatial.transform import Rotation

    cube_from_sun = Rotation.from_euler("ZYX", [40.0, -25.0, 10.0], degrees=True)
    sun_from_rot = Rotation.from_euler("xyz", [0.35, -0.6, 12.0], degrees=True) * Rotation.from_euler("y", 30, degrees=True)
    cube_from_rot = cube_from_sun * sun_from_rot
    Cc, Cs = np.diag([4.0, 9.0, 1.0]), np.diag([400.0, 2500.0, 25.0])
    (tmp_path / "c.json").write_text(json.dumps({"R_cube_from_rot": {"matrix": cube_from_rot.as_matrix().tolist(),
                                                                     "covariance": {"matrix": Cc.tolist()}}}))
    (tmp_path / "s.json").write_text(json.dumps({"R_sun_from_rot": {"matrix": sun_from_rot.as_matrix().tolist(),
                                                                    "covariance": {"matrix": Cs.tolist()}}}))
    assert main(["compose", "--cube-from-rot", str(tmp_path / "c.json"), "--sun-from-rot", str(tmp_path / "s.json"),
                 "--out", str(tmp_path / "cs.json")]) == 0
    got = json.loads((tmp_path / "cs.json").read_text())["R_cube_from_sun"]
    R = np.array(got["matrix"])
    np.testing.assert_allclose(R, cube_from_sun.as_matrix(), atol=1e-12)
    v_sun = np.array([0.3, -0.2, 0.93])
    np.testing.assert_allclose(R @ v_sun, cube_from_rot.apply(sun_from_rot.inv().apply(v_sun)), atol=1e-12)
    wrong = sun_from_rot.inv() * cube_from_rot
    assert np.degrees((wrong * cube_from_sun.inv()).magnitude()) > 20.0
    assert np.trace(np.array(got["covariance"]["matrix"])) == pytest.approx(np.trace(Cc) + np.trace(Cs), rel=1e-12)
