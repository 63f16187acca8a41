"""The cube-mirror file chain closes: a rendered campaign's exported files, run through the commands
as a lab runs them (``python -m rigsim`` in a subprocess, the frames renamed, no sidecars; seed 001's sweep
stages and the null-search frames after each search's first through the same ``rigsim.cli.main`` in this
process), give the
campaign's decisions (each null search's next command and its null) and numbers (the three
rotations to 1e-9 relative, their covariances to 1e-6, the same fit verdicts).

Cheap campaigns (run in-process as `run cube-mirror --export-frames` runs them, without the report): a
±60° sweep every 30° at 64 spp (the forward-model centroids' σ is the detector's Cramér–Rao bound; at
16 spp the renderer's own sampling noise exceeds it and seed 001's sweep fit is judged poor); seed 000 with a coarse aiming camera (400 × 300 px of 60 µm: 1/16 of the
pixels, the same field), seed 001 with the autocollimator's frames at 64 spp."""

import json
import shutil

import numpy as np
import pytest
from file_chain import assert_rel, derived_rig, read, rigsim, rigsim_in_process

from rigsim.cli import main
from rigsim.files import Column, read_table


def _campaign(d, rig_file, fmt, **kw):
    """The rendered campaign in-process, its frames exported as `run cube-mirror --export-frames` does (the
    report and its pictures left out), renamed (reverse order) with the angle log rewritten; its result record."""
    import warnings

    from rigsim.procedures.cube_mirror.rendered_campaign import run_rendered_campaign
    from rigsim.procedures.cube_mirror.result_json import campaign_json
    from rigsim.procedures.cube_mirror.user_frames import CampaignFrames
    from rigsim.rig.load import load_rig
    from rigsim.truth.cube_mirror.realization import realization_from_rig

    rig = load_rig(rig_file)
    frames = CampaignFrames(rig, d / "export", seed=2009, suffix=fmt)
    frames.out_dir.mkdir()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = run_rendered_campaign(rig, realization_from_rig(rig), seed=2009, sweep_spp=64, sweep_step_deg=30.0,
                                  frames=frames, **kw)
    frames.write_logs([s.final_reading_rad for s in c.searches], rig.procedure.faces)
    camp = json.loads(json.dumps({**campaign_json(c.result, rig, mode="rendered", seed=2009),
                                  "searches": [s.as_dict() for s in c.searches]}, default=float))
    bare = d / "bare"
    bare.mkdir()
    t = read_table(d / "export" / "angles.csv", [Column("frame", kind="str")], what="angle log")
    names = {f: f"img_{k:03d}{fmt}" for k, f in enumerate(reversed(list(t["frame"])))}
    for f, g in names.items():
        shutil.copy(d / "export" / f, bare / g)
    text = (d / "export" / "angles.csv").read_text()
    for f, g in names.items():
        text = text.replace(f + ",", g + ",")
    (bare / "angles.csv").write_text(text)
    shutil.copy(d / "export" / "nulls.csv", bare / "nulls.csv")
    return camp, bare


def _stages(bare, rig, frames, run=rigsim):
    """centroid → calibrate sun-sensor → triad → compose, each in its own process (``run=rigsim``; the seed-001
    chain runs the same commands through ``rigsim.cli.main`` in this process)."""
    run("centroid", *frames, "--rig", rig, "--angles", "angles.csv", "--out", "c.csv", "--quiet", cwd=bare)
    run("calibrate", "sun-sensor", "--rig", rig, "--angles", "angles.csv", "--centroids", "c.csv", "--out", "sun.json",
        "--opencv", "cam.yml", cwd=bare)
    run("triad", "--nulls", "nulls.csv", "--rig", rig, "--out", "cube.json", cwd=bare)
    p = run("compose", "--cube-from-rot", "cube.json", "--sun-from-rot", "sun.json", "--out", "cs.json", cwd=bare)
    assert "fit: no fit of its own; its inputs': cube_from_rot" in p.stdout
    return {k: read(bare / f"{k}.json") for k in ("sun", "cube", "cs")}


