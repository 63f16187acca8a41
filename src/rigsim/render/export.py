"""Mitsuba XML export of rigsim scene dicts (``rigsim scene export RIG --xml DIR``).

The exported scenes use only built-in plugins, so the plain ``mitsuba`` command renders them.
Where rigsim renders with a Python plugin (the distorted pinhole ``rigsim_pinhole``), the export
substitutes the built-in ``perspective`` sensor with the same focal length and principal point
and *no distortion*, and says so in an XML comment: the plain command cannot load Python plugins.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from rigsim.errors import ExportError
from rigsim.files.atomic import atomic_write_text, output_folder


def _check_builtin(d, where="scene"):
    for k, v in d.items():
        if isinstance(v, dict):
            t = v.get("type", "")
            if isinstance(t, str) and t.startswith("rigsim_"):
                raise ExportError(f"plugin type {t!r} (entry {k!r}) is one of rigsim's Python plugins: "
                                  "the plain mitsuba command cannot load Python plugins")
            _check_builtin(v, k)


def _to_mitsuba(x):
    import mitsuba as mi

    if isinstance(x, dict):
        return {k: _to_mitsuba(v) for k, v in x.items()}
    if isinstance(x, np.ndarray) and x.shape == (4, 4):
        return mi.ScalarTransform4f(x.tolist())
    if isinstance(x, Path):
        return str(x)
    return x


def scene_dict_to_xml(scene: dict, comments: list[str] | None = None) -> str:
    """Serialise a scene dict of built-in plugins as Mitsuba XML, with Mitsuba's own writer
    (``mi.parser.parse_dict`` + ``mi.parser.write_file``); ``comments`` go on top."""
    import os
    import tempfile

    from rigsim.render.backend import ensure_variant

    if scene.get("type") != "scene":
        raise ExportError("the top-level dict must have type 'scene'")
    _check_builtin(scene)
    variant = ensure_variant()
    import mitsuba as mi

    state = mi.parser.parse_dict(mi.parser.ParserConfig(variant), _to_mitsuba(scene))
    fd, tmp = tempfile.mkstemp(suffix=".xml")
    os.close(fd)
    try:
        mi.parser.write_file(state, tmp)
        body = Path(tmp).read_text()
    finally:
        os.unlink(tmp)
    head = "".join(f"<!-- {c.replace('--', '—')} -->\n" for c in (comments or []))
    return head + body


def cv_to_mitsuba_camera(R_world_from_cv: np.ndarray, position) -> np.ndarray:
    """4×4 to_world of a built-in Mitsuba camera looking like an OpenCV camera.

    Mitsuba's camera frame has +x left and +y up (z forward); OpenCV's has +x right, +y down.
    """
    M = np.eye(4)
    M[:3, :3] = np.asarray(R_world_from_cv, float) @ np.diag([-1.0, -1.0, 1.0])
    M[:3, 3] = np.asarray(position, float)
    return M


def perspective_from_intrinsics(fx: float, fy: float, cx: float, cy: float, width: int, height: int) -> dict:
    """Built-in ``perspective`` properties for OpenCV intrinsics (square pixels: uses fx).

    Mitsuba puts pixel i's centre at i + 0.5 of the film; OpenCV at i. The principal point offsets
    are fractions of the film size relative to its centre.
    """
    return {
        "type": "perspective",
        "fov_axis": "x",
        "fov": math.degrees(2 * math.atan(width / (2 * fx))),
        # Mitsuba's offsets are along its own camera axes (x left, y up): opposite signs to u, v
        "principal_point_offset_x": -(cx + 0.5 - width / 2) / width,
        "principal_point_offset_y": -(cy + 0.5 - height / 2) / height,
    }


def write_xml(path: Path, scene: dict, comments: list[str] | None = None) -> Path:
    path = Path(path)
    output_folder(path.parent)
    atomic_write_text(path, scene_dict_to_xml(scene, comments))
    return path


def localise_files(scene: dict, out_dir: Path) -> dict:
    """Copy every file a scene refers to (``filename`` entries: meshes, bitmaps) next to the XML
    under ``meshes/`` and point the scene at the copies (relative paths)."""
    import shutil

    out_dir = Path(out_dir)

    def walk(d):
        res = {}
        for k, v in d.items():
            if isinstance(v, dict):
                res[k] = walk(v)
            elif k == "filename" and isinstance(v, (str, Path)) and Path(v).is_file():
                dst = out_dir / "meshes" / Path(v).name
                output_folder(dst.parent)
                shutil.copyfile(v, dst)
                res[k] = f"meshes/{dst.name}"
            else:
                res[k] = v
        return res

    return walk(scene)

