"""Mutation testing of the mission-critical modules with cosmic-ray (PyPI ``cosmic-ray`` 8.x), one module at a time.

Each module is mapped to the fast tests that cover it (MODULES below). For a module, the script copies the
repository's ``src/`` and ``tests/`` (and ``scenes/``, ``pyproject.toml``) into a scratch folder — cosmic-ray
edits the module file in place, so the working tree is never touched and other test runs are not disturbed —
writes a cosmic-ray config there, makes the session, drops the operators listed in EXCLUDED_OPERATORS, runs
every mutant against the module's tests (one process, no xdist, stop at the first failure, a per-mutant time
limit) and writes the summary (killed, survived, timed out, and every survivor's line and operator) to
``<out>/<module>.json``. docs/testing.md gives the last results and the survivors judged equivalent.

A module listed in FUNCTIONS is narrowed to those functions and methods ("name" or "Class.method"): after the
operator filter, every mutant whose line lies outside their line ranges (found with ``ast`` in the scratch
copy) is marked skipped in the session, as the operator filter marks its own, and left out of the summary.

    pip install -e ".[mutation]"
    nice python scripts/mutation.py --list
    nice python scripts/mutation.py atomic            # one module (run them one after another, never two at once)
    nice python scripts/mutation.py atomic --report   # the summary of the last run

Mutation runs are CPU-heavy (a module's tests run once per mutant): run them with ``nice``, module by module.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# module key: (source file, the fast tests that cover it)
MODULES = {
    "atomic": ("src/rigsim/files/atomic.py", ["tests/files/test_crash_safety.py", "tests/files/test_files.py"]),
    "dataset_store": ("src/rigsim/dataset/store.py", ["tests/files/test_crash_safety.py", "tests/dataset/test_store.py"]),
    "detector": ("src/rigsim/detector/model.py", ["tests/detector/test_detector_distribution.py", "tests/detector/test_detector_model.py",
                                                  "tests/detector/test_detector_blocks.py", "tests/detector/test_detector_chain.py"]),
    "poisson": ("src/rigsim/detector/poisson.py", ["tests/detector/test_detector_poisson_inverse.py"]),
    "triad": ("src/rigsim/estimation/triad.py", ["tests/estimation/test_triad.py", "tests/test_cli.py::test_triad_table1",
                                                 "tests/procedures/cube_mirror/test_campaign.py"]),
    "cube_attitude": ("src/rigsim/estimation/cube_attitude.py", ["tests/procedures/cube_mirror/test_campaign.py",
                                                                 "tests/procedures/cube_mirror/test_user_files.py::test_triad_3axis_and_compose_covariance",
                                                                 "tests/estimation/test_cube_attitude.py"]),
    "turntable": ("src/rigsim/rig/turntable.py", ["tests/rig/test_rig_turntable.py", "tests/procedures/cube_mirror/test_campaign.py"]),
    "sun_calibration": ("src/rigsim/estimation/sun_calibration.py", ["tests/estimation/test_sun_calibration.py",
                                                                     "tests/estimation/test_sun_calibration_outliers.py"]),
    "dvad": ("src/rigsim/estimation/dvad.py", ["tests/estimation/test_dvad.py", "tests/estimation/test_dvad_truths.py"]),
    "star_calibration": ("src/rigsim/estimation/star_calibration.py", ["tests/estimation/test_star_calibration.py",
                                                                       "tests/estimation/test_star_equation_sets.py",
                                                                       "tests/estimation/test_star_calibration_truths.py"]),
    "star_ekf_batch": ("src/rigsim/estimation/star_ekf_batch.py", ["tests/estimation/test_star_ekf_batch.py",
                                                                   "tests/estimation/test_star_ekf_batch_truths.py"]),
    "camera": ("src/rigsim/optics/camera.py", ["tests/optics/test_camera_model.py", "tests/optics/test_camera_convention.py",
                                               "tests/optics/test_camera_entry_points.py", "tests/optics/test_camera_truth.py"]),
    "centroid": ("src/rigsim/imaging/centroid.py", ["tests/imaging/test_imaging_centroid.py", "tests/imaging/test_centroid_truth.py"]),
    # the WCS's own unit tests and the catalogue check; the dataset test (a star frame rendered, 5 s) is left out
    "wcs": ("src/rigsim/optics/wcs.py", ["tests/optics/test_wcs.py",
                                         "tests/render/test_star_fits_wcs.py::test_the_wcs_puts_every_catalogue_star_on_its_true_pixel"]),
}

# modules narrowed to their mission-critical functions (top-level names or "Class.method"); the others are mutated whole
FUNCTIONS = {
    "camera": ["brown_distort", "brown_jacobian", "brown_undistort", "radial_r2_max", "_radial_r2_max_cached",
               "_radial_r2_max_array", "_split", "_dist_partials", "distort", "project", "unproject",
               "PinholeBrown.camera_matrix", "PinholeBrown.dist_coeffs", "PinholeBrown.params", "PinholeBrown.r2_max",
               "PinholeBrown.distort", "PinholeBrown.distort_jacobian", "PinholeBrown.undistort",
               "PinholeBrown.normalized_to_pixel", "PinholeBrown.project", "PinholeBrown.project_valid",
               "PinholeBrown.pixel_to_normalized", "PinholeBrown.unproject", "PinholeBrown.backproject",
               "PinholeBrown.on_detector"],
    # the default centroiders: tcom (boresight cameras, autocollimator spot) and gauss (star fields), with helpers
    "centroid": ["_threshold_moments", "centroid_tcom", "_pix_1d", "_gauss_init", "_basis_terms", "_normal_equations",
                 "_chol", "_chol_solve", "_chol_inverse", "_solve_spd", "_gauss_newton", "centroid_gauss"],
}

# operators left out: bitwise, shift, power, modulo and floor-division swaps of arithmetic (thousands of mutants
# that are all killed at once or meaningless on floats), and the variable replacer/inserter (a mutant per name).
EXCLUDED_OPERATORS = [
    r"core/ReplaceBinaryOperator_.*_(BitOr|BitAnd|BitXor|LShift|RShift|Pow|Mod|FloorDiv)$",
    r"core/ReplaceBinaryOperator_(BitOr|BitAnd|BitXor|LShift|RShift|Pow|Mod|FloorDiv)_.*",
    r"core/ReplaceBinaryOperator_(Add_Mul|Add_Div|Sub_Mul|Sub_Div|Mul_Add|Mul_Sub|Div_Add|Div_Sub)$",
    r"core/ReplaceComparisonOperator_(Is|IsNot|In|NotIn)_.*",
    r"core/ReplaceComparisonOperator_.*_(Is|IsNot|In|NotIn)$",
    r"core/ReplaceUnaryOperator_.*Invert.*",
    r"core/VariableReplacer", r"core/VariableInserter", r"core/RemoveDecorator",
]


def _scratch(out: Path) -> Path:
    w = out / "tree"
    if w.exists():
        shutil.rmtree(w)
    w.mkdir(parents=True)
    for name in ("src", "tests", "scenes"):
        shutil.copytree(ROOT / name, w / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    shutil.copy(ROOT / "pyproject.toml", w / "pyproject.toml")
    return w


def _config(key: str, tree: Path, timeout: float) -> Path:
    module, tests = MODULES[key]
    cmd = (f"{sys.executable} -m pytest -x -q -p no:xdist -p no:cacheprovider -p no:randomly -o addopts= "
           + " ".join(tests))
    excl = ", ".join(json.dumps(x) for x in EXCLUDED_OPERATORS)
    text = f"""[cosmic-ray]
