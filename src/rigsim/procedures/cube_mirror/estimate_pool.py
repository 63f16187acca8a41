"""The estimation side of Monte-Carlo campaigns in worker processes: from one trial's observations
(sweep readings and centroids, null readings) to its R(cube←sun) error — the sweep fit, TRIAD and
the comparison with that trial's truth.

Only this part runs in the workers. The random draws and the null searches (which consume random
numbers as they go) stay in the caller, trial after trial from one generator, and the estimate
draws none; so every number is the same for any number of workers, 0 (in process) included.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
import threading
from concurrent.futures import Future, ProcessPoolExecutor

import numpy as np

from rigsim.procedures.cube_mirror.campaign import compare
from rigsim.procedures.cube_mirror.pipeline import estimate
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.truth.cube_mirror.realization import Realization

_WORKER_RIG: CubeMirrorRig | None = None


def campaign_error_arcsec(rig: CubeMirrorRig, real: Realization, null_readings, axis_order: str,
                          sweep_readings=None, sweep_uv=None) -> np.ndarray:
    """Steps 1/B (when the sweep was run), 4/C3 and 5/D from the observations; error against ``real``."""
    est = estimate(rig, null_readings, axis_order, sweep_readings=sweep_readings, sweep_uv=sweep_uv)
    return compare(rig, est, real).error_arcsec


def _init_worker(rig: CubeMirrorRig) -> None:
    global _WORKER_RIG
    _WORKER_RIG = rig


def _worker_error(args) -> np.ndarray:
    return campaign_error_arcsec(_WORKER_RIG, *args)


def default_workers() -> int:
    """One worker beside the caller when there are two or more CPUs (the estimate is about a third of
    a surrogate campaign: more workers would wait for the caller), else none."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        n = os.cpu_count() or 1
    return 1 if n > 1 else 0


def _start_method() -> str:
    """fork (cheap; a caller's script needs no ``if __name__ == "__main__"`` guard) unless this process
    runs other threads — Mitsuba's, after a rendered campaign — that a fork would copy half-alive: then
    "spawn", which here means rigsim's pools' start (:mod:`rigsim.render.workers`: a forkserver that never loads
    Mitsuba, or spawn; ``rigsim`` and ``python -m rigsim`` are guarded)."""
    if "fork" not in multiprocessing.get_all_start_methods():
        return "spawn"
    busy = threading.active_count() > 1 or any(m in sys.modules for m in ("drjit", "mitsuba"))
    return "spawn" if busy else "fork"


class EstimatePool:
    """``submit(real, null_readings, axis_order, sweep_readings, sweep_uv)`` → a future of the error
    (arcsec, (3,)). ``workers=0``: computed at once in this process. Use as a context manager."""

    def __init__(self, rig: CubeMirrorRig, workers: int):
        if workers < 0:
            raise ValueError(f"workers = {workers!r}: must be >= 0")
        self.rig = rig
        self._ex = None
        if workers > 0:
            if _start_method() == "fork":
                self._ex = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"),
                                               initializer=_init_worker, initargs=(rig,))
            else:  # rigsim's pools' start (a forkserver that never loads Mitsuba, or spawn)
                from rigsim.render.workers import process_pool

                self._ex = process_pool(workers, f"{__name__}:_init_worker", (rig,))

    def submit(self, real: Realization, null_readings, axis_order: str, sweep_readings=None, sweep_uv=None) -> Future:
        args = (real, list(null_readings), axis_order, sweep_readings, sweep_uv)
        if self._ex is not None:
            return self._ex.submit(_worker_error, args)
        f: Future = Future()
        f.set_result(campaign_error_arcsec(self.rig, *args))
        return f

    def close(self, cancel: bool = False) -> None:
        if self._ex is not None:
            self._ex.shutdown(wait=True, cancel_futures=cancel)
            self._ex = None

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(cancel=exc_type is not None)
