"""One render loop for every rigsim scene (Eradiate's habit).

A scene is a list of elements. Each element emits its part of the Mitsuba scene dict
(:meth:`SceneElement.template`) and, per frame, a parameter-update map
(:meth:`SceneElement.updates`: ``{"<key>.<parameter>": value}`` for ``mi.traverse``, built from the
frame's *state*, a plain dict such as ``{"window_origin": (u0, v0), "sun_dir": s}``). A
:class:`Scene` loads the dict once; :meth:`Scene.render` applies the updates (no rebuild, no
recompile) and renders. The detector stage is :func:`rigsim.render.frame.digitise`, which returns the
one :class:`~rigsim.render.frame.Frame` type: update → render → detector.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from rigsim.render.backend import ensure_variant

__all__ = ["SceneElement", "Element", "PinholeSensor", "Scene"]


def mitsuba_seed(seed: int, *stream: int) -> int:
    """Mitsuba's sampler seed (an unsigned 32-bit integer) for any integer ``seed`` and optional
    sub-streams: a seed already in [0, 2³²) without streams is used as is (so frames stay the
    same); anything else is hashed into that range (numpy's SeedSequence)."""
    seed = int(seed)
    if not stream and 0 <= seed < 2**32:
        return seed
    words = [0x5EED, len(stream), int(seed < 0), abs(seed) & (2**64 - 1), abs(seed) >> 64, *(int(s) & (2**64 - 1) for s in stream)]
    return int(np.random.SeedSequence(words).generate_state(1, np.uint32)[0])


class SceneElement:
    """Base of a scene element: a part of the Mitsuba scene dict and its per-frame updates."""

    def template(self) -> dict:
        raise NotImplementedError

    def updates(self, state: Mapping) -> dict:
        return {}


@dataclass
class Element(SceneElement):
    """A fixed piece of the scene dict (``{key: mitsuba}``) and an optional update map
    ``update(state) -> {"key.param": value}``."""

    key: str
    mitsuba: dict
    update: Callable[[Mapping], dict] | None = None

    def template(self) -> dict:
        return {self.key: self.mitsuba}

    def updates(self, state: Mapping) -> dict:
        return self.update(state) if self.update is not None else {}


class PinholeSensor(SceneElement):
    """rigsim's distorted pinhole sensor (``rigsim_pinhole``) for a
    :class:`~rigsim.optics.camera.PinholeBrown`: its film is a ``width`` × ``height`` window of the
    detector whose pixel (0, 0) is detector pixel ``state["window_origin"]`` (moved per frame)."""

    def __init__(self, camera, *, width: int, height: int, spp: int, sampler: str = "ldsampler",
                 response: str = "flux", key: str = "sensor"):
        self.camera, self.key = camera, key
        self.width, self.height, self.spp, self.sampler, self.response = int(width), int(height), int(spp), sampler, response

    def template(self) -> dict:
        from rigsim.render.plugins import PINHOLE_PLUGIN, register_sensors

        register_sensors()
        c = self.camera
        return {self.key: {
            "type": PINHOLE_PLUGIN,
            "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy,
            "k1": c.k1, "k2": c.k2, "k3": c.k3, "p1": c.p1, "p2": c.p2,
            "detector_width": c.width, "detector_height": c.height,
            "window_u0": 0, "window_v0": 0, "response": self.response,
            "film": {"type": "hdrfilm", "width": self.width, "height": self.height, "rfilter": {"type": "box"},
                     "pixel_format": "luminance"},
            "sampler": {"type": self.sampler, "sample_count": self.spp},
        }}

    def updates(self, state: Mapping) -> dict:
        if "window_origin" not in state:
            return {}
        import mitsuba as mi

        u0, v0 = state["window_origin"]
        return {f"{self.key}.window_origin": mi.Point2f(float(u0), float(v0))}


class Scene:
    """A Mitsuba scene built once from elements; :meth:`render` = update → render."""

    def __init__(self, integrator: dict, elements: Sequence[SceneElement]):
        self.variant = ensure_variant()
        import mitsuba as mi

        d = {"type": "scene", "integrator": dict(integrator)}
        for e in elements:
            part = e.template()
            clash = set(part) & set(d)
            if clash:
                raise ValueError(f"scene keys {sorted(clash)} are emitted twice")
            d.update(part)
        self.elements = list(elements)
        self.scene_dict = d
        _collect_stale_scenes()
        self.scene = mi.load_dict(d)
        self.params = mi.traverse(self.scene)

    @classmethod
    def from_dict(cls, scene_dict: Mapping, updates: Mapping[str, Callable[[Mapping], dict]] | None = None) -> "Scene":
        """A scene from a whole scene dict: one element per top-level key, with the update maps of
        ``updates`` ({key: update(state) -> {"key.param": value}})."""
        updates = dict(updates or {})
        d = dict(scene_dict)
        integrator = d.pop("integrator")
        d.pop("type", None)
        unknown = set(updates) - set(d)
        if unknown:
            raise ValueError(f"updates for keys not in the scene: {sorted(unknown)}")
        return cls(integrator, [Element(k, v, updates.get(k)) for k, v in d.items()])

    def update(self, state: Mapping | None) -> None:
        """Apply every element's updates for ``state`` through ``mi.traverse`` (no recompile)."""
        if not state:
            return
        changes: dict = {}
        for e in self.elements:
            changes.update(e.updates(state))
        if changes:
            for k, v in changes.items():
                self.params[k] = v
            self.params.update()

    def render(self, state: Mapping | None = None, *, seed: int = 0, spp: int | None = None,
               single_thread: bool = False, progress: Callable[[int, int], None] | None = None) -> np.ndarray:
        """Update for ``state``, render, return the film as a 2-D float64 array (rows v, columns u).

        ``single_thread``: render with one Dr.Jit thread (light tracers splat with float32 atomic
        adds whose order varies between threads; one thread makes the image bit-identical).
        A render of more than :data:`PASS_SAMPLES` light paths runs in passes (:func:`render_passes`);
        ``progress(done, passes)`` is called after each."""
        import drjit as dr

        self.update(state)
        sensor = self.scene.sensors()[0]
        total = int(spp) if spp is not None else int(sensor.sampler().sample_count())
        passes, per_pass = render_passes(total, int(np.prod(sensor.film().crop_size())))
        prev = dr.thread_count()
        if single_thread and prev != 1:
            dr.set_thread_count(1)
        try:
            if passes == 1:
                kw = {} if spp is None else {"spp": total}
                arr = np.array(_mi_render(self.scene, seed=mitsuba_seed(seed), **kw), dtype=np.float64)
            else:  # equal passes with their own seeds, averaged: the same estimator as one pass of all samples
                import sys

                from tqdm import tqdm

                arr = None
                with tqdm(total=passes, desc=f"render ({total} spp in {passes} passes)", unit="pass", leave=False,
                          disable=None if progress is None else True, file=sys.stderr) as bar:
                    for k in range(passes):
                        a = np.array(_mi_render(self.scene, seed=mitsuba_seed(seed, 0x9A55, k), spp=per_pass),
                                     dtype=np.float64)
                        arr = a if arr is None else arr + a
                        bar.update(1)
                        if progress is not None:
                            progress(k + 1, passes)
                arr /= passes
        finally:
            if dr.thread_count() != prev:
                dr.set_thread_count(prev)
        return arr[..., 0] if arr.ndim == 3 else arr


def _collect_stale_scenes() -> None:
    """Free the Mitsuba objects of earlier scenes that only a Python reference cycle still holds. Dr.Jit's
    vcalls over emitters trace every live emitter instance of the process, not only this scene's; an
    area emitter whose shape is already gone then calls into a destroyed shape ("Shape::sample_position():
    not implemented", or a crash) in the next light-tracer render."""
    import gc

    gc.collect()


def _mi_render(scene, **kw):
    """``mi.render``, retried once after :func:`_collect_stale_scenes` when a stale instance of another
    scene broke the trace of a vcall."""
    import mitsuba as mi

    try:
        return mi.render(scene, **kw)
    except RuntimeError as exc:
        if "not implemented" not in str(exc) and "not implemented" not in str(exc.__cause__ or ""):
            raise
    _collect_stale_scenes()
    return mi.render(scene, **kw)


PASS_SAMPLES = 2**30  # light paths per Mitsuba pass: below its 2^32 wavefront limit, whose own split fails


def render_passes(spp: int, pixels: int, limit: int | None = None) -> tuple[int, int]:
    """(passes, samples per pixel per pass) for ``spp`` samples on ``pixels``: the fewest equal passes of at
    most ``limit`` light paths each. A power-of-4 ``spp`` (the ldsampler's) is split into powers of 4."""
    limit = PASS_SAMPLES if limit is None else int(limit)
    spp, pixels = int(spp), int(pixels)
    power_of_4 = spp & (spp - 1) == 0 and (spp.bit_length() - 1) % 2 == 0
    for passes in range(1, spp + 1):
        if spp % passes or (power_of_4 and (passes.bit_length() - 1) % 2) or passes & (passes - 1) and power_of_4:
            continue
        if (spp // passes) * pixels <= limit:
            return passes, spp // passes
    from rigsim.errors import CliError

    raise CliError(f"spp = {spp} on {pixels} pixels: {spp * pixels:.3g} light paths cannot be split into equal "
                   f"passes of at most {limit:.3g}")