module-path = "{module}"
timeout = {timeout}
excluded-modules = []
test-command = {json.dumps(cmd)}

[cosmic-ray.distributor]
name = "local"

[cosmic-ray.filters.operators-filter]
exclude-operators = [{excl}]
"""
    p = tree / f"{key}.toml"
    p.write_text(text)
    return p


def _line_ranges(path: Path, names) -> list[tuple[int, int]]:
    """First and last line of each named function or "Class.method" in a source file."""
    import ast

    found = {}
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            found[node.name] = (node.lineno, node.end_lineno)
        elif isinstance(node, ast.ClassDef):
            for m in node.body:
                if isinstance(m, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    found[f"{node.name}.{m.name}"] = (m.lineno, m.end_lineno)
    missing = [n for n in names if n not in found]
    if missing:
        raise SystemExit(f"FUNCTIONS names not found in {path}: {missing}")
    return [found[n] for n in names]


def _skip_outside(session: Path, tree: Path, key: str) -> int:
    """Mark skipped every pending mutant outside FUNCTIONS[key] (as cr-filter-operators does); the count left."""
    from cosmic_ray.work_db import use_db
    from cosmic_ray.work_item import WorkerOutcome, WorkResult

    ranges = _line_ranges(tree / MODULES[key][0], FUNCTIONS[key])
    with use_db(str(session)) as db:
        items = db.pending_work_items
        out = [i.job_id for i in items if not all(any(a <= m.start_pos[0] <= b for a, b in ranges) for m in i.mutations)]
        # one transaction for all (a commit per mutant, as the operator filter does, takes minutes)
        db.set_multiple_results(out, WorkResult(output="Outside the narrowed functions", worker_outcome=WorkerOutcome.SKIPPED))
    return len(items) - len(out)


def summary(session: Path, tree: Path, key: str) -> dict:
    """Killed / survived / incompetent counts and every survivor (line, operator, diff) from a session."""
    con = sqlite3.connect(session)
    rows = con.execute(
        "select m.job_id, m.module_path, m.operator_name, m.occurrence, m.start_pos_row, r.test_outcome, r.worker_outcome, r.diff "
        "from mutation_specs m join work_results r on m.job_id = r.job_id").fetchall()
    out = {"module": MODULES[key][0], "tests": MODULES[key][1], "mutants": len(rows), "killed": 0, "survived": 0,
           "incompetent": 0, "other": 0, "survivors": []}
    for job, _path, op, occ, line, test_outcome, worker_outcome, diff in rows:
        worker_outcome, test_outcome = str(worker_outcome).upper(), str(test_outcome).upper()
        if worker_outcome == "SKIPPED":  # an excluded operator
            out["mutants"] -= 1
            continue
        if worker_outcome != "NORMAL":  # a time-out or a crash of the test run counts as killed
            out["other"] += 1
            out["killed"] += 1
            continue
        if test_outcome == "KILLED":
            out["killed"] += 1
        elif test_outcome == "INCOMPETENT":
            out["incompetent"] += 1
        else:
            out["survived"] += 1
            out["survivors"].append({"line": line, "operator": op, "occurrence": occ, "diff": diff})
    out["score"] = out["killed"] / max(1, out["killed"] + out["survived"])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("module", nargs="?", choices=sorted(MODULES))
    ap.add_argument("--list", action="store_true", help="the modules and their tests")
    ap.add_argument("--out", default="mutation-results", help="folder for the scratch tree, sessions and summaries")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per mutant's test run")
    ap.add_argument("--report", action="store_true", help="only summarise the last session of the module")
    a = ap.parse_args(argv)
    if a.list or not a.module:
        for k, (m, t) in MODULES.items():
            print(f"{k:18s} {m}\n{'':18s} {' '.join(t)}")
        return 0
    out = Path(a.out).resolve() / a.module
    session = out / "session.sqlite"
    if not a.report:
        out.mkdir(parents=True, exist_ok=True)
        tree = _scratch(out)
        cfg = _config(a.module, tree, a.timeout)
        if session.exists():
            session.unlink()
        # one BLAS thread: a mutant's tests run on one core (threaded BLAS made the WCS fit 30× slower on 2 busy cores)
        env = {**os.environ, "PYTHONPATH": str(tree / "src"), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
               "MKL_NUM_THREADS": "1"}
        run = lambda *c: subprocess.run(c, cwd=tree, env=env, check=True)  # noqa: E731
        bin_ = Path(sys.executable).parent
        # the baseline: the module's tests must pass unmutated, or every mutant would look killed
        module, tests = MODULES[a.module]
        base = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:xdist", "-p", "no:cacheprovider",
                               "-o", "addopts=", *tests], cwd=tree, env=env, capture_output=True, text=True)
        if base.returncode != 0:
            print(base.stdout[-3000:], base.stderr[-2000:], sep="\n")
            print(f"{a.module}: the tests fail on the unmutated module; no mutation run", file=sys.stderr)
            return 1
        run(str(bin_ / "cosmic-ray"), "init", str(cfg), str(session))
        run(str(bin_ / "cr-filter-operators"), str(session), str(cfg))
        if a.module in FUNCTIONS:
            left = _skip_outside(session, tree, a.module)
            print(f"{a.module}: narrowed to {', '.join(FUNCTIONS[a.module])}: {left} mutants left", flush=True)
        run(str(bin_ / "cosmic-ray"), "exec", str(cfg), str(session))
    s = summary(session, out / "tree", a.module)
    (out.parent / f"{a.module}.json").write_text(json.dumps(s, indent=1))
    print(f"{a.module}: {s['mutants']} mutants, {s['killed']} killed, {s['survived']} survived, "
          f"{s['incompetent']} incompetent; score {100 * s['score']:.1f} %")
    for x in s["survivors"]:
        print(f"  line {x['line']}: {x['operator']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
