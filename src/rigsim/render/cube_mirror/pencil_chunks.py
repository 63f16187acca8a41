"""The aiming camera's collimated-pencil render split into fixed sample chunks, optionally run in
worker processes: the same image for any worker count.

Mitsuba's light tracer splats with float32 atomic adds, so a render on several Dr.Jit threads is not
bit-reproducible, and two Python threads rendering at once were measured no faster than one after
the other (docs/campaign.md). The pencil's ``spp`` samples
are therefore split into a fixed number of chunks, each rendered single-threaded with its own seed
(:func:`chunk_seeds`); the chunks are averaged in chunk order. Which process renders a chunk does
not matter (each is a pure function of the scene, the pose and its seed), so the image depends on
the seed only, never on ``workers``. With ``workers = 2`` the second chunk is rendered by a worker
process (:mod:`rigsim.render.workers`) holding its own copy of the scene while this process renders the first.
"""

from __future__ import annotations

import atexit
import weakref

import numpy as np

from rigsim.render.scene import mitsuba_seed

__all__ = ["PencilChunks", "chunk_count", "chunk_seeds"]

_CHUNKS = 2  # fixed: part of the random stream, never derived from the worker count


def chunk_count(spp: int) -> int:
    """Chunks of an ``spp``-sample render: :data:`_CHUNKS` equal ones when they divide ``spp``, else 1."""
    return _CHUNKS if spp % _CHUNKS == 0 else 1


def chunk_seeds(seed: int, spp: int) -> list[int]:
    """The Mitsuba seed of each chunk of a render seeded ``seed`` (one chunk: ``seed`` itself)."""
    n = chunk_count(spp)
    return [int(seed)] if n == 1 else [mitsuba_seed(seed, 0xC4, c) for c in range(n)]


# -- the worker process side ------------------------------------------------------------------------
_WORKER: dict = {}


def _worker_init(rig, real, face_index: int, kwargs: dict) -> None:
    from rigsim.render.cube_mirror.diaphragm import DiaphragmRenderer

    _WORKER["renderer"] = DiaphragmRenderer(rig, real, face_index, **kwargs)


def _worker_render(pose_rad: dict, seed: int, spp: int):
    r = _WORKER["renderer"]
    r.set_pose(pose_rad)
    return _crop(r.render_chunk(seed, spp))


def _worker_warm() -> None:
    r = _WORKER["renderer"]
    r.render_chunk(0, max(1, r.spp // chunk_count(r.spp)))


def _crop(img: np.ndarray):
    """(row0, col0, the nonzero bounding box of ``img``) — the lit part is a few % of the frame."""
    rows = np.flatnonzero(np.any(img != 0, axis=1))
    if rows.size == 0:
        return 0, 0, np.zeros((0, 0))
    cols = np.flatnonzero(np.any(img[rows[0]:rows[-1] + 1] != 0, axis=0))
    return int(rows[0]), int(cols[0]), img[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1].copy()


def _uncrop(shape, part) -> np.ndarray:
    r0, c0, a = part
    out = np.zeros(shape)
    out[r0:r0 + a.shape[0], c0:c0 + a.shape[1]] = a
    return out


def _shutdown(pool) -> None:
    pool.shutdown(wait=False, cancel_futures=True)


class PencilChunks:
    """Render ``pencil`` (a :class:`~rigsim.render.cube_mirror.diaphragm.DiaphragmRenderer`) in
    :func:`chunk_count` chunks; ``workers`` (1 or 2) processes take part. ``init`` = the
    (rig, real, face_index, renderer kwargs) a worker rebuilds the same renderer from."""

    def __init__(self, pencil, workers: int = 1, init: tuple | None = None):
        if int(workers) != workers or workers < 1:
            raise ValueError(f"workers = {workers!r}: must be an integer >= 1")
        self.pencil = pencil
        self.workers = min(int(workers), chunk_count(pencil.spp))
        self._pool = None
        if self.workers > 1:
            if init is None:
                raise ValueError("workers > 1 needs the renderer's init arguments")
            from rigsim.render.workers import process_pool

            self._pool = process_pool(self.workers - 1, f"{__name__}:_worker_init", init)
            weakref.finalize(self, _shutdown, self._pool)
            atexit.register(_shutdown, self._pool)
            self._pool.submit(_worker_warm)  # start the worker and compile its kernels now

    def render(self, pose_rad: dict, seed: int) -> np.ndarray:
        """Photons per pixel of the pencil at ``pose_rad`` (the pose is set here), Mitsuba seed ``seed``."""
        p = self.pencil
        p.set_pose(pose_rad)
        seeds = chunk_seeds(seed, p.spp)
        per = p.spp // len(seeds)
        if len(seeds) == 1:
            return p.render_chunk(seeds[0], per)
        futures = {}
        if self._pool is not None:  # chunks 1 … workers-1 in the workers, the rest here, in order
            try:
                futures = {c: self._pool.submit(_worker_render, dict(pose_rad), s, per)
                           for c, s in enumerate(seeds) if 0 < c < self.workers}
            except Exception as exc:  # noqa: BLE001  (the pool broke since the last frame)
                self._lost_worker(exc)
                futures = {}
        parts = [None] * len(seeds)
        for c, s in enumerate(seeds):
            if c not in futures:
                parts[c] = p.render_chunk(s, per)
        for c, fut in futures.items():
            try:
                parts[c] = _uncrop(parts[0].shape, fut.result())
            except Exception as exc:  # noqa: BLE001  (the worker died or could not start: render that chunk here)
                self._lost_worker(exc)
                p.set_pose(pose_rad)
                parts[c] = p.render_chunk(seeds[c], per)
        acc = np.zeros_like(parts[0])
        for c in range(len(seeds)):
            acc += parts[c]
        return acc / len(seeds)

    def _lost_worker(self, exc: BaseException) -> None:
        if self._pool is not None:
            import warnings

            warnings.warn(f"aiming-camera worker process failed ({type(exc).__name__}); rendering its chunks in this "
                          "process (same frames, slower)", RuntimeWarning, stacklevel=3)
            self.close()

    def close(self) -> None:
        if self._pool is not None:
            _shutdown(self._pool)
            self._pool = None
