"""An OpenCV camera (``cv2.FileStorage`` YAML, JSON or XML: ``camera_matrix``, ``distortion_coefficients``,
``image_width``, ``image_height``, as ``calibrateCamera`` results are usually saved) pasted into a rig file's
camera: the sun sensor of a cube-mirror rig, or the star sensor of a seed-004 rig. The rig file keeps its
comments and layout (tomlkit); only the intrinsics change. docs/custom-rig.md has the mapping."""

from __future__ import annotations

import math
import re
import stat
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rigsim.errors import InputError, RigError

MATRIX_KEYS = ("camera_matrix", "cameraMatrix", "K", "intrinsic_matrix")
DIST_KEYS = ("distortion_coefficients", "dist_coeffs", "distCoeffs", "D", "distortion")
DIST_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "tau_x", "tau_y")


@dataclass
class OpenCVCamera:
    fx: float
    fy: float
    cx: float
    cy: float
    dist: dict[str, float]
    size: tuple[int, int] | None  # (width, height)
    skew: float = 0.0


def read_opencv_camera(path) -> OpenCVCamera:
    """The camera in an OpenCV FileStorage file; one line naming the file and the key for anything unusable."""
    import cv2

    path = Path(path)
    try:
        st = path.stat()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode) or st.st_size > (1 << 20):
        raise InputError(f"{path}: not a regular file of at most 1 MiB; expected an OpenCV FileStorage camera (.yml, .json)")
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte {exc.start}); expected an OpenCV FileStorage camera") from None
    if path.suffix.lower() in (".yml", ".yaml") and not text.lstrip().startswith("%YAML"):
        text = "%YAML:1.0\n" + text  # OpenCV insists on its header; files written by hand often lack it
    check_filestorage_text(text, path)
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError) as exc:  # OpenCV's parser raises through a SystemError on some syntax errors
        cause = exc.__cause__ or exc
        raise InputError(f"{path}: not an OpenCV FileStorage file ({str(cause).strip().splitlines()[-1][:120]})") from None
    try:
        if not fs.root().isMap():  # a list or a scalar at the top: OpenCV's getNode would assert
            raise InputError(f"{path}: the top level is not a map of named nodes; expected an OpenCV FileStorage "
                             "camera (camera_matrix, distortion_coefficients, image_width, image_height)")
        K = _matrix(fs, MATRIX_KEYS)
        D = _matrix(fs, DIST_KEYS)
        size = tuple(_integer(fs, k) for k in ("image_width", "image_height"))
    except cv2.error as exc:
        raise InputError(f"{path}: not an OpenCV FileStorage camera ({str(exc).strip().splitlines()[-1][:120]})") from None
    finally:
        fs.release()
    if K is None:
        raise InputError(f"{path}: no camera matrix (looked for {', '.join(MATRIX_KEYS)})")
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise InputError(f"{path}: camera_matrix is {K.shape[0]}×{K.shape[1] if K.ndim > 1 else 1}; expected a finite 3×3 matrix")
    if not (K[1, 0] == 0 and K[2, 0] == 0 and K[2, 1] == 0 and abs(K[2, 2] - 1.0) < 1e-9):
        raise InputError(f"{path}: camera_matrix is not [[fx, s, cx], [0, fy, cy], [0, 0, 1]]")
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    if not (fx > 0 and fy > 0):
        raise InputError(f"{path}: camera_matrix fx = {fx:g}, fy = {fy:g}; both must be positive")
    d = np.zeros(0) if D is None else D.ravel()
    if len(d) not in (0, 4, 5, 8, 12, 14) or not np.all(np.isfinite(d)):
        raise InputError(f"{path}: distortion_coefficients has {len(d)} finite values; OpenCV's are 4, 5, 8, 12 or 14")
    dist = {n: float(v) for n, v in zip(DIST_NAMES, d)}
    w, h = size
    return OpenCVCamera(fx, fy, cx, cy, dist, (w, h) if w and h else None, float(K[0, 1]))


MAX_DEPTH = 64
"""Deepest nesting read from a FileStorage file (a camera file nests 2 deep; OpenCV's parser recurses and
crashes near 10⁵)."""
_DIMS = re.compile(r'(?<![A-Za-z_])["\']?(rows|cols)["\']?\s*:\s*"?([0-9]+)|<(rows|cols)>\s*([0-9]+)\s*</(?:rows|cols)>')
_SIZES = re.compile(r'(?<![A-Za-z_])["\']?sizes["\']?\s*(?::|>)\s*\[?\s*([0-9][0-9\s,]*)')
_XML_TAG = re.compile(r"<(/?)[A-Za-z_][^\s>/]*[^>]*?(/?)>")


