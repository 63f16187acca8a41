"""``rigsim readings`` (every reading of every seed document, with its options, default and the claims it
changes) and ``rigsim check-matrix`` (is a printed 3×3 matrix a rotation; the simplest sign repair)."""

from __future__ import annotations

import argparse
import json
import re
import textwrap

import numpy as np

from rigsim.errors import CliError
from rigsim.files.options import number
from rigsim.files.outputs import declare

__all__ = ["add_cli", "parse_matrix"]


def add_cli(groups: dict) -> None:
    p = groups["top"].add_parser(
        "readings", formatter_class=argparse.RawDescriptionHelpFormatter,
        help="how rigsim reads each inconsistent or lost equation of the seed documents, and how to choose another",
        description="Every reading of every seed document: what the document prints, the options (rigsim's default "
                    "marked *), why the default, how to select another, and the claims whose verdict changes.",
        epilog="examples:\n  rigsim readings\n  rigsim readings --seed 004\n  rigsim readings 000:eq8 --evaluate\n"
               "  rigsim readings --json readings.json")
    p.add_argument("key", nargs="?", default=None, help="one reading, as KEY or SEED:KEY (e.g. 000:eq8)")
    p.add_argument("--seed", default=None, choices=["000", "001", "003", "004"], help="one document only")
    p.add_argument("--evaluate", action="store_true",
                   help="also recompute the numbers the documents' own data decide (Table 1, the printed matrix)")
    p.add_argument("--json", default=None, metavar="FILE", help="write the registry (and the evaluation) as JSON")
    p.set_defaults(func=cmd_readings)
    declare(p, "json")
    m = groups["top"].add_parser(
        "check-matrix", formatter_class=argparse.RawDescriptionHelpFormatter,
        help="is a printed 3×3 matrix a rotation? determinant, norms, angles, nearest rotation, sign repair",
        description="Analyse a matrix as printed in a document: determinant, row and column norms, angles between "
                    "the columns, max |M·Mᵀ − I|, the nearest rotation, and the simplest sign change (one element, "
                    "else one row or column, else two elements) that makes it a proper rotation within print precision.",
        epilog="examples:\n  rigsim check-matrix            # seed 001's printed R(ref←sun)\n"
               "  rigsim check-matrix \"0.9998 -0.0204 -0.0028; 0.0203 -0.9989 -0.0430; 0.0037 0.0430 0.9991\"")
    m.add_argument("matrix", nargs="?", default=None,
                   help="nine numbers, rows separated by ';' (default: seed 001's printed example)")
    m.add_argument("--tolerance", type=number(1e-12, 1), default=None,
                   help="largest |M·Mᵀ − I| entry the print allows (default 3e-4, a 4-decimal print)")
    m.add_argument("--json", action="store_true", help="print the analysis as JSON")
    m.set_defaults(func=cmd_check_matrix)


def _wrap(label: str, text: str, width: int = 100) -> list[str]:
    return textwrap.wrap(text, width=width, initial_indent=f"  {label:12s}", subsequent_indent=" " * 14) or [f"  {label}"]


def cmd_readings(args) -> int:
    from rigsim.files import write_json
    from rigsim.procedures.readings import evaluate, find

    rows = find(args.seed, args.key)
    if not rows:
        from rigsim.procedures.readings import READINGS

        raise CliError(f"reading {args.key!r}: unknown; known: "
                       + ", ".join(f"{r.seed}:{r.key}" for r in READINGS if args.seed in (None, r.seed)))
    for r in rows:
        print(f"seed {r.seed} · {r.key} — {r.title}")
        for line in _wrap("printed", r.printed):
            print(line)
        for opt, what in r.options.items():
            for line in _wrap(("* " if opt == r.default else "  ") + opt, what):
                print(line)
        for line in _wrap("why", r.why) + _wrap("select", r.select):
            print(line)
        for c in r.claims:
            for line in _wrap("claim", c):
                print(line)
        if r.doc:
            print(f"  {'docs':12s}{r.doc}")
        print()
    ev = evaluate() if args.evaluate else None
    if ev is not None:
        print("Seed 000 Table 1 (θ1, θ2) = (181.398°, 0.528°), (θ3, θ4) = (91.386°, −0.048°), faces +Z +Y:")
        print("  axis order  eq 8     ∠(r1, r2)   amplification  R(cube←rot) from XY/beam  degenerate")
        for t in ev["seed000_table1"]:
            print(f"  {t['axis_order']:10s}  {t['eq8']:7s}  {t['angle_r_deg']:9.4f}°  ×{t['amplification']:<13.1f} "
                  f"{t['deg_from_default']:9.4f}°                {'yes' if t['degenerate'] else 'no'}")
        print("Seed 000 budget (eq 14) under each reading of σ1, with σ2 = σ3 = 2″, σ4 = 0.4″:")
        for b in ev["seed000_budget"]:
            print(f"  {b['sigma1_reading']:32s} σ1 {b['sigma1_arcsec']:.3f}″  RSS {b['rss_arcsec']:.2f}″  "
                  f"< 4″ {'holds' if b['claim_holds'] else 'fails'}")
        m = ev["seed001_printed_matrix"]
        rep = m["sign_repair"]
        print(f"Seed 001 printed R(ref←sun): det {m['determinant']:+.4f}, max |M·Mᵀ − I| {m['max_abs_MMt_minus_I']:.4f}; "
              + (f"repair: flip {rep['change']} → det {rep['determinant']:+.5f}, max |M·Mᵀ − I| "
                 f"{rep['max_abs_MMt_minus_I']:.1e}, xyz Euler ({', '.join(f'{a:.2f}°' for a in rep['euler_xyz_deg'])})"
                 if rep else "no sign repair found"))
    if args.json:
        write_json(args.json, {"readings": [r.as_dict() for r in rows], **({"evaluation": ev} if ev else {})})
        print(f"→ {args.json}")
    return 0


