"""Frame generators: one per kind of frame a rig produces, one module per rig family.

A generator is built from the rig file's *text* (so a worker on another machine rebuilds exactly
the same rig) and turns (frame index, frame parameters, seed) into (uint16 image, sidecar, one
row of the truth table). Its ``plan`` draws every frame's parameters up front from the dataset
seed (``SeedSequence([seed, index])``), so the dataset does not depend on worker count, order or
restarts. docs/datasets.md describes each kind.
"""

from __future__ import annotations

from rigsim.dataset.generators.aiming import AimingCameraGenerator
from rigsim.dataset.generators.autocollimator import AutocollimatorGenerator
from rigsim.dataset.generators.boresight import BoresightRoiGenerator
from rigsim.dataset.generators.cube_mirror import SunSensorGenerator
from rigsim.dataset.generators.star import StarFieldGenerator
from rigsim.errors import DatasetError

__all__ = [
    "AimingCameraGenerator",
    "AutocollimatorGenerator",
    "BoresightRoiGenerator",
    "StarFieldGenerator",
    "SunSensorGenerator",
    "generator_for_rig",
    "make_generator",
    "worker_generator",
]

GENERATORS: dict[str, type] = {g.kind: g for g in (SunSensorGenerator, AimingCameraGenerator, AutocollimatorGenerator,
                                                   StarFieldGenerator, BoresightRoiGenerator)}
"""``--generator`` name → generator class. Each class names the seed documents it renders (``seeds``)."""


def generator_for_rig(rig_text: str) -> str:
    """The default generator of a rig file (by its seed_document; none: a cube-mirror rig): the first
    generator naming that seed, i.e. ``sun-sensor`` for both cube-mirror seeds."""
    import tomllib

    sd = str(tomllib.loads(rig_text).get("seed_document", "000"))
    for kind, cls in GENERATORS.items():
        if sd in cls.seeds:
            return kind
    return SunSensorGenerator.kind


def make_generator(kind: str, rig_text: str, rig_source: str, **opts):
    if kind not in GENERATORS:
        raise DatasetError(f"--generator {kind!r}: allowed {', '.join(sorted(GENERATORS))}")
    return GENERATORS[kind](rig_text, rig_source, **opts)


_WORKER_CACHE: dict[tuple, object] = {}


def worker_generator(kind: str, rig_text: str, rig_source: str, opts: dict):
    """The generator of this worker process (built once per process: its Mitsuba state)."""
    import hashlib
    import json

    key = (kind, hashlib.sha256(rig_text.encode()).hexdigest(), json.dumps(opts, sort_keys=True))
    g = _WORKER_CACHE.get(key)
    if g is None:
        g = _WORKER_CACHE[key] = make_generator(kind, rig_text, rig_source, **opts)
    return g
