"""Planar calibration targets: point layouts, bitmaps and the exact projection of their points.

Target frame (OpenCV's object-point convention): the board lies in the plane z = 0, x along a row of
points (right as printed), y down the columns, origin at point 0; the printed side faces −z, so the
pose ``rvec = 0, tvec = (0, 0, d)`` shows the board upright and unmirrored ``d`` mm in front of the
camera. A pose is ``p_cam = R(rvec) p_target + tvec`` (``cv2.projectPoints``), here in degrees and mm.

Specs (:func:`parse_target`):

* ``chessboard:COLSxROWS:SQUARE_MM`` — COLS × ROWS *squares*; its points are the (COLS−1) × (ROWS−1)
  inner corners, row by row, i.e. OpenCV's ``patternSize = (COLS−1, ROWS−1)``; square (0, 0) (top
  left) is black; a white margin one square wide surrounds the board.
* ``circles:COLSxROWS:PITCH_MM:DIAM_MM`` — a symmetric grid of COLS × ROWS black disks on white
  (``cv2.findCirclesGrid`` with ``patternSize = (COLS, ROWS)``), points = disk centres, margin one pitch.
* ``image:PATH:WIDTH_MM`` — a user's single-channel 8/16-bit image printed WIDTH_MM wide (height from
  its aspect); points = its four outer corners (top-left, top-right, bottom-right, bottom-left).

No Mitsuba here: ``rigsim.render.target`` draws the bitmap through the rig's true camera.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.errors import InputError
from rigsim.files import Column, read_image, read_table

from .camera import PinholeBrown

__all__ = [
    "POSE_COLUMNS",
    "TARGET_SPECS",
    "PlanarTarget",
    "TargetPoses",
    "chessboard",
    "circle_grid",
    "image_target",
    "parse_target",
    "project_target",
    "read_poses",
    "spread_poses",
    "target_to_camera",
    "write_poses",
]

TARGET_SPECS = "chessboard:COLSxROWS:SQUARE_MM, circles:COLSxROWS:PITCH_MM:DIAM_MM or image:PATH:WIDTH_MM"
_GRID = re.compile(r"^\s*([0-9]+)\s*[xX×]\s*([0-9]+)\s*$")


@dataclass(frozen=True)
class PlanarTarget:
    """A planar target: its points (N, 2) mm in the target frame, the printed rectangle
    ``extent_mm = (x0, y0, x1, y1)`` and how to draw it (:meth:`bitmap`)."""

    kind: str
    spec: str
    points_mm: np.ndarray
    extent_mm: tuple[float, float, float, float]
    pattern_size: tuple[int, int] | None
    filter: str  # texture filter the renderer uses: "nearest" (exact edges) or "bilinear"
    params: dict = field(default_factory=dict)
    image: np.ndarray | None = field(default=None, repr=False)  # image targets: reflectance in [0, 1]

    @property
    def size_mm(self) -> tuple[float, float]:
        x0, y0, x1, y1 = self.extent_mm
        return x1 - x0, y1 - y0

    def object_points(self) -> np.ndarray:
        """Points (N, 3) with z = 0, as ``cv2.calibrateCamera`` takes them (float32 there)."""
        return np.column_stack([self.points_mm, np.zeros(len(self.points_mm))])

    def corners_mm(self) -> np.ndarray:
        """The printed rectangle's corners (4, 2): top-left, top-right, bottom-right, bottom-left."""
        x0, y0, x1, y1 = self.extent_mm
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])

    def bitmap(self) -> np.ndarray:
        """Reflectance (rows, cols) in [0, 1] over ``extent_mm``; row 0 at y0, column 0 at x0."""
        if self.kind == "chessboard":
            c, r = self.params["cols"], self.params["rows"]
            j, i = np.indices((r + 2, c + 2))
            inside = (i >= 1) & (i <= c) & (j >= 1) & (j <= r)
            return np.where(inside & ((i + j) % 2 == 0), 0.0, 1.0)
        if self.kind == "circles":
            return _circle_bitmap(**self.params)
        return np.asarray(self.image, float)

    def describe(self) -> str:
        w, h = self.size_mm
        ps = f", OpenCV patternSize {self.pattern_size}" if self.pattern_size else ""
        return f"{self.spec}: {len(self.points_mm)} points, printed {w:g} × {h:g} mm{ps}"


