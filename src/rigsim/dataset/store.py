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
from pathlib import Path

import numpy as np

from rigsim.errors import DatasetError
from rigsim.files.atomic import atomic_write_bytes

FORMAT = "rigsim.dataset/1"


def sha256_bytes(b: bytes) -> str:
    return hashlib.sha256(b).hexdigest()


def sha256_file(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def atomic_write_json(path, obj) -> None:
    from rigsim.render.frame import _jsonable

    atomic_write_bytes(path, (json.dumps(_jsonable(obj), indent=1) + "\n").encode())


def canonical_sha256(obj) -> str:
    """SHA-256 of a JSON value's canonical text (sorted keys, no spaces): what a sidecar's own
    checksum covers, so a hand edit of any field is seen on resume and by ``verify``."""
    return sha256_bytes(json.dumps(obj, sort_keys=True, separators=(",", ":")).encode())


def encode_image(img: np.ndarray, fmt: str, header=None) -> bytes:
    """Lossless bytes of a uint16 image: PNG (OpenCV) or FITS (astropy, with the ``header`` cards)."""
    a = np.asarray(img)
    if a.dtype != np.uint16 or a.ndim != 2:
        raise ValueError(f"frames must be 2-D uint16, got {a.dtype} {a.shape}")
    from rigsim.files.images import encode_image as encode_frame

    if fmt == "png":
        return encode_frame(a, ".png")  # the one PNG writer (Huffman-only after the Average filter: fast, lossless)
    if fmt == "fits":
        return encode_frame(a, ".fits", header)  # the one FITS writer, header cards included
    raise ValueError(f"image format {fmt!r}: must be 'png' or 'fits'")


def decode_image(path) -> np.ndarray:
    """A dataset frame's pixels (through :func:`rigsim.files.read_image`: its header checked before decoding)."""
    from rigsim.files import read_image

    a = read_image(path, what="dataset frame")
    return a.astype(np.uint16) if Path(path).suffix == ".fits" else a


def frame_stem(index: int) -> str:
    return f"frame_{index:06d}"


def frame_files(root, index: int, fmt: str) -> tuple[Path, Path]:
    d = Path(root) / "frames"
    return d / f"{frame_stem(index)}.{fmt}", d / f"{frame_stem(index)}.json"


def write_frame_atomic(root, index: int, img: np.ndarray, sidecar: dict, fmt: str = "png", params=None) -> str:
    """Image first, then the sidecar holding the image's checksum, the checksum of the frame's plan entry
    (``params``) and its own; returns the image's SHA-256."""
    from rigsim.render.frame import _jsonable

    ip, jp = frame_files(root, index, fmt)
    data = encode_image(img, fmt, sidecar.get("fits_header"))
    digest = sha256_bytes(data)
    atomic_write_bytes(ip, data)
    sc = _jsonable(dict(sidecar))
    sc["dataset"] = {**sc.get("dataset", {}), "index": int(index), "image_file": ip.name, "image_sha256": digest}
    if params is not None:
        sc["dataset"]["params_sha256"] = canonical_sha256(_jsonable(params))
    sc["dataset"]["sidecar_sha256"] = canonical_sha256(sc)
    atomic_write_bytes(jp, (json.dumps(sc, indent=1) + "\n").encode())
    return digest


def sidecar_problem(jp, index: int, params=None) -> str | None:
    """Why a frame's sidecar cannot be trusted (None: it can): unreadable, not for this frame or this
    plan entry, or edited since it was written (its own checksum no longer matches)."""
    from rigsim.render.frame import _jsonable

    from rigsim.files.results import parse_json

    try:
        sc = parse_json(Path(jp).read_bytes(), jp, "sidecar", max_bytes=SIDECAR_MAX_BYTES)
        ds = sc["dataset"]
        want = ds.pop("sidecar_sha256")
        if not isinstance(want, str) or not isinstance(ds.get("image_sha256"), str):
            return "no checksums"
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError, AttributeError):
        return "unreadable or not written by rigsim dataset generate"
    if canonical_sha256(sc) != want:
        return "edited after it was written (its own checksum does not match)"
    if ds.get("index") != index:
        return f"written for frame {ds.get('index')!r}"
    if params is not None and ds.get("params_sha256") != canonical_sha256(_jsonable(params)):
        return "written for another plan (pose, seed or options differ)"
    return None


def frame_complete(root, index: int, fmt: str, verify: bool = True, params=None) -> bool:
    """A frame is complete when its sidecar is intact, is this frame's (and, given ``params``, this plan
    entry's) and names the image's checksum."""
    ip, jp = frame_files(root, index, fmt)
    if not (ip.is_file() and jp.is_file()) or ip.is_symlink() or jp.is_symlink():
        return False
    if sidecar_problem(jp, index, params) is not None:
        return False
    if not verify:
        return True
    from rigsim.files.results import parse_json

    want = parse_json(jp.read_bytes(), jp, "sidecar", max_bytes=SIDECAR_MAX_BYTES)["dataset"]["image_sha256"]
    return sha256_file(ip) == want


SIDECAR_MAX_BYTES = 1 << 20  # a frame's sidecar is a few kB (a star frame's truth: up to some 100 kB)


def read_json(path, what: str):
    """A dataset's JSON file (plan, manifest, sidecar) within :func:`rigsim.files.results.parse_json`'s nesting and
    integer bounds (no size bound: a plan grows with the frames)."""
    from rigsim.files.results import parse_json

    path = Path(path)
    if not path.exists():
        raise DatasetError(f"{path}: missing ({what})")
    if not path.is_file():
        raise DatasetError(f"{path}: not a regular file ({what})")
    return parse_json(path.read_bytes(), path, what.removeprefix("the "), max_bytes=None, error=DatasetError)
