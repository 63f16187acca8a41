"""What every dataset generator shares: the ``--sweep`` grammar and the truth-table row type."""

from __future__ import annotations

import math

import numpy as np

from rigsim.errors import DatasetError
from rigsim.files.numbers import parse_float


def parse_sweep(spec: str, allowed: list[str]) -> dict[str, np.ndarray]:
    """``"X=-60:60:5 Y=0,10,20"`` → {axis: values (deg)}; ranges are inclusive of both ends."""
    out: dict[str, np.ndarray] = {}
    for part in spec.replace(";", " ").split():
        if "=" not in part:
            raise DatasetError(f"--sweep {spec!r}: '{part}' is not NAME=VALUES (e.g. X=-60:60:5 or Y=0,10,20)")
        name, vals = part.split("=", 1)
        if name not in allowed:
            raise DatasetError(f"--sweep {spec!r}: '{name}' is not sweepable; allowed: {', '.join(allowed)}")
        if name in out:
            raise DatasetError(f"--sweep {spec!r}: '{name}' given twice")
        try:
            if ":" in vals:
                a, b, s = (parse_float(x) for x in vals.split(":"))
                if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(s)) or s <= 0 or b < a:
                    raise ValueError
                n = int(math.floor((b - a) / s + 1e-9)) + 1
                if n > 100000:
                    raise DatasetError(f"--sweep {spec!r}: {name} has {n} values (max 100000)")
                v = a + s * np.arange(n)
            else:
                v = np.array([parse_float(x) for x in vals.split(",")])
            if not np.all(np.isfinite(v)):
                raise ValueError
        except (ValueError, OverflowError):
            raise DatasetError(f"--sweep {spec!r}: '{vals}' must be START:STOP:STEP (finite, STEP > 0, STOP ≥ START) "
                               "or a comma list of finite numbers") from None
        out[name] = v
    if not out:
        raise DatasetError(f"--sweep {spec!r}: empty")
    total = math.prod(len(v) for v in out.values())
    if total > MAX_SWEEP_FRAMES:
        raise DatasetError(f"--sweep {spec!r}: the grid has {total} poses (at most {MAX_SWEEP_FRAMES}, as --frames)")
    return out


MAX_SWEEP_FRAMES = 10_000_000


TruthRow = dict
