"""Frames as plain image files: 8/16-bit single-channel PNG and TIFF (OpenCV) and FITS (astropy).

Pixel convention everywhere in rigsim: ``img[v, u]``, pixel (0, 0)'s centre at (u, v) = (0, 0)
(OpenCV's; FITS counts from 1, so FITS pixel (1, 1) is rigsim's (0, 0))."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from rigsim.errors import InputError

from .atomic import atomic_write_bytes

FRAME_SUFFIXES = (".png", ".tif", ".tiff", ".fits", ".fit", ".fts")
_BITS = {np.dtype(np.uint8): 8, np.dtype(np.uint16): 16}


def _regular_file(path: Path) -> None:
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if not path.is_file():
        raise InputError(f"{path}: not a regular file (a folder, FIFO or device); expected an image file")


FITS_MAX_ABS = 1e9
"""Largest |pixel| of a float FITS frame: no detector counts more; beyond it a frame is a unit or scaling error
(and squares of 1e300 overflow)."""


def _read_fits(path: Path) -> np.ndarray:
    from astropy.io import fits

    try:
        with fits.open(path, memmap=False) as hdul:
            for hdu in hdul:
                if hdu.data is not None and getattr(hdu, "is_image", True):
                    data = np.asarray(hdu.data)
                    break
            else:
                raise InputError(f"{path}: no image HDU with data; expected a 2-D image")
    except (OSError, TypeError, ValueError, MemoryError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{path}: not a readable FITS file ({exc})") from None
    if data.ndim != 2:
        raise InputError(f"{path}: FITS image of shape {data.shape}; expected a 2-D (rows, cols) image")
    if data.dtype.kind == "f":
        with np.errstate(all="ignore"):
            data = data.astype(np.float64)
            finite = np.isfinite(data)
            if not np.all(finite):
                raise InputError(f"{path}: FITS image holds NaN or infinite pixels; expected finite values")
            big = float(np.max(np.abs(data))) if data.size else 0.0
        if big > FITS_MAX_ABS:
            raise InputError(f"{path}: FITS pixel values up to {big:.3g} in magnitude; expected at most "
                             f"{FITS_MAX_ABS:.0e} (DN or electrons): check BSCALE/BZERO and the units")
        return data
    if data.dtype.kind in "iu":
        lo, hi = int(data.min()), int(data.max())
        if lo < 0 or hi > 65535:
            raise InputError(f"{path}: FITS pixel values {lo}..{hi}; expected 0..65535 (an 8- or 16-bit frame)")
        return data.astype(np.uint16 if hi > 255 or data.dtype.itemsize > 1 else np.uint8)
    raise InputError(f"{path}: FITS data type {data.dtype}; expected integer or float pixels")


def _check_header(path: Path, suffix: str, shape, what: str) -> None:
    """The image's header against the rig's detector (``shape`` = (rows, cols)), the page count and the
    memory budget, before any pixel is decoded."""
    from .image_header import read_header
    from .memory import check_frame_pixels

    try:
        h = read_header(path, suffix)
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if h.pages > 1:
        kind = "a multi-page TIFF" if suffix in (".tif", ".tiff") else "a FITS file with several images"
        raise InputError(f"{path}: {kind} ({h.pages} {'pages' if suffix != '.fits' else 'image HDUs with data'}); "
                         f"rigsim reads one {what} per file: split it into single-image files")
    if shape is not None and (h.height, h.width) != tuple(shape):
        raise InputError(f"{path}: {h.width}×{h.height} px (width×height); expected {shape[1]}×{shape[0]} px, the rig's "
                         "detector")
    check_frame_pixels(path, h.width, h.height, h.channels, what=what)


def read_image(path, *, shape: tuple[int, int] | None = None, allowed_bits=(8, 16), what: str = "frame") -> np.ndarray:
    """A single-channel frame as an array ``img[v, u]``: uint8/uint16 for PNG and TIFF (and
    integer FITS), float64 for float FITS. ``shape`` = (rows, cols) to check the size against.

    The header is read first (:mod:`rigsim.files.image_header`): its size is checked against ``shape`` and
    the memory budget (:func:`rigsim.files.memory.check_frame_pixels`), a multi-page TIFF or a FITS file with
    several images is refused, and a file whose content is not its suffix's format is never decoded."""
    path = Path(path)
    _regular_file(path)
    suffix = path.suffix.lower()
    if suffix not in FRAME_SUFFIXES:
        raise InputError(f"{path}: unsupported {what} file type {suffix or '(none)'!r}; expected one of "
                         f"{', '.join(FRAME_SUFFIXES)}")
    _check_header(path, suffix, shape, what)
    if suffix in (".fits", ".fit", ".fts"):
        img = _read_fits(path)
    else:
        import cv2

        try:
            img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        except cv2.error as exc:
            msg = str(exc).strip().splitlines()[-1][:120] if str(exc).strip() else "OpenCV error"
            raise InputError(f"{path}: not a readable {suffix[1:].upper()} image ({msg})") from None
        if img is None:
            raise InputError(f"{path}: not a readable {suffix[1:].upper()} image")
        if img.ndim != 2:
            raise InputError(f"{path}: {img.shape[2]}-channel (colour) image; expected a single-channel grey {what}")
        if img.dtype not in _BITS or _BITS[img.dtype] not in allowed_bits:
            allowed = " or ".join(f"{b}-bit" for b in allowed_bits)
            raise InputError(f"{path}: pixel type {img.dtype}; expected an unsigned {allowed} {what}")
    if shape is not None and tuple(img.shape) != tuple(shape):
        raise InputError(f"{path}: {img.shape[1]}×{img.shape[0]} px (width×height); expected "
                         f"{shape[1]}×{shape[0]} px, the rig's detector")
    return img


