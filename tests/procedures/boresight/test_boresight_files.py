"""Seed 003 on a user's files: the orbit scenario's ROI frames, written as bare renamed files, go
through `rigsim boresight centroid` and `solve` and give the in-process (Δf, α, β, γ) to 1e-9
relative; the streaming mode gives the same rows; bad tables are one line."""

import io
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from rigsim.cli import main
from rigsim.files import Column, read_table, write_image, write_table


@pytest.fixture(scope="module")
def orbit(tmp_path_factory):
    from rigsim.procedures.boresight.studies import run_orbit
    from rigsim.rig.load import load_boresight_rig

    rig = load_boresight_rig()
    d = tmp_path_factory.mktemp("bs")
    names = [c.name for c in rig.cameras]
    files = {}

    def export(stage, c, j, k, fr):  # renamed: no stage, camera or detector in the name
        p = d / f"roi_{len(files):04d}.png"
        write_image(p, fr.dn)
        files[(stage, names[c], j, k)] = p

    res = run_orbit(rig, seed=11, measurements=3, jitter_px=0.0, on_frame=export)
    return rig, res, files, d


def test_orbit_frames_round_trip(orbit, tmp_path, capsys):
    rig, res, files, _ = orbit
    outs = {}
    for cam in [c.name for c in rig.cameras]:
        for stage, tag in (("reference", "ref"), ("measurement", "meas")):
            ks = sorted(k for (s, c, j, k) in files if s == stage and c == cam and j == 0)
            m1 = [str(files[(stage, cam, 0, k)]) for k in ks]
            m2 = [str(files[(stage, cam, 1, k)]) for k in ks]
            outs[(cam, tag)] = tmp_path / f"{tag}_{cam}.csv"
            assert main(["boresight", "centroid", "--camera", cam, "--m1", *m1, "--m2", *m2,
                         "--out", str(outs[(cam, tag)])]) == 0
    cams = [c.name for c in rig.cameras]
    assert main(["boresight", "solve", "--reference", *(str(outs[(c, "ref")]) for c in cams),
                 "--measured", *(str(outs[(c, "meas")]) for c in cams), "--out", str(tmp_path / "est.csv")]) == 0
    t = read_table(tmp_path / "est.csv", [Column("camera", kind="str"), Column("delta_f", "um"), Column("alpha", "arcsec"),
                                          Column("beta", "arcsec"), Column("gamma", "arcsec")])
    dv = res["estimates"]["dvad"]
    for c, cam in enumerate(cams):
        rows = t["camera"] == cam
        got = np.column_stack([t["delta_f_um"][rows], t["alpha_arcsec"][rows], t["beta_arcsec"][rows], t["gamma_arcsec"][rows]])
        ref = np.column_stack([dv["delta_f_um"][c], np.array(dv["camera_angles_arcsec"][c])])
        assert got.shape == ref.shape == (3, 4)
        assert np.all(np.abs(got - ref) <= 1e-9 * np.abs(ref).max()), np.abs(got - ref).max()
    # streaming: the same rows through stdin/stdout (the cached DVAD solver)
    meas = read_table(outs[(cams[0], "meas")], [Column("camera", kind="str"), Column("u_m1", "px")])
    text = (outs[(cams[0], "meas")]).read_text()
    p = subprocess.run([sys.executable, "-c", "import sys; from rigsim.cli import main; sys.exit(main(sys.argv[1:]))",
                        "boresight", "solve", "--reference", str(outs[(cams[0], "ref")]), "--stream"],
                       input=text, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    lines = p.stdout.strip().splitlines()
    assert lines[0] == "sample,camera,delta_f_um,alpha_arcsec,beta_arcsec,gamma_arcsec" and len(lines) == 1 + len(meas["camera"])
    s = np.array([[float(x) for x in ln.split(",")[2:]] for ln in lines[1:]])
    ref = np.column_stack([dv["delta_f_um"][0], np.array(dv["camera_angles_arcsec"][0])])
    np.testing.assert_allclose(s, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    capsys.readouterr()


@pytest.mark.parametrize("edit, message", [
    (lambda p: p.write_text(p.read_text().replace("u_m1_px", "u_m1_mm")), r"column u_m1_mm: expected u_m1_px \(pixels\), got millimetres"),
    (lambda p: p.write_text(p.read_text().replace("forward,", "sideways,", 1)), r"line 2, column camera: 'sideways'"),
    (lambda p: p.write_text(p.read_text().replace(",forward,100.0", ",forward,nan", 1)), r"line 2, column u_m1_px: 'nan'; expected a finite number"),
])
def test_bad_spot_tables_one_line(tmp_path, capsys, edit, message):
    import re

    ref = tmp_path / "ref.csv"
    write_table(ref, {"sample": ["0"], "camera": ["forward"], "u_m1_px": [100.0], "v_m1_px": [20.0], "u_m2_px": [900.0],
                      "v_m2_px": [20.0]})
    meas = tmp_path / "meas.csv"
    shutil.copy(ref, meas)
    edit(meas)
    rc = main(["boresight", "solve", "--reference", str(ref), "--measured", str(meas)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and re.search(message, err), err


def test_bad_roi_frames_one_line(orbit, tmp_path, capsys):
    rig, _, files, _ = orbit
    one = str(next(iter(files.values())))
    write_image(tmp_path / "small.png", np.zeros((20, 20), np.uint16))
    assert main(["boresight", "centroid", "--camera", "forward", "--m1", one, "--m2", str(tmp_path / "small.png"),
                 "--out", str(tmp_path / "x.csv")]) == 2
    assert "small.png: 20×20 px (width×height); expected 48×48 px" in capsys.readouterr().err
    assert main(["boresight", "centroid", "--camera", "forward", "--m1", one, one, "--m2", one,
                 "--out", str(tmp_path / "x.csv")]) == 2
    assert "--m1 has 2 frames and --m2 1" in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()
