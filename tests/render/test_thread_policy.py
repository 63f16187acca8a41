"""The thread policy sets Dr.Jit, BLAS and OpenCV together and restores them."""

import subprocess
import sys

import pytest

from rigsim.render.threads import KINDS, current_threads, thread_policy


def test_policy_sets_and_restores_blas_and_opencv():
    before = current_threads()
    with thread_policy("worker") as plan:
        now = current_threads()
        assert plan == {"drjit": 1, "blas": 1, "opencv": 1}
        assert now["opencv"] == 1
        assert now.get("blas", 1) == 1
        assert now["drjit"] == 1
    after = current_threads()
    assert after["opencv"] == before["opencv"]
    assert after.get("blas") == before.get("blas")


def test_numeric_policy_leaves_drjit_alone():
    with thread_policy("numeric", 2) as plan:
        assert plan["drjit"] is None and plan["blas"] == 2 and plan["opencv"] == 2


def test_unknown_kind_is_refused():
    with pytest.raises(ValueError, match="render, worker, numeric"), thread_policy("fast"):
        pass
    assert KINDS == ("render", "worker", "numeric")


def test_apply_in_a_fresh_process_limits_blas():
    code = ("from rigsim.render.threads import apply_thread_policy, current_threads\n"
            "apply_thread_policy('worker')\nc = current_threads()\n"
            "print(c.get('blas', 1), c['opencv'], c['drjit'])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["1", "1", "1"]
