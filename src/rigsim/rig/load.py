"""Load and validate rig files (TOML) into :class:`~rigsim.rig.cube_mirror.CubeMirrorRig`.

Every problem becomes one :class:`RigError` whose message names the file, the field, the
value and the allowed range — never a traceback from inside pydantic or tomllib.
"""

from __future__ import annotations

import importlib.resources
import tomllib
import typing
from pathlib import Path

import annotated_types as at
from pydantic import BaseModel, ValidationError

from rigsim.errors import RigError
from rigsim.rig.boresight import BoresightRig
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.star import StarRig

SCENES_DIR = Path(str(importlib.resources.files("rigsim") / "scenes")).resolve()
"""The default rigs shipped with the package (in the repository: the top-level scenes/ folder)."""


def _field_at(model: type[BaseModel], loc: tuple) -> tuple[type[BaseModel] | None, object | None]:
    """Walk ``loc`` through the model; return (parent model class, FieldInfo of the last key)."""
    cls: object = model
    info = None
    parent = None
    for key in loc:
        if isinstance(key, int):
            cls = _inner(cls, list)
            continue
        if isinstance(cls, type) and issubclass(cls, BaseModel):
            parent = cls
            info = cls.model_fields.get(key)
            if info is None:
                return parent, None
            cls = _strip(info.annotation)
        else:
            cls = _inner(cls, dict)
            info = None
    return parent, info


def _strip(tp):
    """Unwrap Optional / Annotated to the concrete class."""
    origin = typing.get_origin(tp)
    if origin is typing.Annotated:
        return _strip(typing.get_args(tp)[0])
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return _strip(args[0]) if len(args) == 1 else tp
    return tp


def _inner(tp, container):
    tp = _strip(tp)
    if typing.get_origin(tp) in (list, dict):
        args = typing.get_args(tp)
        return _strip(args[-1])
    return tp


def _allowed(info) -> str:
    if info is None:
        return ""
    lo = hi = None
    for m in info.metadata:
        if isinstance(m, at.Ge):
            lo = f"≥ {m.ge}"
        elif isinstance(m, at.Gt):
            lo = f"> {m.gt}"
        elif isinstance(m, at.Le):
            hi = f"≤ {m.le}"
        elif isinstance(m, at.Lt):
            hi = f"< {m.lt}"
    parts = [p for p in (lo, hi) if p]
    if parts:
        return "allowed: " + " and ".join(parts)
    ann = typing.get_origin(_strip(info.annotation))
    if ann is typing.Literal:
        return "allowed: one of " + ", ".join(repr(a) for a in typing.get_args(_strip(info.annotation)))
    return ""


def _dotted(loc: tuple) -> str:
    out = ""
    for k in loc:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else str(k))
    return out or "(top level)"


def describe_error(err: dict, model: type[BaseModel]) -> str:
    """One pydantic validation error of ``model`` as one line: 'field `a.b` = value: message;
    allowed: …' (or the unknown key with the keys allowed there). Shared by every rig family."""
    loc = tuple(err.get("loc", ()))
    field = _dotted(loc)
    etype = err.get("type", "")
    value = err.get("input")
    if etype == "extra_forbidden":
        target = model
        if len(loc) > 1:
            _, pinfo = _field_at(model, loc[:-1])
            target = _inner(pinfo.annotation, list) if pinfo is not None else None
            if isinstance(loc[-2], int) or target is None:
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
    if isinstance(value, dict):  # a check across several fields of one table
        where = f"table `[{field}]`" if loc else "the rig"
        return f"in {where}: {msg}"
    shown = repr(value)
    if len(shown) > 80:
        shown = shown[:77] + "..."
    tail = f"; {allowed}" if allowed and allowed.split(": ", 1)[-1] not in msg else ""
    return f"field `{field}` = {shown}: {msg}{tail}"


