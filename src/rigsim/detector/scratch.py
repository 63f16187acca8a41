"""Named scratch arrays that a loop over blocks reuses instead of allocating per block."""

from __future__ import annotations

import threading

import numpy as np

__all__ = ["Scratch", "thread_scratch"]


class Scratch:
    """Flat arrays by name, grown on demand and kept: ``get(name, n, dtype)`` is a view of the
    first ``n`` elements. A caller's views of one name alias each other; one owner per thread."""

    def __init__(self):
        self._arrays: dict[str, np.ndarray] = {}

    def get(self, name: str, n: int, dtype) -> np.ndarray:
        a = self._arrays.get(name)
        if a is None or a.size < n or a.dtype != np.dtype(dtype):
            a = self._arrays[name] = np.empty(n, dtype)
        return a[:n]


_LOCAL = threading.local()


def thread_scratch() -> Scratch:
    """This thread's scratch arrays (kept between calls, so repeated frames allocate nothing)."""
    s = getattr(_LOCAL, "scratch", None)
    if s is None:
        s = _LOCAL.scratch = Scratch()
    return s
