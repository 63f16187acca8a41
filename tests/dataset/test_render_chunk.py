"""The worker task writes a frame on its I/O thread while the next renders: every frame of the chunk is
whole and complete when the task returns, and a failed write fails the task (to be retried)."""

import json

import pytest

from rigsim.dataset import runner
from rigsim.dataset.generators import make_generator
from rigsim.dataset.store import frame_complete, frame_files, sha256_file
from rigsim.rig.load import read_rig_text, resolve_rig_path

pytestmark = pytest.mark.render


@pytest.fixture(scope="module")
def chunk():
    rig = resolve_rig_path("sun_sensor_2axis_diaphragm")
    text = read_rig_text(rig)
    gen = make_generator("sun-sensor", text, str(rig), spp=16)
    return text, str(rig), gen.plan(3, None, 4)


def _run(chunk, root):
    text, rig, params = chunk
    (root / "frames").mkdir(exist_ok=True)
    return runner.render_chunk("sun-sensor", text, rig, {"spp": 16}, str(root), "png", list(enumerate(params)))


def test_every_frame_is_complete_when_the_task_returns(chunk, tmp_path):
    done = _run(chunk, tmp_path)
    assert [i for i, _ in done] == [0, 1, 2]
    for i, digest in done:
        assert frame_complete(tmp_path, i, "png", params=chunk[2][i])
        assert sha256_file(frame_files(tmp_path, i, "png")[0]) == digest
        render = json.loads(frame_files(tmp_path, i, "png")[1].read_text())["render"]
        assert render["spp"] == 16 and 4 <= render["tile_px"] < render["window_px"]  # Mitsuba drew the spot's tile
    assert _run(chunk, tmp_path) == done  # all complete: nothing rendered again, same checksums


def test_a_failed_write_fails_the_task(chunk, tmp_path, monkeypatch):
    write = runner.write_frame_atomic

    def flaky(root, index, *a, **k):
        if index == 1:
            raise OSError(28, "No space left on device")
        return write(root, index, *a, **k)

    monkeypatch.setattr(runner, "write_frame_atomic", flaky)
    with pytest.raises(OSError, match="No space"):
        _run(chunk, tmp_path)
    assert frame_complete(tmp_path, 0, "png", params=chunk[2][0])
    assert not frame_complete(tmp_path, 1, "png", params=chunk[2][1])
