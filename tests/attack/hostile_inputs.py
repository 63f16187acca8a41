"""Hostile files for the attack suite and the tests: images whose header lies or claims too much (PNG, TIFF,
FITS), multi-page TIFFs, FITS pixels of 1e300, deeply nested or huge-number JSON/YAML/XML, OpenCV matrices
that claim 10⁶×10⁶, and tables with non-ASCII digits. Each writer is cheap (a few kB on disk)."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_header_bomb(path, width: int = 65535, height: int = 65535) -> Path:
    """A PNG whose IHDR claims ``width``×``height`` 16-bit grey pixels, with one short IDAT (~0.6 kB)."""
    ihdr = struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, 0)
    body = zlib.compress(b"\0" * 4096, 9)
    Path(path).write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", body) + _chunk(b"IEND", b""))
    return Path(path)


def png_zero_bomb(path, side: int = 16000) -> Path:
    """A valid ``side``² 16-bit grey PNG of zeros: a few hundred kB that decode to 2·side² bytes."""
    comp = zlib.compressobj(9)
    row = b"\0" * (1 + 2 * side)
    parts = [comp.compress(row) for _ in range(side)] + [comp.flush()]
    ihdr = struct.pack(">IIBBBBB", side, side, 16, 0, 0, 0, 0)
    Path(path).write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", b"".join(parts))
                           + _chunk(b"IEND", b""))
    return Path(path)


def tiff_pages(path, pages: int = 2, shape=(64, 64)) -> Path:
    """A multi-page 16-bit TIFF (each page a different constant)."""
    import cv2

    imgs = [np.full(shape, 1000 * (k + 1), np.uint16) for k in range(pages)]
    ok = cv2.imwritemulti(str(path), imgs)
    assert ok
    return Path(path)


def tiff_header_bomb(path, width: int = 100000, height: int = 100000) -> Path:
    """A little-endian TIFF whose only directory claims ``width``×``height`` 16-bit pixels, with no strip data."""
    entries = [(256, 4, 1, width), (257, 4, 1, height), (258, 3, 1, 16), (259, 3, 1, 1), (262, 3, 1, 1),
               (273, 4, 1, 8), (277, 3, 1, 1), (278, 4, 1, height), (279, 4, 1, 2 * width * height & 0xFFFFFFFF)]
    ifd = struct.pack("<H", len(entries))
    for tag, typ, count, value in entries:
        ifd += struct.pack("<HHI", tag, typ, count) + (struct.pack("<HH", value, 0) if typ == 3 else struct.pack("<I", value))
    ifd += struct.pack("<I", 0)
    Path(path).write_bytes(b"II*\0" + struct.pack("<I", 16) + b"\0" * 8 + ifd)
    return Path(path)


def _fits_cards(cards: list[str]) -> bytes:
    text = "".join(c.ljust(80) for c in [*cards, "END"])
    return text.ljust(((len(text) + 2879) // 2880) * 2880).encode("ascii")


def fits_header_bomb(path, side: int = 100000) -> Path:
    """A FITS header claiming ``side``² 16-bit pixels, followed by one block of data."""
    head = _fits_cards(["SIMPLE  =                    T", "BITPIX  =                   16", "NAXIS   =                    2",
                        f"NAXIS1  = {side:20d}", f"NAXIS2  = {side:20d}"])
    Path(path).write_bytes(head + b"\0" * 2880)
    return Path(path)


def fits_huge_values(path, shape=(1024, 1024), value: float = 1e300) -> Path:
    """A float64 FITS frame of a plausible background with one pixel of ``value``."""
    from astropy.io import fits

    a = np.full(shape, 100.0)
    a[shape[0] // 2, shape[1] // 2] = value
    fits.PrimaryHDU(a).writeto(path, overwrite=True)
    return Path(path)


def deep_json(path, depth: int = 100_000) -> Path:
    Path(path).write_text("[" * depth + "]" * depth)
    return Path(path)


def long_integer_json(path, digits: int = 100_001, key: str = "R_cube_from_rot") -> Path:
    Path(path).write_text('{"%s": %s}' % (key, "9" * digits))
    return Path(path)


def deep_yaml(path, depth: int = 100_000) -> Path:
    Path(path).write_text("%YAML:1.0\nK: " + "[" * depth + "]" * depth + "\n")
    return Path(path)


def deep_xml(path, depth: int = 100_000) -> Path:
    Path(path).write_text('<?xml version="1.0"?>\n<opencv_storage>' + "<a>" * depth + "</a>" * depth + "</opencv_storage>\n")
    return Path(path)


def opencv_matrix_bomb(path, n: int = 1_000_000) -> Path:
    """An OpenCV FileStorage YAML whose camera_matrix claims n×n doubles (8 TB for 10⁶) with nine values."""
    Path(path).write_text("%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n"
                          f"   rows: {n}\n   cols: {n}\n   dt: d\n   data: [ 1000., 0., 512., 0., 1000., 512., 0., 0., 1. ]\n"
                          "image_width: 1024\nimage_height: 1024\n")
    return Path(path)
