"""Load and validate seed-003 rig files into :class:`~rigsim.boresight.schema.BoresightRig`.

Errors are :class:`rigsim.rig.load.RigError` (file, field, value, allowed range), built with the
helpers of :mod:`rigsim.rig.load`; only the model class differs.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from pydantic import BaseModel, ValidationError

from rigsim.rig.load import RigError, _allowed, _dotted, _field_at, _inner, resolve_rig_path

from .schema import BoresightRig

__all__ = ["load_boresight_rig", "parse_boresight_rig", "DEFAULT_RIG", "RigError"]

DEFAULT_RIG = "dual_line_array_prism"


def _describe(err: dict, model: type[BaseModel] = BoresightRig) -> str:
    """One validation error as 'field `a.b` = value: message; allowed: …' (as rigsim.rig.load)."""
    loc = tuple(err.get("loc", ()))
    field = _dotted(loc)
    etype = err.get("type", "")
    value = err.get("input")
    if etype == "extra_forbidden":
        target = model
        if len(loc) > 1:
            _, pinfo = _field_at(model, tuple(k for k in loc[:-1] if not isinstance(k, int)))
            target = _inner(pinfo.annotation, list) if pinfo is not None else None
        keys = sorted(target.model_fields) if isinstance(target, type) and issubclass(target, BaseModel) else []
        allowed = f" (allowed keys here: {', '.join(keys)})" if keys else ""
        return f"unknown key `{field}`{allowed}"
    if etype == "missing":
        return f"field `{field}` is required but missing"
    _, info = _field_at(model, loc)
    allowed = _allowed(info)
    msg = err.get("msg", "invalid")
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    if isinstance(value, dict):
        where = f"table `[{field}]`" if loc else "the rig"
        return f"in {where}: {msg}"
    shown = repr(value)
    if len(shown) > 80:
        shown = shown[:77] + "..."
    tail = f"; {allowed}" if allowed and allowed.split(": ", 1)[-1] not in msg else ""
    return f"field `{field}` = {shown}: {msg}{tail}"


def parse_boresight_rig(data: dict, source: str | Path = "<dict>") -> BoresightRig:
    try:
        return BoresightRig.model_validate(data)
    except ValidationError as exc:
        raise RigError(source, [_describe(e) for e in exc.errors()]) from None


def load_boresight_rig(name_or_path: str | Path = DEFAULT_RIG) -> BoresightRig:
    """A path, or the stem of a file in scenes/ (default ``dual_line_array_prism``)."""
    path = resolve_rig_path(name_or_path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise RigError(path, [f"cannot read file: {exc.strerror}"]) from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise RigError(path, [f"not UTF-8 text (byte {exc.start})"]) from None
    except tomllib.TOMLDecodeError as exc:
        raise RigError(path, [f"TOML syntax error: {exc}"]) from None
    if data.get("seed_document") not in (None, "003"):
        raise RigError(path, [f"field `seed_document` = {data.get('seed_document')!r}: this is not a seed-003 rig "
                              "(use `rigsim run cube-mirror` for seeds 000/001)"])
    return parse_boresight_rig(data, path)
