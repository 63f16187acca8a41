"""Work bounded up front: a dataset that cannot fit in memory or on the disk is refused with one line before
anything is written; too many workers for the memory are reduced; a disk that fills while the manifest is
written gives one clean line, loses nothing, and the same command completes the dataset afterwards."""

import errno
import json
from pathlib import Path

import pytest

from rigsim import cli
from rigsim.dataset.runner import generate
from rigsim.render import budget
from rigsim.rig.load import SCENES_DIR

pytestmark = pytest.mark.render
RIG = "sun_sensor_2axis_diaphragm"


def _huge_rig(tmp_path, side=20000) -> Path:
    text = (SCENES_DIR / f"{RIG}.toml").read_text()
    text = text.replace("resolution_px = [1024, 1024]", f"resolution_px = [{side}, {side}]", 1)
    text = text.replace("pixel_pitch_um = 11.0", f"pixel_pitch_um = {11.0 * 1024 / side:.4f}", 1)
    p = tmp_path / "huge.toml"
    p.write_text(text)
    return p


def test_the_memory_model_matches_a_measured_render():
    """The model's figure for the default 1 Mpx sun sensor against the measured peak of a worker (324 MB with
    Mitsuba loaded, docs/reliability.md), and for 67 Mpx (7.8 GB)."""
    assert budget.process_bytes(1024 * 1024) == pytest.approx(324e6, rel=0.5)
    assert budget.process_bytes(8192 * 8192) == pytest.approx(7.8e9, rel=0.1)


def test_a_frame_larger_than_the_memory_is_refused_before_anything_is_written(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(budget, "available_bytes", lambda: 8e9)
    rig = _huge_rig(tmp_path)
    out = tmp_path / "ds"
    rc = cli.main(["dataset", "generate", str(rig), "--out", str(out), "--frames", "2"])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "46.4 GB" in err and "resolution_px" in err, err
    assert not out.exists()
    rc = cli.main(["render", "sun-sensor", "--rig", str(rig), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert rc == 2 and "sun_sensor.resolution_px = [20000, 20000]" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "r").exists()


def test_frames_that_cannot_fit_on_the_disk_are_refused_before_the_plan(tmp_path, capsys, monkeypatch):
    real = budget.shutil.disk_usage
    monkeypatch.setattr(budget.shutil, "disk_usage", lambda p: real(p)._replace(free=50e6))
    out = tmp_path / "ds"
    rc = cli.main(["dataset", "generate", RIG, "--out", str(out), "--frames", "30", "--spp", "4"])  # 30 × 2.1 MB > 50 MB
    err = capsys.readouterr().err
    assert rc == 2 and "30 frames of 1.0 Mpx need up to 63.4 MB" in err and "has 50 MB free" in err, err
    assert not out.exists()
    rc = cli.main(["dataset", "generate", RIG, "--out", str(out), "--frames", "2", "--spp", "4", "--workers", "1",
                   "--quiet"])
    assert rc == 0, capsys.readouterr().err


def test_workers_are_reduced_to_what_the_memory_holds(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(budget, "available_bytes", lambda: 1.6 * budget.process_bytes(1024 * 1024) / budget.HEADROOM)
    r = generate(RIG, tmp_path / "ds", frames=2, seed=1, spp=4, workers=2, progress=False)
    assert r.n_rendered == 2
    assert "2 workers of 0.5 GB each do not fit in the available memory; rendering with 1" in capsys.readouterr().err


def test_a_disk_that_fills_while_the_manifest_is_written(tmp_path, capsys, monkeypatch):
    from rigsim.dataset import store

    out = tmp_path / "ds"
    real = store.atomic_write_bytes

    def full(path, data):
        if Path(path).name == "manifest.json":
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, data)

    monkeypatch.setattr(store, "atomic_write_bytes", full)
    args = ["dataset", "generate", RIG, "--out", str(out), "--frames", "3", "--spp", "4", "--workers", "1", "--quiet"]
    rc = cli.main(args)
    err = capsys.readouterr().err
    assert rc == 1 and len(err.strip().splitlines()) == 1 and "no space left" in err and "manifest.json" in err, err
    frames = {p.name: p.read_bytes() for p in (out / "frames").iterdir()}
    assert len(frames) == 6 and not (out / "manifest.json").exists()
    assert not [p for p in out.rglob("*") if p.name.endswith(".tmp")]  # no temporary left behind
    monkeypatch.setattr(store, "atomic_write_bytes", real)
    assert cli.main(args) == 0
    assert {p.name: p.read_bytes() for p in (out / "frames").iterdir()} == frames  # nothing rendered again
    assert cli.main(["dataset", "verify", str(out)]) == 0
    assert json.loads((out / "manifest.json").read_text())["n_frames"] == 3
