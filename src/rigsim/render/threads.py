"""One thread policy for each kind of work: Dr.Jit, BLAS/OpenMP (threadpoolctl) and OpenCV set together.

Kinds (the measured reasons are in docs/performance.md):

- ``"render"``: one process renders. Dr.Jit and OpenCV use every core; BLAS one thread (the numpy
  work between renders is on small matrices, where a second BLAS thread only adds overhead and
  competes with Dr.Jit).
- ``"worker"``: one of several worker processes sharing the cores. Every pool one thread, so
  ``P`` workers never run more than ``P`` busy threads.
- ``"numeric"``: numpy/scipy work on large arrays (batch least squares, FFTs): BLAS and OpenCV
  on every core; Dr.Jit untouched.

Bit-identical light tracing is not a thread-count question here: :meth:`rigsim.render.scene.SceneHandle.render`
pins Dr.Jit to one thread for the render that asks for it (``single_thread=True``).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["KINDS", "apply_thread_policy", "command_threads", "cores", "current_threads", "thread_policy"]

KINDS = ("render", "worker", "numeric")


def cores() -> int:
    """CPUs this process may run on (the affinity mask, not the machine's count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


def _plan(kind: str, n: int) -> dict[str, int | None]:
    if kind not in KINDS:
        raise ValueError(f"thread policy kind must be one of {', '.join(KINDS)}, got {kind!r}")
    if kind == "render":
        return {"drjit": n, "blas": 1, "opencv": n}
    if kind == "worker":
        return {"drjit": 1, "blas": 1, "opencv": 1}
    return {"drjit": None, "blas": n, "opencv": n}


def current_threads() -> dict[str, int]:
    """Threads each pool uses now (drjit only if it is already imported)."""
    import sys

    import cv2
    from threadpoolctl import threadpool_info

    out = {"opencv": int(cv2.getNumThreads())}
    blas = [d["num_threads"] for d in threadpool_info() if d.get("user_api") == "blas"]
    if blas:
        out["blas"] = int(max(blas))
    if "drjit" in sys.modules:
        out["drjit"] = int(sys.modules["drjit"].thread_count())
    return out


def _set(plan: dict[str, int | None]) -> None:
    import cv2

    if plan.get("opencv"):
        cv2.setNumThreads(int(plan["opencv"]))
    if plan.get("drjit"):
        from rigsim.render.backend import set_thread_count

        set_thread_count(int(plan["drjit"]))


def apply_thread_policy(kind: str, n: int | None = None) -> dict[str, int | None]:
    """Set every pool for ``kind`` for the rest of the process (worker start-up, CLI start-up)."""
    from threadpoolctl import threadpool_limits

    plan = _plan(kind, int(n) if n else cores())
    _set(plan)
    if plan.get("blas"):
        threadpool_limits(limits=int(plan["blas"]), user_api="blas")
        threadpool_limits(limits=int(plan["blas"]), user_api="openmp")
    return plan


@contextmanager
def thread_policy(kind: str, n: int | None = None) -> Iterator[dict[str, int | None]]:
    """Set every pool for ``kind`` inside the block and restore the previous counts after it."""
    from threadpoolctl import threadpool_limits

    before = current_threads()
    plan = _plan(kind, int(n) if n else cores())
    limits = threadpool_limits(limits=int(plan["blas"]), user_api="blas") if plan.get("blas") else None
    try:
        _set(plan)
        yield plan
    finally:
        if limits is not None:
            limits.restore_original_limits()
        _set({"opencv": before.get("opencv"), "drjit": before.get("drjit") if plan.get("drjit") else None})


@contextmanager
def command_threads() -> Iterator[None]:
    """What every ``rigsim`` command runs under: the ``"render"`` policy's BLAS limit (one thread).

    Dr.Jit and OpenCV keep their default (every core) and are not imported for it, so a command that
    renders nothing starts as fast as before."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield
