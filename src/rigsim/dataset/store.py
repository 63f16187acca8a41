"""Dataset files on disk: atomic frame writes, checksums, the plan, the truth table, the manifest.

Layout of a dataset directory::

    plan.json              what is being generated (rig file text, generator, seed, N / sweep);
                           written first, checked on every rerun (resume)
    frames/frame_000042.png    lossless 16-bit PNG (img[v, u]; FITS for star frames)
    frames/frame_000042.json   the frame's sidecar: truth, render settings, seeds, flags and the
                               SHA-256 of the image file; written *after* the image, so a frame
                               is complete exactly when its JSON exists and the checksum matches
    truth.parquet, truth.csv   one row per frame: every truth column (written at the end)
    manifest.json          rig file, software versions, seeds, and the SHA-256 of every file

Every file is written to a temporary name in the same directory and moved into place with
``os.replace`` (atomic on POSIX), so a killed generator never leaves a half-written file under a
final name.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from rigsim.errors import DatasetError

FORMAT = "rigsim.dataset/1"


def sha256_bytes(b: bytes) -> str:
    return hashlib.sha256(b).hexdigest()


def sha256_file(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def atomic_write_bytes(path, data: bytes) -> None:
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def atomic_write_json(path, obj) -> None:
    from rigsim.render.frame import _jsonable

    atomic_write_bytes(path, (json.dumps(_jsonable(obj), indent=1) + "\n").encode())


def encode_image(img: np.ndarray, fmt: str) -> bytes:
    """Lossless bytes of a uint16 image: PNG (OpenCV) or FITS (astropy)."""
    a = np.asarray(img)
    if a.dtype != np.uint16 or a.ndim != 2:
        raise ValueError(f"frames must be 2-D uint16, got {a.dtype} {a.shape}")
    if fmt == "png":
        import cv2

        ok, buf = cv2.imencode(".png", a, [cv2.IMWRITE_PNG_COMPRESSION, 3])
        if not ok:
            raise RuntimeError("PNG encoding failed")
        return buf.tobytes()
    if fmt == "fits":
        import io

        from astropy.io import fits

        bio = io.BytesIO()
        fits.PrimaryHDU(a).writeto(bio)
        return bio.getvalue()
    raise ValueError(f"image format {fmt!r}: must be 'png' or 'fits'")


def decode_image(path) -> np.ndarray:
    path = Path(path)
    if path.suffix == ".fits":
        from astropy.io import fits

        with fits.open(path, memmap=False) as h:
            return np.asarray(h[0].data).astype(np.uint16)
    import cv2

    a = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if a is None:
        raise DatasetError(f"{path}: not a readable image (corrupt or truncated)")
    return a


def frame_stem(index: int) -> str:
    return f"frame_{index:06d}"


def frame_files(root, index: int, fmt: str) -> tuple[Path, Path]:
    d = Path(root) / "frames"
    return d / f"{frame_stem(index)}.{fmt}", d / f"{frame_stem(index)}.json"


def write_frame_atomic(root, index: int, img: np.ndarray, sidecar: dict, fmt: str = "png") -> str:
    """Image first, then the sidecar holding its checksum; returns the image's SHA-256."""
    ip, jp = frame_files(root, index, fmt)
    ip.parent.mkdir(parents=True, exist_ok=True)
    data = encode_image(img, fmt)
    digest = sha256_bytes(data)
    atomic_write_bytes(ip, data)
    sc = dict(sidecar)
    sc["dataset"] = {**sc.get("dataset", {}), "index": int(index), "image_file": ip.name, "image_sha256": digest}
    atomic_write_json(jp, sc)
    return digest


def frame_complete(root, index: int, fmt: str, verify: bool = True) -> bool:
    """A frame is complete when its sidecar parses and names the image's checksum."""
    ip, jp = frame_files(root, index, fmt)
    if not (ip.exists() and jp.exists()):
        return False
    try:
        sc = json.loads(jp.read_text())
        want = sc["dataset"]["image_sha256"]
    except (ValueError, KeyError, TypeError):
        return False
    return (not verify) or sha256_file(ip) == want


def read_json(path, what: str) -> dict:
    path = Path(path)
    if not path.exists():
        raise DatasetError(f"{path}: missing ({what})")
    try:
        return json.loads(path.read_text())
    except ValueError as e:
        raise DatasetError(f"{path}: corrupt JSON ({what}): {e}") from None
