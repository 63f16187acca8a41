"""Load and validate seed-003 rig files into :class:`~rigsim.boresight.schema.BoresightRig`.

Errors are :class:`rigsim.rig.load.RigError` (file, field, value, allowed range), built with the
helpers of :mod:`rigsim.rig.load`; only the model class differs.
"""

from __future__ import annotations

from pathlib import Path

from rigsim.rig.load import RigError, parse_model, read_rig_toml, resolve_rig_path

from .schema import BoresightRig

__all__ = ["load_boresight_rig", "parse_boresight_rig", "DEFAULT_RIG", "RigError"]

DEFAULT_RIG = "dual_line_array_prism"


def parse_boresight_rig(data: dict, source: str | Path = "<dict>") -> BoresightRig:
    return parse_model(BoresightRig, data, source)


def load_boresight_rig(name_or_path: str | Path = DEFAULT_RIG) -> BoresightRig:
    """A path, or the stem of a file in scenes/ (default ``dual_line_array_prism``)."""
    path = resolve_rig_path(name_or_path)
    data = read_rig_toml(path)
    if data.get("seed_document") not in (None, "003"):
        raise RigError(path, [f"field `seed_document` = {data.get('seed_document')!r}: this is not a seed-003 rig "
                              "(use `rigsim run cube-mirror` for seeds 000/001)"])
    return parse_boresight_rig(data, path)