def _png_params(cv2) -> list[int]:
    """Lossless PNG settings that encode a noisy frame fastest: Huffman coding only (LZ77 string
    matching finds little in sensor noise) after the Average row filter (the smallest output)."""
    params = [cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]
    if hasattr(cv2, "IMWRITE_PNG_FILTER"):  # OpenCV >= 4.10
        params += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_AVG]
    return params


def encode_image(dn: np.ndarray, suffix: str, header=None) -> bytes:
    """The bytes of ``dn`` (2-D uint8/uint16) as a PNG, TIFF or FITS file; ``header``: FITS cards
    ``[(keyword, value, comment), ...]`` (FITS only)."""
    img = np.ascontiguousarray(dn)
    if img.ndim != 2 or img.dtype not in _BITS:
        raise ValueError(f"frames are 2-D uint8/uint16 images; got shape {img.shape}, dtype {img.dtype}")
    suffix = suffix.lower()
    if suffix in (".fits", ".fit", ".fts"):
        from astropy.io import fits

        buf = io.BytesIO()
        hdu = fits.PrimaryHDU(img)
        for key, value, comment in header or ():
            hdu.header[key] = (value, comment)
        hdu.writeto(buf)
        return buf.getvalue()
    import cv2

    ok, enc = cv2.imencode(".tiff" if suffix == ".tif" else suffix, img, _png_params(cv2) if suffix == ".png" else [])
    if not ok:
        raise ValueError(f"OpenCV cannot encode a {suffix} image")
    return enc.tobytes()


def write_image(path, dn: np.ndarray, header=None) -> Path:
    """Write a frame as PNG, TIFF or FITS (by the suffix), atomically; ``header``: FITS cards (FITS only)."""
    path = Path(path)
    if path.suffix.lower() not in FRAME_SUFFIXES:
        raise InputError(f"{path}: unsupported frame file type {path.suffix!r}; expected one of {', '.join(FRAME_SUFFIXES)}")
    return atomic_write_bytes(path, encode_image(dn, path.suffix, header))
