"""The rig families, in one plain-import table.

A family is the set of rigs one procedure serves: its seed documents, its rig schema and default
rig, its commands (``add_cli``), its dataset generators and its 3D view. Every layer has a module
named after each family (``rig/star.py``, ``truth/star.py``, ``estimation/star_*``,
``render/star.py``, ``procedures/star/``, ``dataset/generators/star.py``, ``view/star.py``);
this table ties them together for the ``rigsim`` command. docs/architecture.md explains how to
add a family.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from rigsim.dataset.generators import (
    AimingCameraGenerator,
    AutocollimatorGenerator,
    BoresightRoiGenerator,
    StarFieldGenerator,
    SunSensorGenerator,
)
from rigsim.procedures.boresight import cli as boresight_cli
from rigsim.procedures.cube_mirror import cli as cube_mirror_cli
from rigsim.procedures.star import cli as star_cli
from rigsim.rig.boresight import BoresightRig
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.load import DEFAULT_BORESIGHT_RIG, DEFAULT_RIG, DEFAULT_STAR_RIG
from rigsim.rig.star import StarRig
from rigsim.view.api import builder_for

__all__ = ["Family", "FAMILIES", "family_of"]


@dataclass(frozen=True)
class Family:
    name: str                        # the module name used in every layer
    seeds: tuple[str, ...]           # seed documents (``seed_document`` of its rig files)
    title: str
    rig_class: type
    default_rig: str                 # a file stem in scenes/
    add_cli: Callable[[dict], None]  # adds its commands to the parser groups {"top", "run", "render"}
    generators: tuple[type, ...]     # its dataset generators (``rigsim dataset generate --generator``)

    def view(self, rig, **options):
        """The family's 3D scene of ``rig`` (rigsim.view)."""
        return builder_for(rig)(rig, **options)


FAMILIES: tuple[Family, ...] = (
    Family("cube_mirror", ("000", "001"), "sun sensor and mirror cube on a turntable (diaphragm screen or autocollimator)",
           CubeMirrorRig, DEFAULT_RIG, cube_mirror_cli.add_cli,
           (SunSensorGenerator, AimingCameraGenerator, AutocollimatorGenerator)),
    Family("boresight", ("003",), "boresight of a dual line-array camera with a central prism",
           BoresightRig, DEFAULT_BORESIGHT_RIG, boresight_cli.add_cli, (BoresightRoiGenerator,)),
    Family("star", ("004",), "on-orbit calibration of a star sensor",
           StarRig, DEFAULT_STAR_RIG, star_cli.add_cli, (StarFieldGenerator,)),
)


def family_of(rig) -> Family:
    """The family of a rig object."""
    for f in FAMILIES:
        if isinstance(rig, f.rig_class):
            return f
    raise TypeError(f"{type(rig).__name__} is not the rig of any family ({', '.join(f.name for f in FAMILIES)})")
