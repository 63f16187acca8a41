"""Seed 003 on a user's files: the orbit scenario's ROI frames, written as bare renamed files, go
through `rigsim boresight centroid` and `solve` and give the in-process (Δf, α, β, γ) to 1e-9
relative; the streaming mode gives the same rows; bad tables are one line."""

import json
import shutil

import numpy as np
import pytest
from file_chain import rigsim, rigsim_in_process

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

    # in this process (the frames are the same for any worker count: tests/procedures/boresight/test_frame_pool.py),
    # at 64 spp, not the rig's 256: the chain must give the in-process numbers whatever the frames' noise (13 → 5 s)
    res = run_orbit(rig, seed=11, measurements=3, jitter_px=0.0, on_frame=export, workers=1, spp=64)
    return rig, res, files, d


def test_orbit_frames_round_trip(orbit, tmp_path):
    """The file chain in subprocesses, as a lab runs it: `boresight centroid` per camera and stage, `boresight
    solve` (table, JSON and --stream) — the in-process orbit's estimates to 1e-9, the fit judged (the reference
    rows' scatter against the tables' σ, every spot inside its ROI window). The first `centroid` and the two
    `solve` runs as subprocesses; the other centroid tables and the refused solve through `rigsim.cli.main` in
    this process."""
    rig, res, files, _ = orbit
    outs = {}
    for cam in [c.name for c in rig.cameras]:
        for stage, tag in (("reference", "ref"), ("measurement", "meas")):
            ks = sorted(k for (s, c, j, k) in files if s == stage and c == cam and j == 0)
            m1 = [str(files[(stage, cam, 0, k)]) for k in ks]
            m2 = [str(files[(stage, cam, 1, k)]) for k in ks]
            outs[(cam, tag)] = tmp_path / f"{tag}_{cam}.csv"
            run = rigsim if not outs.keys() - {(cam, tag)} else rigsim_in_process  # the first as a subprocess
            run("boresight", "centroid", "--camera", cam, "--m1", *m1, "--m2", *m2, "--out", outs[(cam, tag)])
    cams = [c.name for c in rig.cameras]
    refs, meas = [str(outs[(c, "ref")]) for c in cams], [str(outs[(c, "meas")]) for c in cams]
    p = rigsim("boresight", "solve", "--reference", *refs, "--measured", *meas, "--out", tmp_path / "est.csv",
               "--json-out", tmp_path / "est.json")
    assert "fit: χ²/dof" in p.stdout and "POOR" not in p.stdout
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
    text = (outs[(cams[0], "meas")]).read_text()
    p = rigsim("boresight", "solve", "--reference", outs[(cams[0], "ref")], "--stream", stdin=text)
    lines = p.stdout.strip().splitlines()
    assert lines[0] == "sample,camera,delta_f_um,alpha_arcsec,beta_arcsec,gamma_arcsec" and len(lines) == 4
    s = np.array([[float(x) for x in ln.split(",")[2:]] for ln in lines[1:]])
    ref = np.column_stack([dv["delta_f_um"][0], np.array(dv["camera_angles_arcsec"][0])])
    np.testing.assert_allclose(s, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    # the one result shape: --json-out validates against the packaged schema, carries the tables' σ and gives the
    # in-process relative angles
    from importlib.resources import files as pkg_files

    import jsonschema

    schema = json.loads(pkg_files("rigsim").joinpath("schemas/boresight-result.schema.json").read_text())
    js = json.loads((tmp_path / "est.json").read_text())
    jsonschema.validate(js, schema)
    assert js["mode"] == "files" and "sigma_* columns" in js["centroid_sigma_source"]
    assert len(js["samples"]) == 6 and len(js["relative"]) == 3
    assert all(x["R_ref_from_meas"].get("true_matrix") is None for x in js["samples"])
    np.testing.assert_allclose([r["angles_arcsec"] for r in js["relative"]], dv["relative_arcsec"], atol=1e-9)
    n_ref = rig.orbit.reference_frames
    assert js["fit"]["dof"] == 4 * (n_ref - 1) * 2 and js["fit"]["verdict"] in ("good", "scaled")
    # u and v swapped in a reference table: every spot leaves its ROI window; refused, nothing written, named
    swapped = tmp_path / "ref_swapped.csv"
    swapped.write_text(outs[(cams[0], "ref")].read_text().replace("u_m1_px,v_m1_px,u_m2_px,v_m2_px",
                                                                   "v_m1_px,u_m1_px,v_m2_px,u_m2_px"))
    p = rigsim_in_process("boresight", "solve", "--reference", swapped, "--measured", outs[(cams[0], "meas")], "--out",
                          tmp_path / "bad.csv", ok=(3,))
    assert "outside the nominal 48-px ROI windows" in p.stderr and "The data fit when read as: u and v swapped" in p.stderr
    assert not (tmp_path / "bad.csv").exists()


def test_boresight_covariance_matches_a_monte_carlo_of_the_estimator():
    """The propagated (Δf, α, β, γ) covariance against the scatter of 3000 DVAD solutions with Gaussian centroid
    noise (σ 0.1 px measured, 0.1/√20 px reference) around a perturbed state: every σ within 6 % (the
    Monte-Carlo's own error is ~1.3 %)."""
    from rigsim.estimation.dvad import estimate
    from rigsim.optics.line_camera import CameraGeometry, rotation_xyz
    from rigsim.procedures.boresight.result_json import propagated_covariances
    from rigsim.procedures.boresight.studies import spots_uv
    from rigsim.rig.load import load_boresight_rig

    g = CameraGeometry.from_rig(load_boresight_rig().cameras[0])
    a = 10.0 / 206264.80624709636
    ref_true = spots_uv(g)
    meas_true = spots_uv(g, rotation_xyz(a, -a, 2 * a), 0.01)
    s_m, s_r = 0.1, 0.1 / np.sqrt(20)
    C = propagated_covariances(g, ref_true, meas_true[None], s_m, s_r)[0]
    rng = np.random.default_rng(3)
    n = 3000
    e = estimate(g, ref_true + rng.normal(0, s_r, (n, 2, 2)), meas_true + rng.normal(0, s_m, (n, 2, 2)))
    P = np.column_stack([e.delta_f_mm * 1e3, e.angles_arcsec])
    np.testing.assert_allclose(P.std(axis=0, ddof=1), np.sqrt(np.diag(C)), rtol=0.06)


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


def test_the_rendered_orbit_result_has_the_same_shape_with_its_truth(orbit):
    """run boresight's result blocks (orbit_result_json): the same schema, the truth beside each estimate, errors
    equal to the orbit scenario's own (relative angle, Δf), and σ measured on the rendered reference frames."""
    from importlib.resources import files as pkg_files

    import jsonschema

    from rigsim.procedures.boresight.result_json import orbit_result_json

    rig, res, _, _ = orbit
    js = json.loads(json.dumps(orbit_result_json(rig, res["_spots"], seed=11, reading="consistent")))
    jsonschema.validate(js, json.loads(pkg_files("rigsim").joinpath("schemas/boresight-result.schema.json").read_text()))
    dv = res["estimates"]["dvad"]
    np.testing.assert_allclose([r["R_change"]["error_arcsec"] for r in js["relative"]], dv["relative_error_arcsec"],
                               atol=1e-7)
    for c, cam in enumerate(x.name for x in rig.cameras):
        got = [x["delta_f_error_um"] for x in js["samples"] if x["camera"] == cam]
        np.testing.assert_allclose(got, dv["delta_f_error_um"][c], atol=1e-9)
    assert "reference frames" in js["centroid_sigma_source"]
    sig = np.array([r["R_change"]["covariance"]["sigma"] for r in js["relative"]])
    assert np.all(sig > 0) and np.all(sig < 0.05)  # arcsec: 0.1″-class monitoring from ~0.01 px centroids
