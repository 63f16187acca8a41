"""Tables as CSV or Parquet with the unit in each column name (``x_deg``, ``u_px``, ``sigma_u_px``).

A :class:`Column` names what a stage needs; :func:`read_table` finds it in the header, refuses a
column in another unit (``x_rad`` where ``x_deg`` is expected) and parses every cell, each problem
one :class:`~rigsim.errors.InputError` naming the file, the line (CSV, 1-based with the header as
line 1) or row (Parquet, 0-based) and the column."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rigsim.errors import InputError

from .atomic import atomic_write_bytes
from .numbers import parse_float, parse_int

UNITS = {"deg": "degrees", "rad": "radians", "mrad": "milliradians", "urad": "microradians", "arcmin": "arcminutes",
         "arcsec": "arcseconds", "mas": "milliarcseconds", "px": "pixels", "nm": "nanometres", "um": "micrometres",
         "mm": "millimetres", "cm": "centimetres", "m": "metres", "km": "kilometres", "s": "seconds", "ms": "milliseconds",
         "us": "microseconds", "ns": "nanoseconds", "min": "minutes", "h": "hours", "dn": "DN", "e": "electrons"}
LINE = "__line__"  # key of the returned source line (CSV) or row (Parquet) numbers


@dataclass(frozen=True)
class Column:
    """A column a stage reads: ``name`` and ``unit`` (the header is ``<name>_<unit>``, or ``name`` when
    unitless), its kind (``float``, ``int``, ``str``), whether it is required, whether an empty or
    NaN cell is allowed (``float`` only: read as NaN), and other accepted header spellings."""

    name: str
    unit: str | None = None
    kind: str = "float"
    required: bool = True
    allow_nan: bool = False
    aliases: tuple[str, ...] = ()

    @property
    def key(self) -> str:
        return f"{self.name}_{self.unit}" if self.unit else self.name

    def describe(self) -> str:
        return f"{self.key} ({UNITS.get(self.unit, self.unit)})" if self.unit else self.key


def _rows_csv(path: Path) -> tuple[list[str], list[tuple[int, list[str]]]]:
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte {exc.start}); expected a CSV table") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    reader = csv.reader(io.StringIO(text))
    header: list[str] | None = None
    rows = []
    try:
        for rec in reader:
            line = reader.line_num
            if not rec or all(not c.strip() for c in rec) or rec[0].lstrip().startswith("#"):
                continue
            if header is None:
                header = [c.strip() for c in rec]
                continue
            if len(rec) != len(header):
                raise InputError(f"{path}: line {line}: {len(rec)} fields; expected {len(header)} like the header")
            rows.append((line, [c.strip() for c in rec]))
    except csv.Error as exc:
        raise InputError(f"{path}: line {reader.line_num}: not valid CSV ({exc})") from None
    if header is None:
        raise InputError(f"{path}: empty table; expected a header line and one row per record")
    return header, rows


def _rows_parquet(path: Path) -> tuple[list[str], list[tuple[int, list]]]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        t = pq.read_table(path)
    except (OSError, ValueError, pa.ArrowException) as exc:
        raise InputError(f"{path}: not a readable Parquet file ({type(exc).__name__})") from None
    header = list(t.column_names)
    cols = [t.column(i).to_pylist() for i in range(len(header))]
    return header, [(i, [c[i] for c in cols]) for i in range(t.num_rows)]


def _where(path: Path, parquet: bool, line: int, key: str) -> str:
    return f"{path}: {'row' if parquet else 'line'} {line}, column {key}"


def _parse(path, parquet, line, col: Column, cell):
    if cell is None or (isinstance(cell, str) and cell.strip() == ""):
        if col.kind == "float" and col.allow_nan:
            return math.nan
        raise InputError(f"{_where(path, parquet, line, col.key)}: empty cell; "
                         f"expected {'a number' if col.kind != 'str' else 'a value'}")
    if col.kind == "str":
        return str(cell)
    if isinstance(cell, bool):
        raise InputError(f"{_where(path, parquet, line, col.key)}: {cell!r} is a boolean; expected a number")
    try:
        if isinstance(cell, str):  # ASCII digits only: float('١٢') is 12 and int('1_0') is 10
            x = parse_float(cell) if col.kind == "float" else parse_int(cell)
        else:
            x = float(cell) if col.kind == "float" else int(cell)
        if col.kind == "int" and not -2**63 <= x < 2**63:
            raise ValueError
    except (TypeError, ValueError, OverflowError):
        want = "a number in ASCII digits" if col.kind == "float" else "an integer in ASCII digits, at most 2⁶³"
        raise InputError(f"{_where(path, parquet, line, col.key)}: {str(cell)[:40]!r} is not {want}") from None
    if col.kind == "float" and not math.isfinite(x) and not (col.allow_nan and math.isnan(x)):
        raise InputError(f"{_where(path, parquet, line, col.key)}: {cell!r}; expected a finite number")
    return x


def _find(path: Path, header: list[str], col: Column) -> int | None:
    for name in (col.key, *col.aliases):
        if name in header:
            return header.index(name)
    if col.unit:
        other = [h for h in header if h.startswith(col.name + "_") and h[len(col.name) + 1:] in UNITS]
        if other:
            raise InputError(f"{path}: column {other[0]}: expected {col.describe()}, got "
                             f"{UNITS[other[0][len(col.name) + 1:]]}")
    if col.required:
        raise InputError(f"{path}: no column {col.describe()}; the header has {', '.join(header) or 'nothing'}")
    return None


def read_table(path, columns: Sequence[Column], *, what: str = "table") -> dict[str, np.ndarray]:
    """Read ``columns`` from a CSV or Parquet table: {key: array} (float64, int64 or str objects),
    plus the extra columns as strings and ``"__line__"`` (each row's CSV line / Parquet row)."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file (the {what})")
    if not path.is_file():
        raise InputError(f"{path}: not a regular file; expected the {what} as .csv or .parquet")
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".parquet"):
        raise InputError(f"{path}: unsupported {what} file type {suffix or '(none)'!r}; expected .csv or .parquet")
    parquet = suffix == ".parquet"
    header, rows = _rows_parquet(path) if parquet else _rows_csv(path)
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise InputError(f"{path}: column {dup[0]} appears twice in the header")
    out: dict[str, np.ndarray] = {}
    used = set()
    for col in columns:
        j = _find(path, header, col)
        if j is None:
            continue
        used.add(j)
        vals = [_parse(path, parquet, line, col, r[j]) for line, r in rows]
        dtype = {"float": np.float64, "int": np.int64, "str": object}[col.kind]
        out[col.key] = np.array(vals, dtype=dtype)
    for j, h in enumerate(header):
        if j not in used and h not in out:
            out[h] = np.array(["" if r[j] is None else str(r[j]) for _, r in rows], dtype=object)
    out[LINE] = np.array([line for line, _ in rows], dtype=np.int64)
    return out


