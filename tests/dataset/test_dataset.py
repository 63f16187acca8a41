"""Datasets: format, reproducibility, resume after SIGKILL, retries, reader, scoring, bad input."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rigsim.dataset import DatasetError, open_dataset
from rigsim.dataset.runner import FAIL_ENV, generate, verify
from rigsim.dataset.score import score

pytestmark = pytest.mark.render
RIG = "sun_sensor_2axis_diaphragm"
N = 8
SPP = 64


def _pngs(root) -> dict:
    m = json.loads((Path(root) / "manifest.json").read_text())["files_sha256"]
    return {k: v for k, v in m.items() if k.endswith(".png")}


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    root = tmp_path_factory.mktemp("clean")
    r = generate(RIG, root, frames=N, seed=11, spp=SPP, workers=2, progress=False)
    return root, r


def test_format_truth_and_reader(clean):
    root, r = clean
    assert r.n_frames == N and r.n_rendered == N and verify(root) == []
    ds = open_dataset(root, verify=True)
    assert len(ds) == N
    t = ds.truth_numpy()
    for i, img, row in ds:
        assert img.dtype == np.uint16 and img.shape == (1024, 1024)
        # the truth's spot is where the image's light is: the thresholded first moment of a window
        # around it equals the exact pixel first moment to the rendering + detector noise (≤ 0.05 px;
        # 0.008 px rms measured on the sweep, docs/campaign.md)
        u0, v0 = int(round(row["spot_centroid_u"])) - 10, int(round(row["spot_centroid_v"])) - 10
        w = img[max(v0, 0):v0 + 21, max(u0, 0):u0 + 21].astype(float) - 64.0
        w[w < 10] = 0
        vv, uu = np.indices(w.shape)
        assert (uu * w).sum() / w.sum() + max(u0, 0) == pytest.approx(row["spot_centroid_u"], abs=0.05)
        assert (vv * w).sum() / w.sum() + max(v0, 0) == pytest.approx(row["spot_centroid_v"], abs=0.05)
        # readings = true angle + the drawn encoder error
        assert row["pose_X_read_deg"] - row["pose_X_true_deg"] == pytest.approx(row["draw_encoder_X_arcsec"] / 3600, abs=1e-12)
    assert np.all(np.abs(np.linalg.norm(np.stack([t["sun_x"], t["sun_y"], t["sun_z"]], 1), axis=1) - 1) < 1e-12)
    # CSV export holds the same table
    lines = (root / "truth.csv").read_text().splitlines()
    assert len(lines) == N + 1 and lines[0].split(",")[0].strip('"') == "frame"
    man = json.loads((root / "manifest.json").read_text())
    assert man["seed"] == 11 and "mitsuba" in man["software"] and len(man["frame_seeds"]) == N


def test_same_seed_same_frames_whatever_the_worker_count(clean, tmp_path):
    root, _ = clean
    generate(RIG, tmp_path, frames=N, seed=11, spp=SPP, workers=1, progress=False)
    assert _pngs(tmp_path) == _pngs(root)


def test_sigkill_then_rerun_resumes_without_loss_duplicate_or_corruption(clean, tmp_path):
    root, _ = clean
    cmd = [sys.executable, "-m", "rigsim.cli", "dataset", "generate", RIG, "--out", str(tmp_path), "--frames", str(N),
           "--seed", "11", "--spp", str(SPP), "--workers", "1", "--quiet"]
    p = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    while time.time() - t0 < 120:
        done = len(list((tmp_path / "frames").glob("frame_*.json"))) if (tmp_path / "frames").exists() else 0
        if done >= 3:
            break
        time.sleep(0.05)
    os.killpg(p.pid, signal.SIGKILL)
    p.wait()
    done = len(list((tmp_path / "frames").glob("frame_*.json")))
    assert 3 <= done < N, "the kill must land mid-run"
    assert not (tmp_path / "manifest.json").exists()
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert f"{N} frames (" in r.stdout and "already complete" in r.stdout
    assert verify(tmp_path) == []
    files = sorted(x.name for x in (tmp_path / "frames").iterdir())
    assert len(files) == 2 * N and not any(f.startswith(".") for f in files)  # no duplicates, no leftovers
    assert _pngs(tmp_path) == _pngs(root)  # every frame identical to the uninterrupted run


@pytest.mark.parametrize("fault", ["crash", "raise"])
def test_a_crashing_task_is_retried_and_its_frame_is_whole(clean, tmp_path, monkeypatch, fault):
    root, _ = clean
    monkeypatch.setenv(FAIL_ENV, f"{fault}:2:{tmp_path.parent}")  # beside the dataset, inside pytest's folder
    r = generate(RIG, tmp_path, frames=4, seed=11, spp=SPP, workers=2, progress=False, chunk=1)
    assert r.retries >= 1
    assert verify(tmp_path) == []
    assert {k: v for k, v in _pngs(tmp_path).items()} == {k: v for k, v in _pngs(root).items() if int(k[13:19]) < 4}


def test_score_against_known_errors(clean, tmp_path):
    root, _ = clean
    ds = open_dataset(root)
    t = ds.truth_numpy()
    p = tmp_path / "c.csv"
    p.write_text("frame,u,v,comment\n" + "".join(f"{i},{t['spot_u'][i] + 0.1},{t['spot_v'][i] - 0.05},x\n" for i in range(N - 1)))
    s = score(root, p)
    assert s.mode == "centroid" and s.n == N - 1 and s.missing == [N - 1]
    assert s.rms == pytest.approx(np.hypot(0.1, 0.05), rel=1e-9)
    np.testing.assert_allclose(s.mean, [0.1, -0.05], atol=1e-9)
    # direction mode: every vector rotated by 10″ → 10″ rms
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec([10 / 206264.806, 0, 0])
    d = tmp_path / "d.csv"
    V = R.apply(np.stack([t["sun_x"], t["sun_y"], t["sun_z"]], 1))
    rows = "".join(f"{i},{V[i, 0]},{V[i, 1]},{V[i, 2]}\n" for i in range(N))
    d.write_text("frame,x,y,z\n" + rows)
    s = score(root, d)
    # the angle to each vector is 10″ × sin(angle between it and the rotation axis)
    expect = 10 * np.linalg.norm(np.cross([1, 0, 0], np.stack([t["sun_x"], t["sun_y"], t["sun_z"]], 1)), axis=1)
    assert s.rms == pytest.approx(np.sqrt(np.mean(expect**2)), rel=1e-6)


def test_rigsim_centroid_tables_are_scored(clean, tmp_path):
    """The file chain: `rigsim centroid` on a dataset's frames writes the table `dataset score` reads (frame file
    names for the index, spot 0 of each frame); `dataset verify` reads the manifest. `dataset score` and `verify`
    in a subprocess, `centroid` in this process (its subprocess runs: the cube-mirror file chain)."""
    from file_chain import rigsim, rigsim_in_process

    root, _ = clean
    frames = sorted(str(p) for p in (root / "frames").glob("*.png"))
    rigsim_in_process("centroid", *frames, "--rig", RIG, "--out", tmp_path / "c.csv", "--quiet")
    p = rigsim("dataset", "score", root, tmp_path / "c.csv", "--json-out", tmp_path / "s.json")
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["n"] == N and s["missing"] == [] and s["rms"] < 0.05, p.stdout
    rigsim("dataset", "verify", root)


@pytest.mark.parametrize("content,msg", [
    ("frame,u\n1,2\n", "hold no known prediction; expected 'frame' and 'u, v' or 'u_px, v_px'"),
    ("u,v\n1,2\n", "no 'frame' column"),
    ("frame,u,v\n1,inf,2\n", "infinite value"),
    ("frame,u,v\n1,nan,2\n", "no prediction rows (1 rows are NaN)"),
    ("frame,u,v\n1,abc,2\n", "column 'u' = 'abc' is not a number"),
    ("frame,u,v\n1,2,3\n1,2,3\n", "frame 1 appears twice"),
    ("frame,u,v\n99,2,3\n", "frame(s) [99] not in the dataset"),
    ("", "empty file"),
])
def test_score_bad_csv(clean, tmp_path, content, msg):
    root, _ = clean
    p = tmp_path / "p.csv"
    p.write_text(content)
    with pytest.raises(DatasetError) as e:
        score(root, p)
    assert msg in str(e.value)


@pytest.mark.parametrize("header", ["u,v", "u_px,v_px", "x_centroid,y_centroid", "xcentroid,ycentroid", "x,y"])
def test_score_reads_the_column_names_of_opencv_photutils_and_sep(clean, tmp_path, header):
    root, _ = clean
    t = open_dataset(root).truth_numpy()
    p = tmp_path / "c.csv"
    p.write_text(f"frame,{header},flux\n" + "".join(f"{i},{t['spot_u'][i] + 0.03},{t['spot_v'][i]},9\n" for i in range(N)))
    s = score(root, p)
    assert s.columns == ["frame", *header.split(",")] and f"columns frame, {header.replace(',', ', ')}" in s.text()
    assert s.rms == pytest.approx(0.03, rel=1e-9) and s.hints == []


def test_score_counts_nan_rows_as_failed_fits_and_writes_every_error(clean, tmp_path):
    root, _ = clean
    t = open_dataset(root).truth_numpy()
    p = tmp_path / "c.csv"
    rows = [f"{i},{t['spot_u'][i] + 0.01 * i},{t['spot_v'][i]}" for i in range(N - 2)] + [f"{N - 2},nan,nan", f"{N - 1},,"]
    p.write_text("frame,u,v\n" + "\n".join(rows) + "\n")
    s = score(root, p)
    assert s.n == N - 2 and s.missing == [N - 2, N - 1] and s.failed == [N - 2, N - 1]
    assert "of which 2 NaN (failed fits)" in s.text()
    out = tmp_path / "errors.csv"
    from rigsim import cli

    assert cli.main(["dataset", "score", str(root), str(p), "--errors-out", str(out), "--json-out",
                     str(tmp_path / "s.json")]) == 0
    from rigsim.files.tables import Column, read_table

    e = read_table(out, [Column("frame", kind="int"), Column("du", "px"), Column("error", "px")])
    np.testing.assert_allclose(e["du_px"], 0.01 * np.arange(N - 2), atol=1e-9)
    assert json.loads((tmp_path / "s.json").read_text())["failed"] == [N - 2, N - 1]


@pytest.mark.parametrize("shift,expect", [((1.0, 1.0), "shifted u by +1 px (subtract 1) and v by +1 px (subtract 1) — 1-based"),
                                          ((0.5, 0.5), "u by +0.5 px (subtract 0.5) and v by +0.5 px (subtract 0.5) — a corner"),
                                          ((-1.0, 0.0), "shifted u by -1 px (add 1) — an index shifted the wrong way"),
                                          ((-0.5, -0.5), "u by -0.5 px (add 0.5) and v by -0.5 px (add 0.5)"),
                                          ((1.0, -1.0), "u by +1 px (subtract 1) and v by -1 px (add 1)")])
def test_score_names_a_pixel_convention_mistake(clean, tmp_path, shift, expect):
    root, _ = clean
    t = open_dataset(root).truth_numpy()
    rng = np.random.default_rng(1)
    p = tmp_path / "c.csv"
    p.write_text("frame,u,v\n" + "".join(f"{i},{t['spot_u'][i] + shift[0] + rng.normal(0, 0.02)},"
                                         f"{t['spot_v'][i] + shift[1] + rng.normal(0, 0.02)}\n" for i in range(N)))
    s = score(root, p)
    assert len(s.hints) == 1 and expect in s.hints[0], s.hints


def test_score_names_swapped_u_and_v_and_takes_an_absolute_outlier_threshold(clean, tmp_path):
    root, _ = clean
    t = open_dataset(root).truth_numpy()
    p = tmp_path / "c.csv"
    p.write_text("frame,u,v\n" + "".join(f"{i},{t['spot_v'][i] + 0.01},{t['spot_u'][i]}\n" for i in range(N)))
    s = score(root, p)
    assert any("u and v look swapped" in h and "0.01 px" in h for h in s.hints), s.hints
    assert s.rms > 1.0
    s = score(root, p, outlier_abs=0.5)
    assert s.outlier_threshold == 0.5 and len(s.outliers) == int(np.sum(np.hypot(t["spot_v"] - t["spot_u"], 0) > 0.5))


def test_bad_dataset_files_are_named(clean, tmp_path):
    import shutil

    root, _ = clean
    d = tmp_path / "copy"
    shutil.copytree(root, d)
    f = d / "frames" / "frame_000003.png"
    f.write_bytes(f.read_bytes()[:-100])  # truncated
    assert any("frame_000003.png: checksum mismatch" in b for b in verify(d))
    with pytest.raises(DatasetError, match="frame_000003.png: checksum mismatch"):
        open_dataset(d).frame(3)
    (d / "truth.parquet").write_bytes(b"not parquet")
    with pytest.raises(DatasetError, match="truth.parquet: corrupt Parquet"):
        open_dataset(d)
    (d / "manifest.json").unlink()
    with pytest.raises(DatasetError, match="manifest.json: missing"):
        open_dataset(d)
    with pytest.raises(DatasetError, match="no such dataset directory"):
        open_dataset(tmp_path / "nope")


def test_rerun_with_other_settings_is_refused(clean):
    root, _ = clean
    with pytest.raises(DatasetError, match="already holds a different dataset \\(seed: existing 11, requested 12\\)"):
        generate(RIG, root, frames=N, seed=12, spp=SPP, progress=False)


def test_sweep_grid_and_bad_specs(tmp_path):
    from rigsim.dataset.generators import SunSensorGenerator

    g = SunSensorGenerator((Path(__file__).parents[2] / "scenes" / f"{RIG}.toml").read_text())
    plan = g.plan(None, "X=-20:20:20 Y=0,5", 0)
    assert [f["pose_true_deg"] for f in plan] == [{"X": x, "Y": y} for x in (-20.0, 0.0, 20.0) for y in (0.0, 5.0)]
    for spec, msg in (("Q=1:2:1", "'Q' is not sweepable"), ("X=5:1:1", "START:STOP:STEP"), ("X", "NAME=VALUES")):
        with pytest.raises(DatasetError, match=msg):
            g.plan(None, spec, 0)


def test_dask_scheduler_gives_the_same_frames(clean, tmp_path):
    distributed = pytest.importorskip("distributed")
    root, _ = clean
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cl:
        generate(RIG, tmp_path, frames=3, seed=11, spp=SPP, scheduler=cl.scheduler_address, progress=False)
    assert _pngs(tmp_path) == {k: v for k, v in _pngs(root).items() if int(k[13:19]) < 3}


def test_star_frames_are_fits_with_one_truth_row_per_star_and_scored_by_matching(tmp_path):
    """Seed-004 rig: FITS frames; the truth has one row per star; a prediction list with 0.05 px
    Gaussian noise per axis scores √2·0.05 = 0.071 px rms (±15 %: ~100–400 stars), one false detection."""
    from astropy.io import fits

    r = generate("star_sensor", tmp_path, frames=3, seed=2, progress=False)
    assert r.n_frames == 3
    ds = open_dataset(tmp_path, verify=True)
    assert ds.fmt == "fits" and ds.rows_per_frame
    img = ds.frame(0)
    with fits.open(tmp_path / "frames" / "frame_000000.fits") as h:
        assert np.array_equal(h[0].data, img)
    t = ds.truth_numpy()
    row0 = ds.row(0)
    assert len(row0["hip"]) == row0["n_stars"][0] > 10
    # the true star positions are where the light is: mean DN at the brightest true stars ≫ background
    bright = np.argsort(row0["photons"])[-5:]
    for k in bright:
        u, v = int(round(row0["u"][k])), int(round(row0["v"][k]))
        if 2 < u < img.shape[1] - 3 and 2 < v < img.shape[0] - 3:
            assert img[v - 1:v + 2, u - 1:u + 2].mean() > np.median(img) + 20
    rng = np.random.default_rng(0)
    sel = t["star"] >= 0
    lines = ["frame,u,v"] + [f"{f},{u + rng.normal(0, 0.05)},{v + rng.normal(0, 0.05)}"
                             for f, u, v in zip(t["frame"][sel], t["u"][sel], t["v"][sel])] + ["1,3.0,3.0"]
    p = tmp_path / "stars.csv"
    p.write_text("\n".join(lines) + "\n")
    s = score(tmp_path, p)
    assert s.detection["false_detections"] == 1 and s.detection["missed"] == 0
    assert s.rms == pytest.approx(np.sqrt(2) * 0.05, rel=0.15)
    assert s.hints == []
    # star frames name a pixel-convention mistake too, with the sign that undoes it
    for (du, dv), words in (((1.0, 1.0), "u by +1 px (subtract 1) and v by +1 px (subtract 1)"),
                            ((-0.5, -0.5), "u by -0.5 px (add 0.5) and v by -0.5 px (add 0.5)")):
        p.write_text("frame,u,v\n" + "".join(f"{f},{u + du + rng.normal(0, 0.02)},{v + dv + rng.normal(0, 0.02)}\n"
                                             for f, u, v in zip(t["frame"][sel], t["u"][sel], t["v"][sel])))
        s = score(tmp_path, p)
        assert any(words in h for h in s.hints), s.hints
    p.write_text("frame,u,v\n" + "".join(f"{f},{v},{u}\n" for f, u, v in zip(t["frame"][sel], t["u"][sel], t["v"][sel])))
    try:
        s = score(tmp_path, p)
        assert any("u and v look swapped" in h for h in s.hints), s.hints
    except DatasetError as e:  # no prediction matched: the error names the cause
        assert "with u and v exchanged: u and v look swapped" in str(e), e
    # the file chain: `star calibrate` reads the dataset's FITS frames (a lab's log: the frames' attitudes), in this
    # process (its subprocess run: tests/procedures/star/test_star_files.py)
    from file_chain import rigsim_in_process as rigsim

    from rigsim.files import write_table
    from rigsim.procedures.star.files import attitude_log_columns

    names = [f"frame_{i:06d}.fits" for i in range(3)]
    R = [np.array(ds.sidecar(i)["truth"]["R_cam_from_icrs"]) for i in range(3)]
    write_table(tmp_path / "log.csv", attitude_log_columns(names, [0.0, 1.0, 2.0], R))
    rigsim("star", "calibrate", *(tmp_path / "frames" / n for n in names), "--attitudes", tmp_path / "log.csv",
           "--out", tmp_path / "cal")
    assert json.loads((tmp_path / "cal" / "calibration.json").read_text())["identification"]["frames_identified"] == 3


def test_boresight_rois_with_the_state_and_exact_spot(tmp_path):
    """Seed-003 rig: 48² CMOS ROIs cycling over (camera, M1/M2); the thresholded first moment of
    each ROI equals the exact spot centre to the rendering + detector noise (≤ 0.03 px; the
    boresight docs measure 0.006 px render error and ~0.003 px noise)."""
    r = generate("dual_line_array_prism", tmp_path, frames=4, seed=1, progress=False, workers=1)
    ds = open_dataset(tmp_path, verify=True)
    t = ds.truth_numpy()
    assert list(t["detector"]) == ["M1", "M2", "M1", "M2"] and r.n_frames == 4
    assert np.all(np.abs(t["alpha_arcsec"]) <= 60) and np.all(np.abs(t["df_um"]) <= 20)
    for i, img, row in ds:
        a = img.astype(float) - np.median(img)
        a[a < 20] = 0
        v, u = np.indices(a.shape)
        assert (u * a).sum() / a.sum() + row["roi_u0"] == pytest.approx(row["spot_u"], abs=0.03)
        assert (v * a).sum() / a.sum() + row["roi_v0"] == pytest.approx(row["spot_v"], abs=0.03)
