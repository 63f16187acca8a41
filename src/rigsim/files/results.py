"""JSON results: written atomically, numpy-aware, NaN as null; every covariance in one shape
(:func:`covariance_block`)."""

from __future__ import annotations

import json
import math
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


def read_json(path, required: Sequence[str] = (), *, what: str = "result") -> dict:
    """Read a JSON object and check that it has the ``required`` top-level keys."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file (the {what})" if not path.exists() else
                         f"{path}: not a regular file; expected the {what} as JSON")
    try:
        obj = json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError:
        raise InputError(f"{path}: not UTF-8 text; expected the {what} as JSON") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: line {exc.lineno}, column {exc.colno}: not valid JSON ({exc.msg})") from None
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