def _cell(x) -> str:
    if isinstance(x, (float, np.floating)):
        return repr(float(x)) if math.isfinite(x) else ("nan" if math.isnan(x) else repr(float(x)))
    if isinstance(x, (np.integer,)):
        return str(int(x))
    return str(x)


def write_table(path, columns: dict[str, Sequence]) -> Path:
    """Write {header: values} as CSV (floats at full precision: they read back bit-identical) or
    Parquet, by the suffix, atomically."""
    path = Path(path)
    names = list(columns)
    data = [list(np.asarray(columns[k], dtype=object)) if np.ndim(columns[k]) else [columns[k]] for k in names]
    n = {len(c) for c in data}
    if len(n) > 1:
        raise ValueError(f"columns of unequal length: {dict(zip(names, map(len, data)))}")
    if path.suffix.lower() == ".parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        buf = io.BytesIO()
        pq.write_table(pa.table({k: np.asarray(columns[k]) for k in names}), buf)
        return atomic_write_bytes(path, buf.getvalue())
    if path.suffix.lower() != ".csv":
        raise InputError(f"{path}: unsupported table file type {path.suffix!r}; expected .csv or .parquet")
    s = io.StringIO()
    w = csv.writer(s, lineterminator="\n")
    w.writerow(names)
    for row in zip(*data):
        w.writerow([_cell(x) for x in row])
    return atomic_write_bytes(path, s.getvalue().encode())
