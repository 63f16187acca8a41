"""The orbit scenario's frames in two processes (rigsim.procedures.boresight.frame_pool): every frame and
every number bit-identical to one process, and a worker that dies or cannot start costs time, not the run."""

from __future__ import annotations

import sys
import warnings

import numpy as np
import pytest

from rigsim.procedures.boresight import frame_pool
from rigsim.procedures.boresight.studies import run_orbit
from rigsim.rig.load import load_boresight_rig

pytestmark = pytest.mark.render


@pytest.fixture(scope="module")
def rig():
    r = load_boresight_rig("scenes/dual_line_array_prism.toml")
    # 64 spp, not 256: the frames and numbers are compared bit for bit between runs, whatever their noise
    return r.model_copy(update={"orbit": r.orbit.model_copy(update={"reference_frames": 2, "spp": 64})})


def _run(rig, workers):
    frames = []

    def keep(stage, c, j, k, fr):
        frames.append(((stage, c, j, k), fr.dn.copy(), fr.photons.copy(), fr.truth, fr.origin_uv))

    res = run_orbit(rig, seed=5, measurements=3, workers=workers, on_frame=keep)
    return frames, res


def _numbers(res):
    e = res["estimates"]
    return (e["dvad"]["relative_arcsec"], e["simplified"]["relative_arcsec"], e["dvad"]["delta_f_um"],
            res["estimates_jitter"]["dvad"]["relative_arcsec"], res["centroid_error_px"],
            res["reference_centroid_std_px"], res["render_fidelity_max_px"])


def _assert_same(a, b):
    fa, ra = a
    fb, rb = b
    assert [f[0] for f in fa] == [f[0] for f in fb]
    for x, y in zip(fa, fb):
        assert np.array_equal(x[1], y[1]), x[0]   # DN
        assert np.array_equal(x[2], y[2]), x[0]   # expected photons
        assert x[3] == y[3] and x[4] == y[4], x[0]
    assert _numbers(ra) == _numbers(rb)


@pytest.fixture(scope="module")
def one_process(rig):
    return _run(rig, 1)


def test_two_processes_give_the_frames_of_one(rig, one_process):
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)   # the worker must not have failed over
        two = _run(rig, 2)
    _assert_same(one_process, two)
    assert one_process[1]["frames_rendered"] == 4 * (2 + 3) == len(two[0])


def test_a_dead_worker_is_replaced_by_this_process(rig, one_process, monkeypatch):
    init = frame_pool.FramePool.__init__

    def start_then_kill(self, *args, **kw):
        init(self, *args, **kw)
        self._proc.kill()   # before it can send a frame (its start-up alone takes longer)

    monkeypatch.setattr(frame_pool.FramePool, "__init__", start_then_kill)
    with pytest.warns(RuntimeWarning, match=r"boresight render worker stopped \(exit status -9\)"):
        two = _run(rig, 2)
    _assert_same(one_process, two)


def test_a_worker_that_cannot_start_costs_one_warning(rig, one_process, monkeypatch):
    monkeypatch.setattr(frame_pool.sys, "executable", sys.executable + "-does-not-exist")
    with pytest.warns(RuntimeWarning, match="boresight render worker could not start"):
        two = _run(rig, 2)
    _assert_same(one_process, two)


def test_workers_must_be_a_positive_integer(rig):
    for bad in (0, -1, 1.5):
        with pytest.raises(ValueError, match="workers"):
            run_orbit(rig, measurements=3, workers=bad)


def test_a_pool_closed_before_its_tasks_stops_its_worker(rig):
    pool = frame_pool.FramePool(rig, {1})
    proc = pool._proc
    pool.close()
    assert proc.poll() is not None
    assert pool.result(0) is None
