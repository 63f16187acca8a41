"""Frames on disk: a 16-bit PNG plus a JSON sidecar holding the truth and every setting.

``write_frame("out/sun_0007", dn, sidecar)`` writes ``out/sun_0007.png`` (uint16, lossless,
``img[v, u]``) and ``out/sun_0007.json``. :func:`build_sidecar` assembles the sidecar from the
pieces a renderer knows (truth, render settings, detector config and frame metadata, pose, seed)
and turns geometry problems and saturation into explicit ``flags``. :func:`read_frame` returns
both and checks they belong together (shape, dtype).

Pure numpy/OpenCV: no mitsuba import.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

__all__ = ["SIDECAR_FORMAT", "FLAG_KEYS", "build_sidecar", "write_frame", "read_frame",
           "frame_paths"]

SIDECAR_FORMAT = "rigsim.frame/1"
FLAG_KEYS = ("spot_outside_model", "spot_off_detector", "spot_cut_by_edge", "spot_exceeds_window",
             "saturated")


def frame_paths(path) -> tuple[Path, Path]:
    p = Path(path)
    if p.suffix.lower() in (".png", ".json"):
        p = p.with_suffix("")
    return p.with_name(p.name + ".png"), p.with_name(p.name + ".json")


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, Path):
        return str(x)
    if hasattr(x, "model_dump"):
        return _jsonable(x.model_dump())
    return x


def build_sidecar(*, truth: dict | None = None, render: dict | None = None,
                  detector: dict | None = None, detector_frame=None,
                  geometry_flags: dict | None = None, pose: dict | None = None,
                  seed: int | None = None, extra: dict | None = None) -> dict:
    """Assemble a sidecar. ``detector_frame`` (a :class:`rigsim.detector.DetectorFrame`) adds
    its metadata and the saturation flag/count; ``geometry_flags`` come from e.g.
    :func:`rigsim.render.cube_mirror.sun_sensor.spot_geometry_flags`. Every flag in :data:`FLAG_KEYS` is present
    (False when not applicable), so readers can test them without guessing."""
    flags = {k: False for k in FLAG_KEYS}
    flags["saturated_pixels"] = 0
    for k, v in (geometry_flags or {}).items():
        flags[k] = v
    det_meta = None
    if detector_frame is not None:
        det_meta = dict(detector_frame.meta)
        flags["saturated_pixels"] = int(detector_frame.saturated_pixels)
        flags["saturated"] = bool(detector_frame.saturated_pixels > 0)
        if detector is None and "config" in det_meta:
            detector = det_meta["config"]
    side = {
        "format": SIDECAR_FORMAT,
        "seed": seed,
        "flags": flags,
        "truth": truth or {},
        "render": render or {},
        "detector": detector or {},
        "detector_frame": det_meta or {},
        "pose": pose or {},
    }
    if extra:
        side["extra"] = extra
    return _jsonable(side)


def write_frame(path, dn: np.ndarray, sidecar: dict) -> tuple[Path, Path]:
    """Write ``<path>.png`` (16-bit) and ``<path>.json``. Returns both paths."""
    import cv2

    img = np.asarray(dn)
    if img.ndim != 2 or img.dtype != np.uint16:
        raise ValueError(f"frames are 2-D uint16 images; got shape {img.shape}, dtype {img.dtype}")
    png, js = frame_paths(path)
    png.parent.mkdir(parents=True, exist_ok=True)
    side = _jsonable(dict(sidecar))
    side.setdefault("format", SIDECAR_FORMAT)
    side["image"] = {"file": png.name, "width": int(img.shape[1]), "height": int(img.shape[0]),
                     "dtype": "uint16", "convention": "img[v, u]; pixel (0,0) centre at (0,0)"}
    if not cv2.imwrite(str(png), np.ascontiguousarray(img)):
        raise OSError(f"cv2.imwrite could not write {png}")
    tmp = js.with_name(f".{js.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(side, indent=1, sort_keys=True, allow_nan=False))
    os.replace(tmp, js)
    return png, js


def read_frame(path) -> tuple[np.ndarray, dict]:
    """Read a frame written by :func:`write_frame`: (uint16 image, sidecar dict)."""
    import cv2

    png, js = frame_paths(path)
    if not png.is_file():
        raise FileNotFoundError(f"frame image {png} not found")
    if not js.is_file():
        raise FileNotFoundError(f"frame sidecar {js} not found (every frame needs its truth)")
    img = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"{png} is not a readable PNG")
    side = json.loads(js.read_text())
    if side.get("format") != SIDECAR_FORMAT:
        raise ValueError(f"{js}: format {side.get('format')!r}, expected {SIDECAR_FORMAT!r}")
    if img.dtype != np.uint16 or img.ndim != 2:
        raise ValueError(f"{png}: expected a single-channel 16-bit PNG, got {img.dtype} "
                         f"with shape {img.shape}")
    meta = side.get("image", {})
    if (meta.get("width"), meta.get("height")) != (img.shape[1], img.shape[0]):
        raise ValueError(f"{png}: size {img.shape[1]}x{img.shape[0]} does not match the sidecar "
                         f"({meta.get('width')}x{meta.get('height')})")
    return img, side