def chessboard(cols: int, rows: int, square_mm: float, *, spec: str | None = None) -> PlanarTarget:
    """COLS × ROWS squares; points = the inner corners row by row (patternSize (cols−1, rows−1))."""
    if not (3 <= cols <= 200 and 3 <= rows <= 200):
        raise InputError(f"chessboard {cols}x{rows}: expected 3 to 200 squares each way")
    if not (math.isfinite(square_mm) and 0 < square_mm <= 1e4):
        raise InputError(f"chessboard square {square_mm} mm: expected a number > 0 and ≤ 10000 mm")
    j, i = np.indices((rows - 1, cols - 1))
    pts = np.column_stack([i.ravel(), j.ravel()]) * float(square_mm)
    s = float(square_mm)
    return PlanarTarget("chessboard", spec or f"chessboard:{cols}x{rows}:{square_mm:g}", pts.astype(float),
                        (-2 * s, -2 * s, cols * s, rows * s), (cols - 1, rows - 1), "nearest",
                        {"cols": int(cols), "rows": int(rows), "square_mm": s})


def circle_grid(cols: int, rows: int, pitch_mm: float, diameter_mm: float, *, spec: str | None = None,
                texels_per_pitch: int = 64) -> PlanarTarget:
    """A symmetric COLS × ROWS grid of disks (patternSize (cols, rows)); points = disk centres."""
    if not (2 <= cols <= 200 and 2 <= rows <= 200):
        raise InputError(f"circle grid {cols}x{rows}: expected 2 to 200 circles each way")
    if not (math.isfinite(pitch_mm) and 0 < pitch_mm <= 1e4):
        raise InputError(f"circle pitch {pitch_mm} mm: expected a number > 0 and ≤ 10000 mm")
    if not (math.isfinite(diameter_mm) and 0 < diameter_mm < pitch_mm):
        raise InputError(f"circle diameter {diameter_mm} mm: expected a number > 0 and below the pitch ({pitch_mm:g} mm)")
    j, i = np.indices((rows, cols))
    p = float(pitch_mm)
    pts = np.column_stack([i.ravel(), j.ravel()]) * p
    return PlanarTarget("circles", spec or f"circles:{cols}x{rows}:{pitch_mm:g}:{diameter_mm:g}", pts.astype(float),
                        (-p, -p, cols * p, rows * p), (cols, rows), "bilinear",
                        {"cols": int(cols), "rows": int(rows), "pitch_mm": p, "diameter_mm": float(diameter_mm),
                         "texels_per_pitch": int(texels_per_pitch)})


def _circle_bitmap(cols, rows, pitch_mm, diameter_mm, texels_per_pitch, sub: int = 4) -> np.ndarray:
    """Area coverage (sub × sub samples per texel) of the disks; disk centres on texel corners."""
    n = int(texels_per_pitch)
    H, W = (rows + 1) * n, (cols + 1) * n
    o = (np.arange(sub) + 0.5) / sub
    out = np.zeros((H, W))
    rad = 0.5 * diameter_mm / pitch_mm * n  # in texels
    for a in o:
        for b in o:
            y = (np.arange(H) + a)[:, None] / n - 1.0  # in pitches from point 0
            x = (np.arange(W) + b)[None, :] / n - 1.0
            cx = np.clip(np.round(x), 0, cols - 1)
            cy = np.clip(np.round(y), 0, rows - 1)
            out += ((x - cx) ** 2 + (y - cy) ** 2) * n * n < rad * rad
    return 1.0 - out / (sub * sub)


def image_target(path, width_mm: float, *, spec: str | None = None) -> PlanarTarget:
    """A user's single-channel 8/16-bit PNG/TIFF (or FITS) image printed ``width_mm`` wide."""
    if not (math.isfinite(width_mm) and 0 < width_mm <= 1e5):
        raise InputError(f"image target width {width_mm} mm: expected a number > 0 and ≤ 100000 mm")
    img = read_image(path, what="target image")
    if min(img.shape) < 2:
        raise InputError(f"{path}: {img.shape[1]}×{img.shape[0]} px; expected at least 2×2 px for a target image")
    if img.dtype == np.uint8:
        refl = img / 255.0
    elif img.dtype == np.uint16:
        refl = img / 65535.0
    else:
        lo, hi = float(img.min()), float(img.max())
        if lo < 0 or hi > 1:
            raise InputError(f"{path}: float pixel values {lo:g}..{hi:g}; expected reflectances in 0..1")
        refl = np.asarray(img, float)
    h_mm = width_mm * img.shape[0] / img.shape[1]
    t = PlanarTarget("image", spec or f"image:{path}:{width_mm:g}", np.zeros((0, 2)), (0.0, 0.0, float(width_mm), h_mm),
                     None, "bilinear", {"path": str(path), "width_mm": float(width_mm), "pixels": list(img.shape[::-1])},
                     refl)
    return PlanarTarget(t.kind, t.spec, t.corners_mm(), t.extent_mm, None, t.filter, t.params, refl)