def _block_depth(text: str) -> int:
    """Nesting of a YAML file's block structure: indentation levels, plus '- ' items opened on one line."""
    stack: list[int] = []
    deepest = 0
    for line in text.splitlines():
        body = line.lstrip(" ")
        if not body or body.startswith(("#", "%", "---", "...")):
            continue
        indent = len(line) - len(body)
        while stack and stack[-1] >= indent:
            stack.pop()
        stack.append(indent)
        dashes = 0
        while body.startswith("- ") or body == "-":
            dashes += 1
            body = body[2:].lstrip(" ")
        deepest = max(deepest, len(stack) + dashes)
    return deepest


def _xml_depth(text: str) -> int:
    depth = deepest = 0
    for m in _XML_TAG.finditer(text):
        if m.group(0).startswith(("<?", "<!")):
            continue
        if m.group(1):
            depth -= 1
        elif not m.group(2):
            depth += 1
            deepest = max(deepest, depth)
    return deepest


def check_filestorage_text(text: str, path) -> None:
    """Refuse, before OpenCV parses it, a FileStorage text nested deeper than :data:`MAX_DEPTH` or with a
    matrix whose ``rows × cols`` (or ``sizes``) claims more values than the file can hold (OpenCV allocates the
    claimed size first: 10⁶ × 10⁶ doubles are 8 TB)."""
    from rigsim.files.results import json_depth

    depth = _xml_depth(text) if text.lstrip().startswith("<") else json_depth(text) + _block_depth(text)
    if depth > MAX_DEPTH:
        raise InputError(f"{path}: nested {depth} deep; an OpenCV camera file is read when it nests at most {MAX_DEPTH} "
                         "deep")
    dims = [(m.group(1) or m.group(3), int(m.group(2) or m.group(4))) for m in _DIMS.finditer(text)]
    claims = [int(np.prod([int(x) for x in re.split(r"[\s,]+", m.group(1).strip()) if x], dtype=object))
              for m in _SIZES.finditer(text)]
    rows = [n for k, n in dims if k == "rows"]
    cols = [n for k, n in dims if k == "cols"]
    claims += [r * c for r, c in zip(rows, cols)] + [n for n in rows + cols if n > len(text)]
    big = [c for c in claims if c > len(text)]
    if big:
        raise InputError(f"{path}: a matrix claims {big[0]} values ({', '.join(f'{k} {n}' for k, n in dims[:2])}) in a file "
                         f"of {len(text)} characters; expected the camera_matrix (3×3) and distortion_coefficients")


def _matrix(fs, keys):
    for k in keys:
        node = fs.getNode(k)
        if not node.empty():
            m = node.mat()
            if m is None and node.isSeq():
                m = np.array([node.at(i).real() for i in range(node.size())])
            return None if m is None else np.asarray(m, float)
    return None


def _integer(fs, key) -> int | None:
    node = fs.getNode(key)
    if node.empty():
        return None
    v = node.real()
    return int(v) if math.isfinite(v) and v == int(v) and 16 <= v <= 20000 else None


def import_camera(rig_text: str, rig_path, cam: OpenCVCamera, *, pixel_pitch_um: float | None = None,
                  source: str = "camera") -> tuple[str, list[str], list[str]]:
    """The rig file's text with ``cam``'s intrinsics in its camera, the lines that say what changed and the
    lines that say what was left as it was (what an OpenCV file does not hold).

    A star rig's ``[nominal]`` (what the estimators start from) takes the same intrinsics as ``[sensor]``: an
    imported calibration is both the best description of the instrument and what the user believes. A camera
    whose image size differs from the rig's detector needs ``pixel_pitch_um`` (the rig's pitch belongs to its
    own detector; a crop of it keeps the pitch: give it again)."""
    import tomlkit

    doc = tomlkit.parse(rig_text)
    if "sun_sensor" in doc:
        sec, name = doc["sun_sensor"], "sun_sensor"
    elif "sensor" in doc:
        sec, name = doc["sensor"], "sensor"
    else:
        raise RigError(rig_path, ["no [sun_sensor] or [sensor] table: only a sun sensor or a star sensor takes an OpenCV camera"])
    pitch = float(pixel_pitch_um if pixel_pitch_um is not None else sec.get("pixel_pitch_um", 0.0))
    if not (pitch > 0):
        raise RigError(rig_path, [f"{name}.pixel_pitch_um is missing; give --pixel-pitch-um (OpenCV's matrix is in pixels)"])
    extra = {k: v for k, v in cam.dist.items() if k not in ("k1", "k2", "p1", "p2", "k3") and v != 0.0}
    if extra:
        raise InputError(f"{source}: distortion {', '.join(f'{k} = {v:g}' for k, v in extra.items())}: rigsim's camera "
                         "has k1, k2, p1, p2, k3 only (OpenCV's 5-coefficient model)")
    if abs(cam.skew) > 1e-9 * cam.fx:
        raise InputError(f"{source}: camera_matrix skew = {cam.skew:g}: rigsim's camera has none")
    old_size = _plain(sec.get("resolution_px"))
    if cam.size is not None and old_size is not None and list(cam.size) != list(old_size) and pixel_pitch_um is None:
        raise InputError(f"{source}: the camera's image is {cam.size[0]}×{cam.size[1]} px, the rig's {name} "
                         f"{old_size[0]}×{old_size[1]} px: give --pixel-pitch-um (the camera's pixel pitch; the rig's "
                         f"{pitch:g} µm belongs to its own detector, a crop of it keeps it)")
    changes: list[str] = []

    def put(table, key, value, text, prefix=name):
        old = _plain(table.get(key))
        table[key] = value
        if old != value:
            changes.append(f"{prefix}.{text}: {old} → {value}")

    if cam.size is not None:
        put(sec, "resolution_px", list(cam.size), "resolution_px")
    if pixel_pitch_um is not None:
        put(sec, "pixel_pitch_um", float(pixel_pitch_um), "pixel_pitch_um")
    put(sec, "focal_length_mm", round(cam.fx * pitch * 1e-3, 9), "focal_length_mm")
    put(sec, "principal_point_px", [round(cam.cx, 6), round(cam.cy, 6)], "principal_point_px")
    k = {n: round(cam.dist.get(n, 0.0), 9) for n in ("k1", "k2", "p1", "p2", "k3")}
    if name == "sun_sensor":
        put(sec, "fy_over_fx", round(cam.fy / cam.fx, 12), "fy_over_fx")
        if "distortion" not in sec:
            sec["distortion"] = tomlkit.inline_table()
        for n, v in k.items():
            put(sec["distortion"], n, v, f"distortion.{n}")
    else:
        if abs(cam.fy / cam.fx - 1.0) > 1e-6:
            raise InputError(f"{source}: fy/fx = {cam.fy / cam.fx:.9f}; the star sensor has one focal length (square pixels)")
        if k["k3"] != 0.0:
            raise InputError(f"{source}: distortion k3 = {k['k3']:g}; the star sensor's model has k1, k2, p1, p2")
        for n in ("k1", "k2", "p1", "p2"):
            put(sec, n, k[n], n)
        _star_nominal(doc, sec, cam, k, put, changes)
    return tomlkit.dumps(doc), changes, _left_as_it_was(doc, name, pitch)


