"""JSON results: written atomically, numpy-aware, NaN as null; every covariance in one shape
(:func:`covariance_block`)."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from rigsim.errors import InputError

from .atomic import atomic_write_bytes


def _plain(x):
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, Path):
        return str(x)
    return x


def write_json(path, obj) -> Path:
    """Write ``obj`` as indented JSON (NaN and infinities become null), atomically."""
    return atomic_write_bytes(path, (json.dumps(_plain(obj), indent=1, allow_nan=False) + "\n").encode())


MAX_JSON_DEPTH = 64
"""Deepest nesting of arrays and objects read (rigsim's own files nest at most 6 deep)."""
MAX_JSON_INT_DIGITS = 40
"""Longest integer literal read (a seed has at most 19 digits; Python refuses beyond 4300)."""
MAX_JSON_BYTES = 64 << 20
"""Largest JSON result read by default (rigsim's results are kB; a dataset's plan and manifest have their own limit)."""
_STRINGS = re.compile(r'"(?:[^"\\]|\\.)*"')


def json_depth(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` in JSON ``text`` (strings skipped), without parsing it."""
    b = np.frombuffer(_STRINGS.sub('""', text).encode("utf-8", "surrogatepass"), dtype=np.uint8)
    if not b.size:
        return 0
    step = (np.isin(b, (0x5B, 0x7B)).astype(np.int64) - np.isin(b, (0x5D, 0x7D)).astype(np.int64))
    return int(np.cumsum(step).max(initial=0))


def _int(text: str) -> int:
    if len(text.lstrip("-")) > MAX_JSON_INT_DIGITS:
        raise _Refused(f"an integer of {len(text.lstrip('-'))} digits; at most {MAX_JSON_INT_DIGITS} are read")
    return int(text)


class _Refused(ValueError):
    pass


def parse_json(data: bytes | str, path, what: str = "result", *, max_bytes: int | None = MAX_JSON_BYTES,
               error=InputError):
    """JSON ``data`` (the content of ``path``) parsed within bounds: at most ``max_bytes``, nesting at most
    :data:`MAX_JSON_DEPTH` deep, integers of at most :data:`MAX_JSON_INT_DIGITS` digits, checked before (or
    while) parsing; every problem one ``error`` naming the file."""
    if max_bytes is not None and len(data) > max_bytes:
        raise error(f"{path}: {len(data)} bytes; the {what} is read when it has at most {max_bytes >> 20} MiB")
    try:
        text = data.decode("utf-8") if isinstance(data, bytes) else data
    except UnicodeDecodeError:
        raise error(f"{path}: not UTF-8 text; expected the {what} as JSON") from None
    depth = json_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise error(f"{path}: JSON nested {depth} deep; the {what} is read when it nests at most {MAX_JSON_DEPTH} deep")
    try:
        return json.loads(text, parse_int=_int)
    except json.JSONDecodeError as exc:
        raise error(f"{path}: line {exc.lineno}, column {exc.colno}: not valid JSON ({exc.msg}); expected the {what}") from None
    except _Refused as exc:
        raise error(f"{path}: {exc}; expected the {what} as JSON") from None
    except (ValueError, RecursionError) as exc:
        raise error(f"{path}: not valid JSON ({str(exc)[:120]})") from None


def read_json(path, required: Sequence[str] = (), *, what: str = "result", max_bytes: int | None = MAX_JSON_BYTES) -> dict:
    """Read a JSON object (:func:`parse_json`'s bounds) and check that it has the ``required`` top-level keys."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file (the {what})" if not path.exists() else
                         f"{path}: not a regular file; expected the {what} as JSON")
    if max_bytes is not None and path.stat().st_size > max_bytes:
        raise InputError(f"{path}: {path.stat().st_size} bytes; the {what} is read when it has at most {max_bytes >> 20} MiB")
    obj = parse_json(path.read_bytes(), path, what, max_bytes=max_bytes)
    if not isinstance(obj, dict):
        raise InputError(f"{path}: a JSON {type(obj).__name__}; expected an object (the {what})")
    missing = [k for k in required if k not in obj]
    if missing:
        raise InputError(f"{path}: no key {missing[0]!r}; expected the {what} with {', '.join(required)}")
    return obj


SYMMETRY_TOLERANCE = 1e-6  # of the largest diagonal entry: a covariance read back is symmetrised within it


def covariance_block(names: Sequence[str], cov, units: Sequence[str]) -> dict:
    """The JSON shape of a covariance: the parameters' names, their units, the matrix (entry (i, j)
    in unit_i·unit_j; written exactly symmetric, (C + Cᵀ)/2) and the 1σ of each parameter."""
    c = np.asarray(cov, float)
    if c.shape != (len(names), len(names)) or len(units) != len(names):
        raise ValueError(f"covariance of shape {c.shape} for {len(names)} names and {len(units)} units")
    c = 0.5 * (c + c.T)
    return {"names": list(names), "units": list(units), "matrix": c.tolist(),
            "sigma": np.sqrt(np.clip(np.diag(c), 0.0, None)).tolist()}


def symmetric_covariance(c, *, where: str) -> np.ndarray:
    """A covariance read from a file, symmetrised: (C + Cᵀ)/2 when C − Cᵀ is within
    :data:`SYMMETRY_TOLERANCE` of its largest diagonal entry (rounding in a writer, a text round
    trip), and positive semi-definite within the same tolerance; otherwise refused naming ``where``."""
    c = np.asarray(c, float)
    n = c.shape[0] if c.ndim == 2 else 0
    if c.ndim != 2 or c.shape != (n, n) or not np.all(np.isfinite(c)):
        raise InputError(f"{where}: shape {c.shape}; expected a finite square matrix")
    scale = float(np.max(np.abs(np.diag(c)))) if n else 0.0
    tol = SYMMETRY_TOLERANCE * max(scale, 1e-300)
    asym = float(np.max(np.abs(c - c.T))) if n else 0.0
    if asym > tol:
        raise InputError(f"{where}: not symmetric (largest |C − Cᵀ| {asym:.3g}, {asym / max(scale, 1e-300):.3g} of the "
                         f"largest variance; allowed {SYMMETRY_TOLERANCE:g})")
    c = 0.5 * (c + c.T)
    lo = float(np.min(np.linalg.eigvalsh(c))) if n else 0.0
    if lo < -tol:
        raise InputError(f"{where}: not positive semi-definite (eigenvalue {lo:.3g} against a largest variance {scale:.3g})")
    return c
