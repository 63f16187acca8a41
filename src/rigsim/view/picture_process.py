"""A rig picture rendered in a short-lived child process, so that its memory (pyvista, VTK and the
off-screen OpenGL of Mesa) never adds to that of a calling process that has rendered or will render.

:func:`picture_in_child` runs ``python -m rigsim.view.picture_process`` with the rig (as JSON), the
pose, the size and the output path on its standard input; the child calls :func:`rigsim.view.rig_picture`
and exits. A failure in the child (no off-screen OpenGL, a crash, a time-out) comes back as one line,
never as an exception or a traceback, so that a report can go on without its picture.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

__all__ = ["TIMEOUT_S", "picture_in_child"]

TIMEOUT_S = 300.0


def _rig_class(name: str):
    from rigsim.rig.boresight import BoresightRig
    from rigsim.rig.cube_mirror import CubeMirrorRig
    from rigsim.rig.star import StarRig

    classes = {c.__name__: c for c in (CubeMirrorRig, BoresightRig, StarRig)}
    if name not in classes:
        raise ValueError(f"no 3D view for a rig of type {name}")
    return classes[name]


def picture_in_child(rig, out_png, *, pose_deg=None, size=(1200, 800), face=None,
                     timeout: float = TIMEOUT_S) -> tuple[Path | None, str]:
    """Render ``rig`` at ``pose_deg`` into ``out_png`` in a child process.

    Returns ``(path, "")`` when the child wrote the picture, else ``(None, one line saying why)``.
    ``pose_deg``: as for :func:`rigsim.view.rig_picture` (a mapping of true degrees or a pose keyword).
    """
    job = {"rig_class": type(rig).__name__, "rig": json.loads(rig.model_dump_json()), "out": str(out_png),
           "pose_deg": pose_deg, "size": list(size), "face": face}
    env = dict(os.environ)
    src = str(Path(__file__).resolve().parents[2])  # the folder holding this rigsim package
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    try:
        proc = subprocess.run([sys.executable, "-m", "rigsim.view.picture_process"], input=json.dumps(job),
                              capture_output=True, text=True, timeout=timeout, env=env, check=False)
    except subprocess.TimeoutExpired:
        return None, f"the picture process did not finish within {timeout:.0f} s"
    except OSError as e:
        return None, f"cannot start the picture process: {type(e).__name__}: {e}"
    out = Path(out_png)
    if proc.returncode == 0 and out.is_file():
        return out, ""
    lines = [ln.strip() for ln in (proc.stderr or "").splitlines() if ln.strip()]
    why = lines[-1] if lines else f"the picture process exited with status {proc.returncode}"
    if proc.returncode < 0:
        why = f"the picture process was killed by signal {-proc.returncode}" + (f" ({why})" if lines else "")
    return None, why[:300]


def _main() -> int:
    try:
        job = json.loads(sys.stdin.read())
        rig = _rig_class(job["rig_class"]).model_validate(job["rig"])
        from rigsim.view import rig_picture

        rig_picture(rig, job["out"], pose_deg=job.get("pose_deg"), size=tuple(job["size"]), face=job.get("face"))
    except Exception as e:  # noqa: BLE001  (one line for the parent, which goes on without the picture)
        sys.stderr.write(f"{type(e).__name__}: {e}".replace("\n", " ") + "\n")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