def _star_nominal(doc, sec, cam: OpenCVCamera, k: dict, put, changes: list[str]) -> None:
    """A star rig's [nominal] takes the imported intrinsics (created, with the schema's σ, if the rig has none)."""
    import tomlkit

    if "nominal" not in doc:
        doc["nominal"] = tomlkit.table()
        doc["nominal"]["focal_length_sigma_px"] = 10.0
        doc["nominal"]["principal_point_sigma_px"] = 10.0
        changes.append("nominal: a new table (the rig had none: its nominal was the design); σ 10 px each")
    nom = doc["nominal"]
    put(nom, "focal_length_mm", _plain(sec["focal_length_mm"]), "focal_length_mm", "nominal")
    put(nom, "principal_point_px", [round(cam.cx, 6), round(cam.cy, 6)], "principal_point_px", "nominal")
    for n in ("k1", "k2", "p1", "p2"):
        put(nom, n, k[n], n, "nominal")


def _left_as_it_was(doc, name: str, pitch_um: float) -> list[str]:
    """What an OpenCV file does not say, as the rig had it: the detector, the optics, the nominal's σ."""
    sec = doc[name]
    det = _plain(sec.get("detector")) or {}
    bits = det.get("adc_bits", 12)
    words = f" in {det['container_bits']}-bit words" if det.get("container_bits") is not None else ""
    left = [f"{name}.detector: {bits}-bit ADC{words}, offset {det.get('offset_dn', 64.0):g}, gain "
            f"{det.get('gain_dn_per_e', 0.2):g} DN/e⁻, read noise {det.get('read_noise_e', 5.0):g} e⁻, exposure "
            f"{det.get('exposure_s', 0.01):g} s: an OpenCV file has no detector; set your camera's"]
    if name == "sensor":
        ap = _plain(sec.get("aperture_diameter_mm"))
        if ap is not None:
            from rigsim.rig.star import PSF, psf_sigma_px

            N = _plain(sec["focal_length_mm"]) / ap
            try:
                sigma = f"σ now {psf_sigma_px(PSF(**(_plain(sec.get('psf')) or {})), N, pitch_um):.2f} px"
            except (ValueError, TypeError):  # an invalid [sensor.psf]: the rig's validation names it
                sigma = "invalid"
            left.append(f"sensor.aperture_diameter_mm: {ap:g} mm, now f/{N:.2f}; sensor.psf as it was ({sigma})")
        nom = doc["nominal"]
        left.append(f"nominal.focal_length_sigma_px {_plain(nom.get('focal_length_sigma_px', 10.0)):g} px, "
                    f"nominal.principal_point_sigma_px {_plain(nom.get('principal_point_sigma_px', 10.0)):g} px: "
                    "set them to your calibration's σ")
        left.append("[sky] [sequence] [identification] [calibration]: as they were (set for the rig's own field)")
    return left


def _plain(v):
    if hasattr(v, "unwrap"):
        v = v.unwrap()
    return v