def parse_matrix(text: str) -> np.ndarray:
    """Nine numbers in row order, separated by spaces, commas, semicolons or brackets ('1 0 0; 0 1 0; 0 0 1',
    '[[1, 0, 0], [0, 1, 0], [0, 0, 1]]')."""
    from rigsim.files.numbers import parse_float

    tokens = [t for t in re.split(r"[\s,;\[\]()]+", text) if t]
    if len(tokens) > 9:
        raise CliError(f"matrix {text[:60]!r}…: {len(tokens)} numbers; expected nine, rows separated by ';'")
    vals = []
    for t in tokens:
        try:
            vals.append(parse_float(t))
        except ValueError:
            raise CliError(f"matrix {text!r}: {t!r} is not a number in ASCII digits; expected nine numbers, rows "
                           "separated by ';'") from None
    M = np.array(vals, float)
    if M.size != 9 or not np.all(np.isfinite(M)):
        raise CliError(f"matrix {text!r}: {M.size} numbers{'' if np.all(np.isfinite(M)) else ', not all finite'}; "
                       "expected nine finite numbers, rows separated by ';'")
    return M.reshape(3, 3)


def cmd_check_matrix(args) -> int:
    from rigsim.estimation.rotation_check import analyse_rotation_matrix
    from rigsim.procedures.readings import PATENT_R_REF_FROM_SUN

    M = np.array(PATENT_R_REF_FROM_SUN) if args.matrix is None else parse_matrix(args.matrix)
    a = analyse_rotation_matrix(M, tolerance=args.tolerance)
    if args.json:
        print(json.dumps(a))
        return 0
    if args.matrix is None:
        print("seed 001's printed example R(ref←sun):")
    with np.printoptions(precision=6, suppress=True):
        print(M)
    print(f"determinant {a['determinant']:+.6f}" + ("  (improper: a reflection)" if a["improper"] else ""))
    print("row norms " + ", ".join(f"{x:.6f}" for x in a["row_norms"]) + "; column norms "
          + ", ".join(f"{x:.6f}" for x in a["column_norms"]))
    print("angles between columns " + ", ".join(f"{k}: {v:.4f}°" for k, v in a["column_angles_deg"].items()))
    print(f"max |M·Mᵀ − I| = {a['max_abs_MMt_minus_I']:.2e} (print precision allows {a['tolerance']:.0e})")
    if a["proper"]:
        print("a proper rotation within print precision; nearest rotation differs by at most "
              f"{a['max_abs_M_minus_nearest']:.1e} per element")
        return 0
    rep = a["sign_repair"]
    if rep is None:
        print("NOT a rotation, and no sign change of one element, one row or column, or two elements makes it one")
        return 0
    print(f"NOT a rotation; flipping the sign of {rep['change']} makes it one: det {rep['determinant']:+.6f}, "
          f"max |M·Mᵀ − I| {rep['max_abs_MMt_minus_I']:.1e}, xyz Euler angles "
          + ", ".join(f"{x:.4f}°" for x in rep["euler_xyz_deg"])
          + (f" (equally good: {', '.join(rep['alternatives'])})" if rep["alternatives"] else ""))
    return 0