def _number(spec: str, text: str, what: str) -> float:
    from rigsim.files.numbers import parse_float

    try:
        x = parse_float(text)
    except ValueError:
        raise InputError(f"--target {spec!r}: {what} {text!r} is not a number; expected {TARGET_SPECS}") from None
    return x


def _grid(spec: str, text: str) -> tuple[int, int]:
    m = _GRID.match(text)
    if not m:
        raise InputError(f"--target {spec!r}: {text!r} is not COLSxROWS (e.g. 9x7); expected {TARGET_SPECS}")
    return int(m.group(1)), int(m.group(2))


def parse_target(spec: str) -> PlanarTarget:
    """A target from its spec string (module docstring); one-line :class:`InputError` otherwise."""
    kind, _, rest = str(spec).partition(":")
    kind = kind.strip().lower()
    parts = rest.split(":")
    if kind == "image":
        path, sep, width = rest.rpartition(":")
        if not sep or not path:
            raise InputError(f"--target {spec!r}: expected image:PATH:WIDTH_MM (e.g. image:logo.png:150)")
        w = _number(spec, width, "WIDTH_MM")
        return image_target(Path(path), w, spec=spec)  # errors about the file name the file
    try:
        if kind == "chessboard":
            if len(parts) != 2:
                raise InputError("expected chessboard:COLSxROWS:SQUARE_MM (e.g. chessboard:10x7:20)")
            c, r = _grid(spec, parts[0])
            return chessboard(c, r, _number(spec, parts[1], "SQUARE_MM"), spec=spec)
        if kind == "circles":
            if len(parts) != 3:
                raise InputError("expected circles:COLSxROWS:PITCH_MM:DIAM_MM (e.g. circles:7x5:20:10)")
            c, r = _grid(spec, parts[0])
            return circle_grid(c, r, _number(spec, parts[1], "PITCH_MM"), _number(spec, parts[2], "DIAM_MM"), spec=spec)
    except InputError as exc:
        if str(exc).startswith("--target"):
            raise
        raise InputError(f"--target {spec!r}: {exc}") from None
    raise InputError(f"--target {spec!r}: unknown kind {kind!r}; expected {TARGET_SPECS}")


# -- poses ----------------------------------------------------------------------------------------
POSE_COLUMNS = (Column("frame", kind="str"), Column("rx", "deg"), Column("ry", "deg"), Column("rz", "deg"),
                Column("tx", "mm"), Column("ty", "mm"), Column("tz", "mm"))
"""The poses table: one row per frame; (rx, ry, rz) is OpenCV's rvec in degrees, (tx, ty, tz) its tvec in mm."""
_STEM = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,99}$")


@dataclass(frozen=True)
class TargetPoses:
    """Target poses in the camera frame: ``frames`` (file stems), ``rvec_deg`` (N, 3), ``tvec_mm`` (N, 3)."""

    frames: tuple[str, ...]
    rvec_deg: np.ndarray
    tvec_mm: np.ndarray

    def __len__(self) -> int:
        return len(self.frames)


