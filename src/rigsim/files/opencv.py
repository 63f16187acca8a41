"""OpenCV's FileStorage camera file (``camera_matrix``, ``distortion_coefficients`` k1 k2 p1 p2 k3, ``image_width``,
``image_height``), as ``calibrateCamera`` results are usually saved; YAML, JSON or XML by the suffix."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rigsim.errors import InputError
from rigsim.files.atomic import atomic_write_bytes


def write_opencv_camera(path, fx: float, fy: float, cx: float, cy: float, dist, width: int, height: int, *,
                        fit_verdict: str | None = None) -> Path:
    """``fit_verdict``: also write ``rigsim_fit_verdict`` (e.g. "poor" for a calibration written with
    --accept-poor-fit; OpenCV's readers ignore a key they do not ask for)."""
    import cv2

    path = Path(path)
    if path.suffix.lower() not in (".yml", ".yaml", ".json", ".xml"):
        raise InputError(f"{path}: expected an OpenCV FileStorage name ending .yml, .yaml, .json or .xml")
    fmt = {".json": cv2.FILE_STORAGE_FORMAT_JSON, ".xml": cv2.FILE_STORAGE_FORMAT_XML}.get(path.suffix.lower(),
                                                                                          cv2.FILE_STORAGE_FORMAT_YAML)
    fs = cv2.FileStorage("", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY | fmt)
    fs.write("image_width", int(width))
    fs.write("image_height", int(height))
    fs.write("camera_matrix", np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], float))
    fs.write("distortion_coefficients", np.asarray(dist, float).reshape(1, -1))
    if fit_verdict is not None:
        fs.write("rigsim_fit_verdict", str(fit_verdict))
    return atomic_write_bytes(path, fs.releaseAndGetString().encode())
