"""The start of every worker process of rigsim's pools (:mod:`rigsim.render.workers`).

On Linux the pools fork their workers from a forkserver that has imported this module once: the libraries and
the rigsim layers below the renderer, ~1 s of imports that each spawned worker paid again. Nothing here imports
Mitsuba or Dr.Jit (their state must be each worker's own) or reads the environment at import: a worker takes its
caller's environment in :func:`start`, before it imports anything of the renderer."""

import importlib
import os

import astropy.io.fits  # noqa: F401
import astropy.time  # noqa: F401
import astropy.units  # noqa: F401
import astropy.wcs  # noqa: F401
import cv2  # noqa: F401
import numpy  # noqa: F401
import pydantic  # noqa: F401
import scipy.linalg  # noqa: F401
import scipy.ndimage  # noqa: F401
import scipy.optimize  # noqa: F401
import scipy.signal  # noqa: F401
import scipy.spatial.transform  # noqa: F401
import scipy.special  # noqa: F401

import rigsim.detector  # noqa: F401
import rigsim.estimation  # noqa: F401
import rigsim.files  # noqa: F401
import rigsim.frames  # noqa: F401
import rigsim.imaging  # noqa: F401
import rigsim.optics  # noqa: F401
import rigsim.rig.load  # noqa: F401


def start(env: dict, initializer: str | None, initargs: tuple) -> None:
    """A pool worker's initializer: the caller's environment (a forkserver's child has the server's, from when the
    server started), then ``initializer`` ("module:function", imported only now) with ``initargs``."""
    if dict(os.environ) != env:
        os.environ.clear()
        os.environ.update(env)
    if initializer:
        module, _, name = initializer.partition(":")
        getattr(importlib.import_module(module), name)(*initargs)
