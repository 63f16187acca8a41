"""The Monte-Carlo budget's speed-ups change no number: estimates in worker processes, the diaphragm
geometry memoised across trials, the searches and draws in trial order from one generator."""

import threading

import numpy as np
import pytest

from rigsim.procedures.cube_mirror import estimate_pool
from rigsim.procedures.cube_mirror.rendered_campaign import (
    rendered_budget_sources,
    rendered_error_budget,
    surrogate_campaign,
)
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.realization import draw_realization

RIG0 = load_rig("sun_sensor_2axis_diaphragm")
RIG1 = load_rig("sun_sensor_3axis_autocollimator")
NULL = {"diaphragm": 0.04, "autocollimator": 0.02}


def _budget(rig, workers, n=4, seed=5):
    return rendered_error_budget(rig, n, seed, null_sigma=NULL[rig.procedure.method], centroid_sigma_px=0.0085,
                                 workers=workers)


@pytest.mark.parametrize("rig", [RIG0, RIG1], ids=["000", "001"])
def test_budget_is_bit_identical_for_every_worker_count(rig):
    ref = _budget(rig, 0)
    for w in (1, 2):
        b = _budget(rig, w)
        assert list(b.errors) == list(ref.errors)
        for name in ref.errors:
            assert np.array_equal(b.errors[name], ref.errors[name]), (w, name)
        assert [r.sigma_arcsec.tolist() for r in b.rows] == [r.sigma_arcsec.tolist() for r in ref.rows]


def test_budget_workers_spawned_beside_threads_give_the_same_numbers():
    """With other threads running (Mitsuba's, after a rendered campaign) the workers are spawned,
    not forked; same numbers."""
    stop = threading.Event()
    t = threading.Thread(target=stop.wait, daemon=True)
    t.start()
    try:
        assert estimate_pool._start_method() == "spawn"
        b = _budget(RIG0, 1, n=3)
    finally:
        stop.set()
        t.join()
    ref = _budget(RIG0, 0, n=3)
    for name in ref.errors:
        assert np.array_equal(b.errors[name], ref.errors[name]), name


@pytest.mark.parametrize("rig", [RIG0, RIG1], ids=["000", "001"])
def test_budget_rows_are_the_surrogate_campaigns_of_one_generator(rig):
    """The first two rows equal surrogate_campaign run trial after trial on one generator (the
    budget's draws, searches and estimates in their original order)."""
    n, seed = 4, 9
    b = _budget(rig, 1, n=n, seed=seed)
    rng = np.random.default_rng(seed)
    sources = rendered_budget_sources(rig, NULL[rig.procedure.method], 0.0085)
    for name, (drawn, noise, mode, _) in list(sources.items())[:2]:
        fit = noise.centroid_sigma_px > 0 or any(noise.encoder_sigma_rad.values()) or "perpendicularity" in drawn
        e = np.array([surrogate_campaign(rig, draw_realization(rig, rng, drawn), noise, rng,
                                         null_sigma=NULL[rig.procedure.method], null_mode=mode,
                                         fit_calibration=fit).error_arcsec for _ in range(n)])
        assert np.array_equal(b.errors[name], e), name


def test_worker_count_is_checked():
    with pytest.raises(ValueError, match="workers"):
        estimate_pool.EstimatePool(RIG0, -1)
