"""What an image file says about itself before its pixels are decoded: width, height, channels, bits and
pages, from the PNG IHDR chunk, the TIFF image file directories, or the FITS headers. A file whose first
bytes are not those of its suffix's format is refused here, so the decoder (OpenCV reads many formats by
their content) only ever sees PNG and TIFF."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

from rigsim.errors import InputError

__all__ = ["ImageHeader", "read_header"]

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}  # colour type → samples per pixel (3: palette indices)
MAX_TIFF_PAGES = 10_000  # directories followed before a file counts as malformed


@dataclass(frozen=True)
class ImageHeader:
    width: int
    height: int
    channels: int = 1
    bits: int = 16
    pages: int = 1  # TIFF directories / FITS image extensions holding data


def _png(path: Path, head: bytes) -> ImageHeader:
    if len(head) < 33 or head[12:16] != b"IHDR":
        raise InputError(f"{path}: not a readable PNG image (no IHDR chunk after the signature)")
    w, h, bits, colour = struct.unpack(">IIBB", head[16:26])
    if w == 0 or h == 0 or colour not in PNG_CHANNELS:
        raise InputError(f"{path}: not a readable PNG image (IHDR says {w}×{h} px, colour type {colour})")
    return ImageHeader(w, h, PNG_CHANNELS[colour], bits)


_TIFF_TYPES = {1: ("B", 1), 3: ("H", 2), 4: ("I", 4), 16: ("Q", 8)}  # BYTE, SHORT, LONG, LONG8


def _tiff(path: Path) -> ImageHeader:
    data = path.read_bytes() if path.stat().st_size <= (1 << 26) else None
    with open(path, "rb") as fh:
        def read(off: int, n: int) -> bytes:
            if data is not None:
                return data[off:off + n]
            fh.seek(off)
            return fh.read(n)

        bo = {b"II": "<", b"MM": ">"}[read(0, 2)]
        magic = struct.unpack(bo + "H", read(2, 2))[0]
        big = magic == 43
        try:
            if big:
                off = struct.unpack(bo + "Q", read(8, 8))[0]
                cnt_fmt, ent_size, nxt_fmt = "Q", 20, "Q"
            else:
                off = struct.unpack(bo + "I", read(4, 4))[0]
                cnt_fmt, ent_size, nxt_fmt = "H", 12, "I"
            seen, first, pages = set(), None, 0
            while off and pages <= MAX_TIFF_PAGES:
                if off in seen:
                    break
                seen.add(off)
                n = struct.unpack(bo + cnt_fmt, read(off, struct.calcsize(cnt_fmt)))[0]
                base = off + struct.calcsize(cnt_fmt)
                if first is None:
                    tags = {}
                    for k in range(min(n, 4096)):
                        e = read(base + k * ent_size, ent_size)
                        tag, typ = struct.unpack(bo + "HH", e[:4])
                        count = struct.unpack(bo + ("Q" if big else "I"), e[4:12 if big else 8])[0]
                        field = e[12:20] if big else e[8:12]
                        if typ in _TIFF_TYPES and tag in (256, 257, 258, 277):
                            f, size = _TIFF_TYPES[typ]
                            raw = field[:size] if count * size <= len(field) else read(
                                struct.unpack(bo + ("Q" if big else "I"), field)[0], size)
                            tags[tag] = struct.unpack(bo + f, raw)[0]
                    first = tags
                pages += 1
                off = struct.unpack(bo + nxt_fmt, read(base + n * ent_size, struct.calcsize(nxt_fmt)))[0]
        except struct.error:
            raise InputError(f"{path}: not a readable TIFF image (its directory is cut short)") from None
    if not first or 256 not in first or 257 not in first:
        raise InputError(f"{path}: not a readable TIFF image (no image width and length in its first directory)")
    return ImageHeader(int(first[256]), int(first[257]), int(first.get(277, 1)), int(first.get(258, 1)), pages)


def _fits(path: Path) -> ImageHeader:
    import warnings

    from astropy.io import fits

    shapes = []
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with fits.open(path, memmap=False, lazy_load_hdus=True) as hdul:
                for hdu in hdul:
                    if not getattr(hdu, "is_image", False):
                        continue
                    shape = tuple(int(x) for x in hdu.shape)  # from the header (NAXISn, ZNAXISn): no data read
                    bits = abs(int(hdu.header.get("ZBITPIX", hdu.header.get("BITPIX", 16))))
                    if shape and all(s > 0 for s in shape):
                        shapes.append((shape, bits))
    except (OSError, TypeError, ValueError, KeyError, IndexError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{path}: not a readable FITS file ({str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__})") from None
    if not shapes:
        raise InputError(f"{path}: no image HDU with data; expected a 2-D image")
    shape, bits = shapes[0]
    if len(shape) != 2:
        raise InputError(f"{path}: FITS image of shape {shape} (NAXIS = {len(shape)}); expected a 2-D (rows, cols) image")
    return ImageHeader(shape[1], shape[0], 1, bits, len(shapes))


def read_header(path, suffix: str | None = None) -> ImageHeader:
    """The header of a PNG, TIFF or FITS file (by ``suffix``, default the file's); one line when the file's first
    bytes are not that format's."""
    path = Path(path)
    suffix = (suffix or path.suffix).lower()
    with open(path, "rb") as fh:
        head = fh.read(64)
    if suffix == ".png":
        if not head.startswith(PNG_SIGNATURE):
            raise InputError(f"{path}: not a readable PNG image (no PNG signature)")
        return _png(path, head)
    if suffix in (".tif", ".tiff"):
        if head[:4] not in (b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"):
            raise InputError(f"{path}: not a readable TIFF image (no TIFF signature)")
        return _tiff(path)
    if not head.startswith(b"SIMPLE  ="):
        raise InputError(f"{path}: not a readable FITS file (no SIMPLE card)")
    return _fits(path)