def _same_numbers(out, camp):
    for k, b in (("sun", "R_sun_from_rot"), ("cube", "R_cube_from_rot"), ("cs", "R_cube_from_sun")):
        assert_rel(out[k][b]["matrix"], camp[b]["matrix"])
        assert_rel(out[k][b]["covariance"]["matrix"], camp[b]["covariance"]["matrix"], rel=1e-6)
        C = np.array(out[k][b]["covariance"]["matrix"])
        assert np.array_equal(C, C.T)  # written exactly symmetric
    i = out["sun"]["intrinsics"]
    assert_rel([i["fx_px"], i["fy_px"], i["cx_px"], i["cy_px"]], [camp["intrinsics"][k] for k in ("fx", "fy", "cx", "cy")])
    # the campaign's sweep fit and the file route's are judged alike
    assert out["sun"]["fit"]["verdict"] == camp["calibration"]["fit"]["verdict"] != "poor"
    # (1e-7: the outlier test's Cauchy-loss judgement is an iterative solve that carries the table's 12 digits less exactly)
    assert out["sun"]["fit"]["chi2_dof"] == pytest.approx(camp["calibration"]["fit"]["chi2_dof"], rel=1e-7)
    assert out["cube"]["fit"]["verdict"] in ("good", "scaled") and out["cs"]["fit"]["inputs"]["sun_from_rot"]


def _decisions(camp):
    """Per null frame (in the search's order): (face, reading, the campaign's decision): 'null' or the next reading."""
    out = []
    for s in camp["searches"]:
        for i, st in enumerate(s["steps"]):
            last = i == len(s["steps"]) - 1
            assert not last or s["converged"]
            out.append((s["face"], st["reading_deg"], "null" if last else s["steps"][i + 1]["reading_deg"]))
    return out


@pytest.fixture(scope="module")
def two_axis(tmp_path_factory):
    d = tmp_path_factory.mktemp("cm2")
    rig = derived_rig("sun_sensor_2axis_diaphragm", d / "rig.toml", {
        r"resolution_px = \[1600, 1200\]": "resolution_px = [400, 300]",
        r"pixel_pitch_um = 15\.0": "pixel_pitch_um = 60.0"})
    camp, bare = _campaign(d, rig, ".tif")
    return d, rig, camp, bare


@pytest.mark.render
def test_two_axis_campaign_closes_through_the_commands(two_axis):
    d, rig, camp, bare = two_axis
    out = _stages(bare, rig, sorted(p.name for p in bare.glob("img_*")))
    _same_numbers(out, camp)
    # every null-search pair through `concentricity`, with the null offset the export records: the campaign's
    # decision (the next command, or this is the null) and its offset
    t = read_table(d / "export" / "null_frames.csv", [Column("frame", kind="str"), Column("kind", kind="str"),
                                                       Column("face", kind="str"), Column("x", "deg"), Column("y", "deg"),
                                                       Column("null_offset_x", "px"), Column("null_offset_y", "px")])
    holes = [i for i, k in enumerate(t["kind"]) if k == "aiming-hole"]
    decisions = _decisions(camp)
    assert len(holes) == len(decisions) >= 3 and any(dec != "null" for *_, dec in decisions)
    # the screen's flat frames (under a lamp), taken once before the first search, for every face
    flats = []
    for j, k in enumerate(t["kind"]):
        if k == "aiming-flat":
            flats.append(f"flat_{len(flats)}.tif")
            shutil.copy(d / "export" / t["frame"][j], bare / flats[-1])
    assert len(flats) == rig_flat_frames(rig) and [k for k in t["kind"][:len(flats)]] == ["aiming-flat"] * len(flats)
    for n, (i, (face, reading, dec)) in enumerate(zip(holes, decisions)):
        shutil.copy(d / "export" / t["frame"][i], bare / f"n{n}h.tif")
        shutil.copy(d / "export" / t["frame"][i + 1], bare / f"n{n}s.tif")
        assert t["face"][i] == face and (t["x_deg"][i], t["y_deg"][i]) == (reading["X"], reading["Y"])
        run = rigsim if n == 0 else rigsim_in_process  # the first pair as a lab runs it, the others through main()
        run("concentricity", f"n{n}h.tif", f"n{n}s.tif", "--rig", rig, "--face", face,
               "--reading", f"X={float(t['x_deg'][i])!r},Y={float(t['y_deg'][i])!r}",
               f"--null-offset-px={float(t['null_offset_x_px'][i])!r},{float(t['null_offset_y_px'][i])!r}", "--json", f"n{n}.json",
               "--flat", *flats, cwd=bare)
        r = read(bare / f"n{n}.json")
        step = next(s for s in camp["searches"] if s["face"] == face)["steps"]
        measured = [s["measured"] for s in step if s["reading_deg"] == reading][0]
        assert_rel(r["offset_from_null_px"], measured)
        assert r["nulled"] == (dec == "null") and r["fit"]["verdict"] == "not judged"
        if dec != "null":
            assert r["next_reading_deg"] == pytest.approx(dec, abs=1e-9)
        # the rendered offset (before the null offset) against the exact trace, near the null (farther, the spot
        # overlaps the hole and loses light into it: docs/campaign.md)
        true = [s["true"] for s in step if s["reading_deg"] == reading][0]
        assert np.hypot(*(np.array(r["offset_px"]) - true)) < 0.2 or np.max(np.abs(true)) > 3.0
    # the OpenCV camera the calibration wrote is read by `rig import-camera` and by OpenCV
    rigsim("rig", "import-camera", "cam.yml", "--rig", rig, "--out", "imported.toml", cwd=bare)
    assert "focal_length_mm" in (bare / "imported.toml").read_text()
    import cv2

    fs = cv2.FileStorage(str(bare / "cam.yml"), cv2.FILE_STORAGE_READ)
    K, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
    i, dd = out_sun_intrinsics(bare)
    assert_rel([K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist[0, 0], dist[0, 1]], [*i, *dd])
    assert int(fs.getNode("image_width").real()) == 1024 and (bare / "sun.residuals.png").stat().st_size > 10_000


