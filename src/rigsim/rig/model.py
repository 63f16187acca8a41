"""The base of every rig schema: unknown fields refused, frozen, and numbers that are numbers — a
boolean or a string is not accepted where a number is expected (pydantic's lax mode would take
``true`` as 1 and ``"3.0"`` as 3.0), and NaN or infinity nowhere."""

from __future__ import annotations

import typing

from pydantic import BaseModel, ConfigDict, ValidationInfo, field_validator


def _leaves(tp) -> set:
    args = typing.get_args(tp)
    if typing.get_origin(tp) is typing.Annotated:
        return _leaves(args[0])
    if not args:
        return {tp}
    out = set()
    for a in args:
        if a is not Ellipsis:
            out |= _leaves(a)
    return out


def _numeric(tp) -> bool:
    leaves = _leaves(tp) - {type(None)}
    return bool(leaves) and leaves <= {float, int}


def _bad_number(v) -> object | None:
    """The first boolean or text found where numbers are expected (None: all fine)."""
    if isinstance(v, (bool, str, bytes)):
        return v
    if isinstance(v, (list, tuple)):
        for x in v:
            b = _bad_number(x)
            if b is not None:
                return b
    return None


class RigModel(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True, allow_inf_nan=False)

    @field_validator("*", mode="before")
    @classmethod
    def _numbers_are_numbers(cls, v, info: ValidationInfo):
        f = cls.model_fields.get(info.field_name)
        if f is not None and _numeric(f.annotation):
            b = _bad_number(v)
            if b is not None:
                what = "a boolean" if isinstance(b, bool) else "text"
                raise ValueError(f"a number is expected, found {what} ({b!r})")
        return v


