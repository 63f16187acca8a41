"""The one frame type every renderer returns, and frames on disk.

:class:`Frame` is a digitised image (the *observation*: what a rig's camera records) with the truth it
was rendered from; ``obs, truth = frame`` splits them. :func:`digitise` is the detector stage of the
render loop (:mod:`rigsim.render.scene`): expected photons → :func:`rigsim.detector.apply_detector` →
Frame. On disk a frame is a 16-bit PNG plus a JSON sidecar holding the truth and every setting.

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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rigsim.files.atomic import output_folder

__all__ = ["SIDECAR_FORMAT", "FLAG_KEYS", "OBSERVABLE_FLAGS", "Frame", "Observation", "digitise", "build_sidecar",
           "write_frame", "read_frame", "frame_paths"]

SIDECAR_FORMAT = "rigsim.frame/1"
FLAG_KEYS = ("spot_outside_model", "spot_off_detector", "spot_cut_by_edge", "spot_exceeds_window",
             "saturated")
OBSERVABLE_FLAGS = ("saturated", "saturated_pixels")
"""The flags a real camera's software can see in its own frame; the others come from the truth."""


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
    render = dict(render or {})
    side = {
        "format": SIDECAR_FORMAT,
        "seed": seed,
        "flags": flags,
        "truth": truth or {},
        "render": render,
        "detector": detector or {},
        "detector_frame": det_meta or {},
        "pose": pose or {},
    }
    if extra:
        side["extra"] = extra
    return _jsonable(side)


def write_frame(path, dn: np.ndarray, sidecar: dict) -> tuple[Path, Path]:
    """Write ``<path>.png`` (16-bit) and ``<path>.json``. Returns both paths."""
    img = np.asarray(dn)
    if img.ndim != 2 or img.dtype != np.uint16:
        raise ValueError(f"frames are 2-D uint16 images; got shape {img.shape}, dtype {img.dtype}")
    png, js = frame_paths(path)
    output_folder(png.parent)
    side = _jsonable(dict(sidecar))
    side.setdefault("format", SIDECAR_FORMAT)
    side["image"] = {"file": png.name, "width": int(img.shape[1]), "height": int(img.shape[0]),
                     "dtype": "uint16", "convention": "img[v, u]; pixel (0,0) centre at (0,0)"}
    from rigsim.files.atomic import atomic_write_bytes
    from rigsim.files.images import encode_image

    atomic_write_bytes(png, encode_image(img, ".png"))
    atomic_write_bytes(js, json.dumps(side, indent=1, sort_keys=True, allow_nan=False).encode())
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
    from rigsim.files.results import parse_json

    side = parse_json(js.read_bytes(), js, "frame sidecar", max_bytes=16 << 20, error=ValueError)
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


@dataclass(frozen=True)
class Observation:
    """What a rig's camera records: the DN image (``dn[j, i]`` is detector pixel
    ``(origin_uv[0] + i, origin_uv[1] + j)``), the detector's shape, and what the camera's software
    knows about the exposure (render and detector settings, seed, saturation). No truth."""

    dn: np.ndarray
    origin_uv: tuple[int, int]
    detector_shape: tuple[int, int] | None
    meta: dict