def rig_flat_frames(rig) -> int:
    from rigsim.rig.load import load_rig

    return load_rig(rig).aiming_camera.flat_frames


def out_sun_intrinsics(bare):
    sun = read(bare / "sun.json")
    i = sun["intrinsics"]
    assert sun["n_frames"] + sun["n_outliers"] + sun["n_outside_field"] + sun["n_rejected"] == 19
    return [i["fx_px"], i["fy_px"], i["cx_px"], i["cy_px"]], [sun["distortion"]["k1"], sun["distortion"]["k2"]]


def test_bad_null_frames_one_line(two_axis, tmp_path, capsys):
    """A frame of the wrong size, a rig without an aiming camera, a missing frame: exit 2, one line."""
    from rigsim.files import write_image

    d, rig, _, _ = two_axis
    first = sorted(p.name for p in (d / "export").glob("aiming-hole_*.tif"))[0]  # after the flats
    k = int(first.split("_")[1].split(".")[0])
    hole, spot = str(d / "export" / first), str(d / "export" / f"aiming-spot_{k + 1:03d}.tif")
    write_image(tmp_path / "small.png", np.zeros((100, 100), np.uint16))
    shutil.copy(hole, tmp_path / "dark.tif")  # a hole frame given as the flat
    for args, msg in ((["autocollimator", "read", str(tmp_path / "small.png")],
                       "small.png: 100×100 px (width×height); expected 1280×1024 px"),
                      (["concentricity", hole, spot, "--rig", "sun_sensor_3axis_autocollimator"], "no aiming camera"),
                      (["concentricity", hole, str(tmp_path / "nope.png"), "--rig", str(rig)], "nope.png: no such file"),
                      (["concentricity", hole, spot, "--rig", str(rig), "--flat", str(tmp_path / "dark.tif")],
                       "dark.tif: --flat: flat field: median level 0 DN above the dark frame; the screen is not lit")):
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert msg in err and len(err.splitlines()) == 1, err


@pytest.mark.render
@pytest.mark.slow  # seed 000's chain runs every command in the default stage; seed 001's adds the autocollimator's (also read by the dataset tests)
def test_three_axis_campaign_closes_through_the_commands(tmp_path):
    """Seed 001 (PNG frames; seed 000's test takes TIFF): the sweep, and the autocollimator's readings and null
    decisions."""
    rig = "sun_sensor_3axis_autocollimator"
    camp, bare = _campaign(tmp_path, rig, ".png", autocollimator_spp=64)
    # the stages in this process: seed 000's chain runs each of them as a subprocess
    out = _stages(bare, rig, sorted(p.name for p in bare.glob("img_*")), run=rigsim_in_process)
    _same_numbers(out, camp)
    t = read_table(tmp_path / "export" / "null_frames.csv", [Column("frame", kind="str"), Column("face", kind="str")])
    decisions = _decisions(camp)
    assert len(t["frame"]) == len(decisions)
    for n, (f, (face, reading, dec)) in enumerate(zip(t["frame"], decisions)):
        shutil.copy(tmp_path / "export" / f, bare / f"a{n}.png")
        run = rigsim if n == 0 else rigsim_in_process  # the first frame as a lab runs it, the others through main()
        run("autocollimator", "read", f"a{n}.png", "--rig", rig, "--json", f"a{n}.json", cwd=bare)
        r = read(bare / f"a{n}.json")
        step = next(s for s in camp["searches"] if s["face"] == face)["steps"]
        assert_rel(r["reading_arcsec"], [s["measured"] for s in step if s["reading_deg"] == reading][0])
        assert r["nulled"] == (dec == "null")