def parse_model(model: type[BaseModel], data: dict, source: str | Path = "<dict>"):
    """Validate ``data`` as ``model``; every problem becomes one line of a :class:`RigError`."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise RigError(source, [describe_error(e, model) for e in exc.errors()]) from None


def parse_rig(data: dict, source: str | Path = "<dict>") -> CubeMirrorRig:
    return parse_model(CubeMirrorRig, data, source)


def resolve_rig_path(name_or_path: str | Path) -> Path:
    """A path, or a rig name (``sun_sensor_2axis_diaphragm``): ``NAME.toml`` in the current folder
    first, then the packaged default rigs."""
    p = Path(name_or_path)

    def there(q: Path, file: bool = False) -> bool:  # a name too long or through a non-folder is simply absent
        try:
            return q.is_file() if file else q.exists()
        except OSError:
            return False

    if p.suffix == ".toml" and there(p):
        return p
    fname = p.name if p.suffix == ".toml" else f"{p.name}.toml"
    if len(p.parts) == 1:
        for cand in (Path.cwd() / fname, SCENES_DIR / fname):
            if there(cand, file=True):
                return cand
    if there(p):
        return p
    known = ", ".join(sorted(x.stem for x in SCENES_DIR.glob("*.toml"))) or "(none)"
    raise RigError(name_or_path, [f"no such rig file; give a path or one of the default rigs: {known}"])


MAX_RIG_FILE_BYTES = 1 << 20  # a rig file is a few kB; anything near this is not one


def read_rig_text(path: Path) -> str:
    """The text of a rig file: a regular file (not a folder, FIFO or device) of at most 1 MiB of UTF-8."""
    import stat

    path = Path(path)
    try:
        st = path.stat()
    except OSError as exc:
        raise RigError(path, [f"cannot read file: {exc.strerror}"]) from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file (a FIFO, socket or device)"
        raise RigError(path, [f"is {kind}; expected a TOML rig file"])
    if st.st_size > MAX_RIG_FILE_BYTES:
        raise RigError(path, [f"{st.st_size} bytes; a rig file has at most {MAX_RIG_FILE_BYTES} bytes"])
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise RigError(path, [f"cannot read file: {exc.strerror}"]) from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RigError(path, [f"not UTF-8 text (byte {exc.start})"]) from None


def parse_rig_text(text: str, path) -> dict:
    """The TOML table of a rig file's text; malformed (or absurdly nested) TOML raises RigError."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RigError(path, [f"TOML syntax error: {exc}"]) from None
    except RecursionError:
        raise RigError(path, ["TOML nested too deeply to be a rig file"]) from None


def read_rig_toml(path: Path) -> dict:
    """The TOML table of a rig file; unreadable, non-UTF-8 or malformed files raise RigError."""
    return parse_rig_text(read_rig_text(path), path)


# The schema of each rig family, and the seed documents it describes (plain imports: the rig layer
# knows every family's schema; families.py ties each family to its procedures, views and generators).
RIG_MODELS: dict[str, type[BaseModel]] = {"000": CubeMirrorRig, "001": CubeMirrorRig, "003": BoresightRig, "004": StarRig}

DEFAULT_RIG = "sun_sensor_2axis_diaphragm"
DEFAULT_BORESIGHT_RIG = "dual_line_array_prism"
DEFAULT_STAR_RIG = "star_sensor"


def load_any_rig(name_or_path: str | Path):
    """Load a rig file of any family (its ``seed_document`` picks the schema; none: seeds 000/001)."""
    path = resolve_rig_path(name_or_path)
    data = read_rig_toml(path)
    model = RIG_MODELS.get(str(data.get("seed_document", "")), CubeMirrorRig)
    return parse_model(model, data, path)


def _load(name_or_path, model: type[BaseModel], wrong_family: str):
    path = resolve_rig_path(name_or_path)
    data = read_rig_toml(path)
    sd = data.get("seed_document")
    if sd is not None and RIG_MODELS.get(str(sd), CubeMirrorRig) is not model:
        raise RigError(path, [f"field `seed_document` = {sd!r}: {wrong_family}"])
    return parse_model(model, data, path)


def load_rig(name_or_path: str | Path = DEFAULT_RIG) -> CubeMirrorRig:
    """A turntable/cube-mirror rig (seeds 000, 001). Other families: :func:`load_any_rig`."""
    return _load(name_or_path, CubeMirrorRig,
                 "this command needs a turntable/cube-mirror rig (seed_document '000' or '001')")


def load_boresight_rig(name_or_path: str | Path = DEFAULT_BORESIGHT_RIG) -> BoresightRig:
    """A dual line-array camera rig (seed 003)."""
    return _load(name_or_path, BoresightRig, "this is not a seed-003 rig (`rigsim run cube-mirror` takes seeds "
                                             "000/001, `rigsim run star-calibration` seed 004)")


def load_star_rig(name_or_path: str | Path = DEFAULT_STAR_RIG) -> StarRig:
    """A star-sensor rig (seed 004)."""
    return _load(name_or_path, StarRig, "this is not a seed-004 star-sensor rig")


def parse_boresight_rig(data: dict, source: str | Path = "<dict>") -> BoresightRig:
    return parse_model(BoresightRig, data, source)


def parse_star_rig(data: dict, source: str | Path = "<dict>") -> StarRig:
    return parse_model(StarRig, data, source)


def default_rigs() -> list[Path]:
    return sorted(SCENES_DIR.glob("*.toml"))
