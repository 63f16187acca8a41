"""A rig picture rendered in a short-lived child process, so that its memory (pyvista, VTK and the
off-screen OpenGL of Mesa) never adds to that of a calling process that has rendered or will render.

:func:`start_picture` runs ``python -m rigsim.view.picture_process`` with the rig (as JSON, or its
file), the pose, the size and the output path on its standard input, and returns at once;
:func:`picture_in_child` also waits; the child calls :func:`rigsim.view.rig_picture`
and exits. A failure in the child (no off-screen OpenGL, a crash, a time-out) comes back as one line,
never as an exception or a traceback, so that a report can go on without its picture.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

__all__ = ["TIMEOUT_S", "PictureJob", "picture_in_child", "start_picture"]

TIMEOUT_S = 300.0


def _rig_class(name: str):
    from rigsim.rig.boresight import BoresightRig
    from rigsim.rig.cube_mirror import CubeMirrorRig
    from rigsim.rig.star import StarRig

    classes = {c.__name__: c for c in (CubeMirrorRig, BoresightRig, StarRig)}
    if name not in classes:
        raise ValueError(f"no 3D view for a rig of type {name}")
    return classes[name]


class PictureJob:
    """A rig picture being drawn by a child process (:func:`start_picture`); :meth:`finish` waits."""

    def __init__(self, proc, out_png, error: str = ""):
        self.proc, self.out, self.error = proc, Path(out_png), error

    def finish(self, timeout: float = TIMEOUT_S) -> tuple[Path | None, str]:
        """``(path, "")`` when the child wrote the picture, else ``(None, one line saying why)``."""
        if self.proc is None:
            return None, self.error
        try:
            _, err = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.communicate()
            return None, f"the picture process did not finish within {timeout:.0f} s"
        if self.proc.returncode == 0 and self.out.is_file():
            return self.out, ""
        lines = [ln.strip() for ln in (err or "").splitlines() if ln.strip()]
        why = lines[-1] if lines else f"the picture process exited with status {self.proc.returncode}"
        if self.proc.returncode < 0:
            why = f"the picture process was killed by signal {-self.proc.returncode}" + (f" ({why})" if lines else "")
        return None, why[:300]


def start_picture(rig, out_png, *, pose_deg=None, size=(1200, 800), face=None) -> PictureJob:
    """Start drawing ``rig`` (a rig object, or a rig file's path or default name) at ``pose_deg`` into
    ``out_png`` in a child process, and return at once; the caller goes on and calls
    :meth:`PictureJob.finish`. ``pose_deg``: as for :func:`rigsim.view.rig_picture` (a mapping of true
    degrees or a pose keyword). The child runs in its own session: a Ctrl-C reaches the caller only."""
    if isinstance(rig, (str, os.PathLike)):
        what = {"rig_path": str(rig)}
    else:
        what = {"rig_class": type(rig).__name__, "rig": json.loads(rig.model_dump_json())}
    job = {**what, "out": str(out_png), "pose_deg": pose_deg, "size": list(size), "face": face}
    env = dict(os.environ)
    src = str(Path(__file__).resolve().parents[2])  # the folder holding this rigsim package
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    try:
        proc = subprocess.Popen([sys.executable, "-m", "rigsim.view.picture_process"], stdin=subprocess.PIPE,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env,
                                start_new_session=True)
        proc.stdin.write(json.dumps(job))
        proc.stdin.close()
        proc.stdin = None  # sent: communicate() in finish() then reads stderr only
    except OSError as e:
        return PictureJob(None, out_png, f"cannot start the picture process: {type(e).__name__}: {e}")
    return PictureJob(proc, out_png)


def picture_in_child(rig, out_png, *, pose_deg=None, size=(1200, 800), face=None,
                     timeout: float = TIMEOUT_S) -> tuple[Path | None, str]:
    """Render ``rig`` at ``pose_deg`` into ``out_png`` in a child process and wait for it.

    Returns ``(path, "")`` when the child wrote the picture, else ``(None, one line saying why)``.
    """
    return start_picture(rig, out_png, pose_deg=pose_deg, size=size, face=face).finish(timeout)


def _main() -> int:
    try:
        job = json.loads(sys.stdin.read())
        rig = job["rig_path"] if "rig_path" in job else _rig_class(job["rig_class"]).model_validate(job["rig"])
        from rigsim.view import rig_picture

        rig_picture(rig, job["out"], pose_deg=job.get("pose_deg"), size=tuple(job["size"]), face=job.get("face"))
    except Exception as e:  # noqa: BLE001  (one line for the parent, which goes on without the picture)
        sys.stderr.write(f"{type(e).__name__}: {e}".replace("\n", " ") + "\n")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
