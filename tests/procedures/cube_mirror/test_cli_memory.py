"""The main job's memory measures (``rigsim run cube-mirror``): the progress bar that gives freed
render memory back, and the fixed mmap threshold that the worker processes inherit."""

import subprocess
import sys

from rigsim.procedures.cube_mirror.cli import _Releasing
from rigsim.render.backend import MMAP_THRESHOLD_BYTES, cap_mmap_threshold


class _Bar:
    def __init__(self):
        self.n, self.desc = 0, []

    def update(self, n=1):
        self.n += n

    def set_description(self, s):
        self.desc.append(s)


def test_releasing_bar_forwards_every_update_and_stage():
    bar = _Bar()
    pb = _Releasing(bar)
    pb.set_description("sun-sensor sweep")
    for _ in range(3):
        pb.update(1)
    pb.update(2)
    pb.set_description("concentricity search, face +Z")
    assert bar.n == 5 and bar.desc == ["sun-sensor sweep", "concentricity search, face +Z"]


def test_mmap_threshold_reaches_child_processes(monkeypatch):
    monkeypatch.delenv("MALLOC_MMAP_THRESHOLD_", raising=False)
    assert cap_mmap_threshold() is True  # glibc here
    out = subprocess.run([sys.executable, "-c", "import os; print(os.environ['MALLOC_MMAP_THRESHOLD_'])"],
                         capture_output=True, text=True, check=True).stdout
    assert int(out) == MMAP_THRESHOLD_BYTES


def test_a_users_mmap_threshold_is_kept(monkeypatch):
    monkeypatch.setenv("MALLOC_MMAP_THRESHOLD_", "4194304")
    assert cap_mmap_threshold() is True
    import os

    assert os.environ["MALLOC_MMAP_THRESHOLD_"] == "4194304"