@dataclass
class Frame:
    """What every renderer returns: the digitised image and the truth it was rendered from.

    ``sidecar`` is the one sidecar format (:func:`build_sidecar`); ``truth`` is the renderer's truth
    (a typed object, e.g. :class:`rigsim.truth.star.StarField`, when it has one; otherwise the
    sidecar's ``truth`` table). ``photons``: the expected photons per pixel before the detector
    (same window as ``dn``); ``extra``: renderer-specific products (render windows, …)."""

    dn: np.ndarray
    sidecar: dict
    origin_uv: tuple[int, int] = (0, 0)
    detector_shape: tuple[int, int] | None = None
    photons: np.ndarray | None = None
    detector: object | None = None
    truth_object: object | None = None
    extra: dict = field(default_factory=dict)
    seconds: float = 0.0
    index: int = 0
    time_s: float = 0.0

    @property
    def truth(self):
        return self.truth_object if self.truth_object is not None else self.sidecar.get("truth", {})

    @property
    def flags(self) -> dict:
        return self.sidecar.get("flags", {})

    @property
    def observation(self) -> Observation:
        meta = {k: v for k, v in self.sidecar.items() if k not in ("truth", "pose", "flags", "extra")}
        meta["flags"] = {k: v for k, v in self.flags.items() if k in OBSERVABLE_FLAGS}
        return Observation(self.dn, tuple(self.origin_uv), self.detector_shape, meta)

    def __iter__(self):
        yield self.observation
        yield self.truth

    def write(self, path) -> tuple[Path, Path]:
        return write_frame(path, self.dn, self.sidecar)

    def photon_centroid(self) -> np.ndarray:
        """First moment of the expected-photon image (detector pixels)."""
        if self.photons is None:
            raise ValueError("this frame kept no photon image")
        s = self.photons.sum()
        if not s > 0:
            return np.array([np.nan, np.nan])
        v, u = np.indices(self.photons.shape)
        return np.array([(self.photons * u).sum() / s + self.origin_uv[0],
                         (self.photons * v).sum() / s + self.origin_uv[1]])


def full_detector_frame(frame: Frame, detector_config, *, seed: int, noiseless: bool = False) -> np.ndarray:
    """The whole detector image of a windowed frame, as a camera that reads out every pixel would
    deliver it: the window's DN where it was rendered, and elsewhere the detector's own dark frame
    (the same fixed patterns, fresh temporal noise from ``seed``). A whole frame is returned as is."""
    from rigsim.detector import apply_detector

    shape = tuple(frame.detector_shape or frame.dn.shape)
    if tuple(frame.dn.shape) == shape:
        return frame.dn
    full = apply_detector(np.zeros(shape), detector_config, seed=seed, noiseless=noiseless).dn
    u0, v0 = frame.origin_uv
    h, w = frame.dn.shape
    full[v0:v0 + h, u0:u0 + w] = frame.dn
    return full


def digitise(photons: np.ndarray, detector_config, *, seed: int, noiseless: bool = False, origin_uv=(0, 0),
             detector_shape: tuple[int, int] | None = None, truth: dict | None = None, truth_object=None,
             render: dict | None = None, geometry_flags: dict | None = None, pose: dict | None = None,
             sidecar_extra: dict | None = None, extra: dict | None = None, seconds: float = 0.0,
             index: int = 0, time_s: float = 0.0, frame_seed: int | None = None, added_e=None) -> Frame:
    """The render loop's detector stage: expected photons per pixel (a whole frame, or a window at
    ``origin_uv`` of a detector of ``detector_shape`` (rows, cols)) → a :class:`Frame` with its sidecar.
    ``seed`` drives the detector noise; ``frame_seed`` (default ``seed``) is the seed the sidecar
    records, the one the whole frame is reproduced from when the detector's is derived from it.
    ``added_e``: electrons added after the shot noise (hot pixels, cosmic rays), same shape as ``photons``."""
    from rigsim.detector import apply_detector
    from rigsim.render.budget import fit_processes

    rows, cols = detector_shape if detector_shape is not None else np.shape(photons)
    fit_processes(1, int(rows) * int(cols), f"a {cols}×{rows} px detector")  # one line, not an out-of-memory kill
    kw = {"origin_uv": tuple(origin_uv), "detector_shape": detector_shape} if detector_shape is not None else {}
    if added_e is not None:
        kw["added_e"] = added_e
    det = apply_detector(photons, detector_config, seed=seed, noiseless=noiseless, **kw)
    sidecar = build_sidecar(truth=truth, render=render, detector_frame=det, geometry_flags=geometry_flags, pose=pose,
                            seed=seed if frame_seed is None else frame_seed, extra=sidecar_extra)
    shape = detector_shape if detector_shape is not None else tuple(np.shape(photons))
    return Frame(det.dn, sidecar, tuple(int(x) for x in origin_uv), tuple(shape), photons, det, truth_object,
                 dict(extra or {}), float(seconds), int(index), float(time_s))
