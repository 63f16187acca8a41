"""Every file a command writes is read by every command docs/formats.md says reads it.

The tables of docs/formats.md are parsed: each (file, writer, reader) pair they name among rigsim's commands
must be exercised by a test listed in COVERED (the family file chains run writers and readers as
subprocesses: tests/procedures/*/test_file_chain.py and the families' file tests); a pair added to the docs
without a test, or a listed test that no longer exists, fails here. The pairs no chain covers run below
(in-process: the chains already run every reader as a subprocess): `render`'s frames through the commands
that read each kind, `render target`'s poses back into it, and a covariance from another writer
(asymmetric by rounding) through `compose`."""

import importlib.util
import json
import re
from pathlib import Path

import numpy as np
import pytest
from file_chain import derived_rig, read

from rigsim.cli import main


def rigsim(*args, cwd=None, ok=(0,)):
    """``rigsim ARGS`` in this process (from ``cwd``); its status must be in ``ok``."""
    import contextlib
    import os

    with contextlib.chdir(cwd or os.getcwd()):
        rc = main([str(a) for a in args])
    assert rc in ok, (args, rc)

ROOT = Path(__file__).resolve().parents[2]
CHAIN = "procedures/cube_mirror/test_file_chain.py::"
TWO, THREE = CHAIN + "test_two_axis_campaign_closes_through_the_commands", CHAIN + "test_three_axis_campaign_closes_through_the_commands"
SLOW_PNG = "procedures/cube_mirror/test_user_files.py::test_campaign_frames_round_trip_through_the_commands"
STAR = "procedures/star/test_star_files.py::test_frames_round_trip_through_star_calibrate"
BORE = "procedures/boresight/test_boresight_files.py::test_orbit_frames_round_trip"
DATA = "dataset/test_dataset.py::"
HERE = "procedures/test_file_matrix.py::"

# (file row, writer, reader) as docs/formats.md names them → the test that writes such a file and reads it
COVERED = {
    ("NAME.png", "render", "centroid"): HERE + "test_rendered_sun_sensor_frame_is_centroided",
    ("NAME.png", "render", "concentricity"): HERE + "test_rendered_aiming_frames_through_concentricity",
    ("NAME.png", "render", "autocollimator read"): HERE + "test_rendered_autocollimator_frame_is_read",
    ("NAME.png", "dataset generate", "centroid"): DATA + "test_rigsim_centroid_tables_are_scored",
    ("NAME.png", "dataset generate", "concentricity"):
        "dataset/test_dataset_integrity.py::test_the_same_seed_gives_byte_identical_frames_for_one_or_two_workers",
    ("NAME.png", "dataset generate", "autocollimator read"):
        "dataset/test_dataset_integrity.py::test_the_same_seed_gives_byte_identical_frames_for_one_or_two_workers",
    ("NAME.png", "run --export-frames", "centroid"): THREE,
    ("NAME.png", "run --export-frames", "concentricity"): SLOW_PNG,  # the default suite's seed-000 chain takes TIFF
    ("NAME.png", "run --export-frames", "autocollimator read"): THREE,
    ("NAME.fits", "dataset generate", "star calibrate"): DATA + "test_star_frames_are_fits_with_one_truth_row_per_star_and_scored_by_matching",
    ("NAME.fits", "render star-field --fits", "star calibrate"): HERE + "test_rendered_star_fields_are_calibrated",
    ("NAME.fits", "run star-calibration --export-frames", "star calibrate"): STAR,
    ("centroid table", "centroid", "calibrate sun-sensor --centroids"): TWO,
    ("centroid table", "centroid", "dataset score"): DATA + "test_rigsim_centroid_tables_are_scored",
    ("angle log", "run --export-frames", "calibrate sun-sensor --angles"): TWO,
    ("null log", "run --export-frames", "triad --nulls"): TWO,
    ("null-search frames", "run --export-frames", "concentricity --face --reading --null-offset-px"): TWO,
    ("null-search frames", "run --export-frames", "autocollimator read"): THREE,
    ("star attitude log", "run star-calibration --export-frames", "star calibrate --attitudes"): STAR,
    ("boresight spots", "boresight centroid", "boresight solve"): BORE,
    ("target poses", "render target --spread", "render target --poses"): HERE + "test_spread_poses_are_rendered_again",
    ("dataset truth", "dataset generate", "dataset score"): DATA + "test_rigsim_centroid_tables_are_scored",
    ("cal.json", "calibrate sun-sensor --out", "compose --sun-from-rot"): TWO,
    ("camera.yml / .json / .xml", "calibrate sun-sensor --opencv", "rig import-camera"): TWO,
    ("camera.yml / .json / .xml", "star calibrate --opencv", "rig import-camera"): STAR,
    ("triad JSON", "triad --out", "compose --cube-from-rot"): TWO,
    ("plan.json, manifest.json", "dataset generate", "dataset verify"): DATA + "test_rigsim_centroid_tables_are_scored",
    ("plan.json, manifest.json", "dataset generate", "dataset generate"):
        DATA + "test_sigkill_then_rerun_resumes_without_loss_duplicate_or_corruption",
}


