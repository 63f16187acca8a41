"""The import contracts of docs/architecture.md (configured in pyproject.toml), checked with import-linter."""

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT = "import sys; from importlinter.cli import lint_imports; sys.exit(lint_imports(no_cache=True, no_logo=True))"


def _lint(cwd: Path, src: Path) -> subprocess.CompletedProcess:
    env = {"PYTHONPATH": str(src), "PATH": "/usr/bin:/bin"}
    return subprocess.run([sys.executable, "-c", LINT], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=300)


def test_import_contracts_hold():
    r = _lint(ROOT, ROOT / "src")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "0 broken" in r.stdout


@pytest.mark.parametrize("module, code, contract", [
    ("estimation/_leak.py", "from rigsim.truth.cube_mirror import realization\n",
     "Estimation and imaging see observations and the nominal rig only"),
    ("imaging/_leak.py", "import mitsuba\n", "Mitsuba and Dr.Jit are imported only in rigsim.render"),
    ("optics/_leak.py", "def f():\n    from rigsim.rig import load_rig\n", "Data flows one way"),
    ("render/_leak.py", "from rigsim.procedures.star import pipeline\n", "Data flows one way"),
    ("procedures/star/_leak.py", "from rigsim.procedures.cube_mirror import campaign\n",
     "Within a layer the rig families do not import one another"),
])
def test_a_planted_violation_breaks_its_contract(tmp_path, module, code, contract):
    """The contracts can fail: the same tree with one forbidden import is refused, naming the contract."""
    shutil.copytree(ROOT / "src" / "rigsim", tmp_path / "src" / "rigsim",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    (tmp_path / "src" / "rigsim" / module).write_text(textwrap.dedent(code))
    r = _lint(tmp_path, tmp_path / "src")
    assert r.returncode != 0
    broken = r.stdout.split("Broken contracts", 1)[-1]
    assert contract in broken, r.stdout
