"""Process pools for rendering and campaign work: one start method for all of them.

``forkserver`` where the platform has it (Linux): each worker is forked from a server process that imported
:mod:`rigsim._worker` (the libraries and the layers below the renderer) once, so a worker starts in ~0.1 s
instead of the ~1 s a fresh interpreter takes to import them. Mitsuba and Dr.Jit are never imported by the server:
each worker loads them itself, as under ``spawn``. ``spawn`` elsewhere, or with ``RIGSIM_START_METHOD=spawn``.
Either way a worker runs in its caller's environment, folder and ``sys.path``."""

from __future__ import annotations

import multiprocessing as mp
import os
from concurrent.futures import ProcessPoolExecutor

from rigsim.errors import InputError

START_METHOD_ENV = "RIGSIM_START_METHOD"
START_METHODS = ("forkserver", "spawn")

__all__ = ["START_METHOD_ENV", "START_METHODS", "pool_context", "process_pool"]


def pool_context():
    """The multiprocessing context of rigsim's pools (module docstring)."""
    method = os.environ.get(START_METHOD_ENV) or ("forkserver" if "forkserver" in mp.get_all_start_methods()
                                                  else "spawn")
    allowed = [m for m in START_METHODS if m in mp.get_all_start_methods()]
    if method not in allowed:
        raise InputError(f"environment variable {START_METHOD_ENV}={method!r}: allowed {', '.join(allowed)}")
    ctx = mp.get_context(method)
    if method == "forkserver":
        ctx.set_forkserver_preload(["rigsim._worker"])
    return ctx


def process_pool(max_workers: int, initializer: str | None = None, initargs: tuple = ()) -> ProcessPoolExecutor:
    """A process pool of ``max_workers``; ``initializer`` is ``"module:function"`` (imported in the worker after it
    has taken this process's environment), called with ``initargs``."""
    from rigsim._worker import start  # the worker unpickles it before anything that reads the environment

    return ProcessPoolExecutor(max_workers, mp_context=pool_context(), initializer=start,
                               initargs=(dict(os.environ), initializer, tuple(initargs)))