def documented_pairs() -> set[tuple[str, str, str]]:
    """(file, writer, reader) of every table row of docs/formats.md with 'written by' and 'read by' columns,
    counting only the rigsim commands named in backticks."""
    from rigsim.cli import build_parser

    subs = {c for a in build_parser()._actions if isinstance(getattr(a, "choices", None), dict) for c in a.choices}
    pairs = set()
    for table in re.split(r"\n(?=\| file )", (ROOT / "docs" / "formats.md").read_text()):
        lines = [ln for ln in table.splitlines() if ln.startswith("|") and not ln.startswith("|---")]
        if not lines:
            continue
        head = [h.strip() for h in lines[0].strip("|").split("|")]
        if "written by" not in head or "read by" not in head:
            continue
        for ln in lines[1:]:
            cells = [c.strip() for c in ln.strip().strip("|").split("|")]
            if len(cells) != len(head):
                break

            def cmds(cell):
                toks = [re.sub(r"^rigsim ", "", t) for t in re.findall(r"`([^`]+)`", cell)]
                return [t for t in toks if t.split()[0] in subs]

            name = cells[0].replace("`", "")
            for w in cmds(cells[head.index("written by")]):
                for r in cmds(cells[head.index("read by")]):
                    pairs.add((name, w, r))
    return pairs


def test_every_documented_pair_is_exercised_by_a_test():
    pairs = documented_pairs()
    assert len(pairs) >= 25
    missing = sorted(pairs - set(COVERED))
    assert not missing, f"docs/formats.md names a writer and a reader that no test runs together: {missing}"
    stale = sorted(set(COVERED) - pairs)
    assert not stale, f"COVERED lists pairs docs/formats.md no longer names: {stale}"
    for node in set(COVERED.values()):
        path, func = node.split("::")
        spec = importlib.util.spec_from_file_location("m", ROOT / "tests" / path)
        src = (ROOT / "tests" / path).read_text()
        assert spec is not None and re.search(rf"^def {func}\(", src, re.M), node


def test_rendered_sun_sensor_frame_is_centroided(tmp_path):
    rigsim("render", "sun-sensor", "--spp", "16", "--out", tmp_path, "--name", "f", "--pose", "X=20,Y=-10")
    rigsim("centroid", tmp_path / "f.png", "--rig", "sun_sensor_2axis_diaphragm", "--out", tmp_path / "c.csv", "--quiet")
    from rigsim.files import Column, read_table

    t = read_table(tmp_path / "c.csv", [Column("u", "px"), Column("v", "px")])
    truth = read(tmp_path / "f.json")["truth"]["spot"]["center_uv"]
    assert len(t["u_px"]) == 1 and np.hypot(t["u_px"][0] - truth[0], t["v_px"][0] - truth[1]) < 0.1


def test_rendered_aiming_frames_through_concentricity(tmp_path):
    rig = derived_rig("sun_sensor_2axis_diaphragm", tmp_path / "rig.toml", {  # 1/16 of the pixels, the same field
        r"resolution_px = \[1600, 1200\]": "resolution_px = [400, 300]", r"pixel_pitch_um = 15\.0": "pixel_pitch_um = 60.0"})
    rigsim("render", "aiming-camera", "--rig", rig, "--spp", "1", "--out", tmp_path, "--name", "a",
           "--pose", "X=181.4,Y=0.55")
    rigsim("concentricity", tmp_path / "a_hole.png", tmp_path / "a_spot.png", "--rig", rig, "--reading", "X=181.4,Y=0.55",
           "--json", tmp_path / "c.json")
    c = read(tmp_path / "c.json")
    true = read(tmp_path / "a_spot.json")["truth"]["offset_mm"]
    # 35 µm: the returned spot still overlaps the hole 1′ from the null and loses the light that falls back into
    # it (docs/campaign.md; about 22 µm here), plus the coarse camera's 60 µm pixels
    assert np.hypot(*(np.array(c["offset_mm"]) - true)) < 0.035
    assert c["fit"]["verdict"] == "not judged" and not c["nulled"]


def test_rendered_autocollimator_frame_is_read(tmp_path):
    rigsim("render", "autocollimator", "--spp", "16", "--out", tmp_path, "--name", "c")
    rigsim("autocollimator", "read", tmp_path / "c.png", "--json", tmp_path / "r.json")
    r = read(tmp_path / "r.json")
    exact = read(tmp_path / "c.json")["truth"]["reading_arcsec"]
    assert np.all(np.abs(np.array(r["reading_arcsec"]) - exact) < 0.5) and r["fit"]["verdict"] == "not judged"


def test_rendered_star_fields_are_calibrated(tmp_path):
    """Three FITS star fields, the log written from their attitudes (a lab's commanded attitudes)."""
    from rigsim.files import write_table
    from rigsim.procedures.star.files import attitude_log_columns

    R = []
    for i in range(3):
        rigsim("render", "star-field", "--renderer", "analytic", "--fits", "--out", tmp_path, "--name", f"s{i}",
               "--attitude", f"ra={80 + 3 * i},dec=-5,roll={10 * i}", "--seed", i)
        R.append(np.array(read(tmp_path / f"s{i}.json")["truth"]["R_cam_from_icrs"]))
    write_table(tmp_path / "log.csv", attitude_log_columns([f"s{i}.fits" for i in range(3)], [0.0, 1.0, 2.0], R))
    rigsim("star", "calibrate", "s0.fits", "s1.fits", "s2.fits", "--attitudes", "log.csv", "--out", "cal", cwd=tmp_path)
    assert read(tmp_path / "cal" / "calibration.json")["identification"]["frames_identified"] == 3


def test_spread_poses_are_rendered_again(tmp_path):
    """`render target --spread` writes poses.csv; `render target --poses` renders the same boards: the same
    exact target points."""
    rigsim("render", "target", "--target", "chessboard:10x7:20", "--spread", "2", "--spp", "1", "--out", tmp_path / "a",
           "--quiet")
    rigsim("render", "target", "--target", "chessboard:10x7:20", "--poses", tmp_path / "a" / "poses.csv", "--spp", "1",
           "--out", tmp_path / "b", "--quiet")
    a, b = ((tmp_path / d / "points.csv").read_text() for d in "ab")
    assert a == b and len(a.splitlines()) == 1 + 2 * 54


@pytest.mark.parametrize("asym, ok", [(1e-7, True), (1e-4, False)])
def test_a_covariance_from_another_writer_is_symmetrised_within_a_tolerance(tmp_path, capsys, asym, ok):
    """compose reads a covariance whose C − Cᵀ is 1e-7 of its largest variance (another writer's rounding) and
    writes its result exactly symmetric; 1e-4 is refused with one line."""
    from scipy.spatial.transform import Rotation

    C = np.array([[4.0, 0.3, -0.2], [0.3, 2.0, 0.1], [-0.2, 0.1, 1.0]])
    Ca = C.copy()
    Ca[0, 1] += asym * 4.0
    blk = {"matrix": Rotation.from_euler("xz", [30, 12], degrees=True).as_matrix().tolist(), "covariance": {"matrix": Ca.tolist()}}
    (tmp_path / "s.json").write_text(json.dumps({"R_sun_from_rot": blk}))
    (tmp_path / "c.json").write_text(json.dumps({"R_cube_from_rot": {**blk, "covariance": {"matrix": C.tolist()}}}))
    rigsim("compose", "--cube-from-rot", "c.json", "--sun-from-rot", "s.json", "--out", "cs.json", cwd=tmp_path,
           ok=(0,) if ok else (2,))
    out, err = capsys.readouterr()
    if ok:
        got = np.array(read(tmp_path / "cs.json")["R_cube_from_sun"]["covariance"]["matrix"])
        assert np.array_equal(got, got.T) and "not judged (no fit block)" in out
    else:
        assert "s.json: R_sun_from_rot.covariance: not symmetric" in err and len(err.splitlines()) == 1
        assert not (tmp_path / "cs.json").exists()