def read_poses(path, target: PlanarTarget | None = None) -> TargetPoses:
    """Read a poses CSV/Parquet (:data:`POSE_COLUMNS`). Each frame name must be a plain file stem
    (letters, digits, ``_.-``) used once; with ``target``, its centre must lie in front of the camera."""
    t = read_table(path, POSE_COLUMNS, what="target poses")
    lines = t["__line__"]
    frames = [str(f) for f in t["frame"]]
    if not frames:
        raise InputError(f"{path}: no rows; expected one row per frame (frame, rx_deg, ry_deg, rz_deg, tx_mm, ty_mm, tz_mm)")
    seen: dict[str, int] = {}
    for f, ln in zip(frames, lines):
        if not _STEM.match(f) or f.lower().endswith((".png", ".json")):
            raise InputError(f"{path}: line {ln}, column frame: {f!r}; expected a file stem of letters, digits, _ . - "
                             "(no suffix, no folder)")
        if f in seen:
            raise InputError(f"{path}: line {ln}, column frame: {f!r} already used on line {seen[f]}")
        seen[f] = int(ln)
    rv = np.column_stack([t["rx_deg"], t["ry_deg"], t["rz_deg"]])
    tv = np.column_stack([t["tx_mm"], t["ty_mm"], t["tz_mm"]])
    if target is not None:
        x0, y0, x1, y1 = target.extent_mm
        centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
        for k, ln in enumerate(lines):
            R, tt = target_to_camera(rv[k], tv[k])
            z = (R @ centre + tt)[2]
            if not z > 0:
                raise InputError(f"{path}: line {ln}: the target's centre is at z = {z:.6g} mm in the camera frame; "
                                 "expected it in front of the camera (z > 0)")
    return TargetPoses(tuple(frames), rv, tv)


def write_poses(path, poses: TargetPoses):
    """Write poses as a table :func:`read_poses` reads (.csv or .parquet)."""
    from rigsim.files import write_table

    cols = {"frame": list(poses.frames)}
    for i, k in enumerate(("rx_deg", "ry_deg", "rz_deg")):
        cols[k] = poses.rvec_deg[:, i]
    for i, k in enumerate(("tx_mm", "ty_mm", "tz_mm")):
        cols[k] = poses.tvec_mm[:, i]
    return write_table(path, cols)


def spread_poses(target: PlanarTarget, n: int, *, distance_mm: tuple[float, float], field_deg: float,
                 tilt_deg: float = 25.0, seed: int = 0, prefix: str = "frame") -> TargetPoses:
    """``n`` poses whose board centres spiral out to ``field_deg`` off the optical axis at distances drawn
    in ``distance_mm``, each board facing the camera and tilted by up to ``tilt_deg`` about its x and y
    axes (a calibration set; frames ``<prefix>_000``, …)."""
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = target.extent_mm
    c = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    rv, tv = np.zeros((n, 3)), np.zeros((n, 3))
    for k in range(n):
        a, az = math.radians(field_deg) * math.sqrt((k + 0.5) / n), 2.399963 * k  # golden-angle spiral
        d = np.array([math.sin(a) * math.cos(az), math.sin(a) * math.sin(az), math.cos(a)])
        xa = np.cross([0.0, 1.0, 0.0], d)
        xa /= np.linalg.norm(xa)
        tilt = Rotation.from_rotvec(np.radians(rng.uniform(-tilt_deg, tilt_deg, 3) * [1.0, 1.0, 0.3])).as_matrix()
        R = np.column_stack([xa, np.cross(d, xa), d]) @ tilt
        rv[k] = np.degrees(Rotation.from_matrix(R).as_rotvec())
        tv[k] = rng.uniform(*distance_mm) * d - R @ c
    return TargetPoses(tuple(f"{prefix}_{k:03d}" for k in range(n)), rv, tv)


def target_to_camera(rvec_deg, tvec_mm) -> tuple[np.ndarray, np.ndarray]:
    """``(R_cam_from_target, t_mm)`` of a pose given as OpenCV's rvec (degrees) and tvec (mm)."""
    R = Rotation.from_rotvec(np.radians(np.asarray(rvec_deg, float))).as_matrix()
    return R, np.asarray(tvec_mm, float).reshape(3)


def project_target(camera: PinholeBrown, target_points_mm, rvec_deg, tvec_mm) -> tuple[np.ndarray, np.ndarray]:
    """Exact pixels (N, 2) of target points (N, 2) mm at a pose, and ``visible`` (N,): in front of the
    camera, inside the lens model's domain, on the detector, and the printed side facing the camera."""
    R, t = target_to_camera(rvec_deg, tvec_mm)
    xy = np.asarray(target_points_mm, float).reshape(-1, 2)
    p = xy @ R[:, :2].T + t
    uv, ok = camera.project_valid(p)
    facing = float(R[:, 2] @ t) > 0.0  # the printed side's normal −z_target points back to the pinhole
    vis = ok & camera.on_detector(np.where(ok[:, None], uv, np.nan)) & facing
    return uv, vis
