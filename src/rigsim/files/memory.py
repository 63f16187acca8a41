"""The memory a command may use, and the frames it may therefore read: checked from an image's header
before its pixels are decoded (docs/reliability.md, "Work bounded up front")."""

from __future__ import annotations

import os
from pathlib import Path

from rigsim.errors import InputError, ResourceError

__all__ = ["FRAME_BYTES_PER_PIXEL", "HEADROOM", "MAX_FRAME_PIXELS", "MEMORY_ENV", "available_bytes", "check_frame_pixels",
           "check_frames_kept", "human_bytes"]

MEMORY_ENV = "RIGSIM_MEMORY_GB"
"""Environment variable: the memory (GB) rigsim may assume it has, instead of the machine's available memory
(a shared machine's fair share, or a batch job's limit)."""
HEADROOM = 0.85
"""Of the available memory: the rest is left to the system and the caller."""
FRAME_BYTES_PER_PIXEL = 64
"""Peak memory per pixel of reading and measuring one frame: ``rigsim centroid`` measured 43 bytes per pixel on
16-bit frames of 4096² and 8192² px (the decoded frame, its float64 copy, the background map, the threshold masks
and labels); 64 leaves a margin for the other measurements."""
MAX_FRAME_PIXELS = 2**30
"""Largest frame read (32768² px): OpenCV's own decoding limit (``CV_IO_MAX_IMAGE_PIXELS``), applied to FITS too."""


def human_bytes(x: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if abs(x) >= scale:
            return f"{x / scale:.3g} {unit}"
    return f"{x / 1e3:.3g} kB"


def _env_bytes() -> float | None:
    text = os.environ.get(MEMORY_ENV)
    if text is None or not text.strip():
        return None
    import re

    if not re.fullmatch(r"[0-9]+(\.[0-9]+)?", text.strip()) or not 0 < float(text) <= 1e6:
        raise ResourceError(f"{MEMORY_ENV} = {text!r}: expected the memory in GB, a number above 0 and at most 1000000")
    return float(text) * 1e9


def available_bytes() -> float | None:
    """Memory this process may still use: ``RIGSIM_MEMORY_GB`` when set, else MemAvailable, or less under a
    cgroup (container) limit; None when unknown."""
    env = _env_bytes()
    if env is not None:
        return env
    avail = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = float(line.split()[1]) * 1024
    except OSError:
        return None
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit != "max":
            used = float(Path("/sys/fs/cgroup/memory.current").read_text())
            avail = min(avail, float(limit) - used) if avail is not None else float(limit) - used
    except (OSError, ValueError):
        pass
    return avail


def _budget_note() -> str:
    return f"{int(HEADROOM * 100)} % of it is used; {MEMORY_ENV} sets the memory rigsim may assume"


def check_frame_pixels(path, width: int, height: int, channels: int = 1, *, what: str = "frame") -> None:
    """Refuse (one line naming the file) a frame whose header announces more pixels than rigsim reads, or more
    than the memory holds while it is measured (:data:`FRAME_BYTES_PER_PIXEL`)."""
    n = int(width) * int(height)
    size = f"{width}×{height} px"
    if n * max(int(channels), 1) > MAX_FRAME_PIXELS:
        raise InputError(f"{path}: its header announces a {size} {what} ({n / 1e6:.0f} Mpx"
                         + (f" × {channels} channels" if channels > 1 else "")
                         + f"); rigsim reads frames of at most {MAX_FRAME_PIXELS / 1e6:.0f} Mpx (32768² px)")
    avail = available_bytes()
    need = FRAME_BYTES_PER_PIXEL * n * max(int(channels), 1)
    if avail is not None and need > HEADROOM * avail:
        raise InputError(f"{path}: its header announces a {size} {what} ({n / 1e6:.0f} Mpx), which needs about "
                         f"{human_bytes(need)} of memory to read and measure; {human_bytes(avail)} is available "
                         f"({_budget_note()})")


def check_frames_kept(n_frames: int, width: int, height: int, bytes_per_pixel: float, *, what: str) -> None:
    """Refuse a sequence of ``n_frames`` frames a command keeps in memory together (plus one being measured) when
    they do not fit: before the first is decoded."""
    avail = available_bytes()
    px = int(width) * int(height)
    need = int(n_frames) * px * float(bytes_per_pixel) + FRAME_BYTES_PER_PIXEL * px
    if avail is not None and need > HEADROOM * avail:
        raise InputError(f"{what}: {n_frames} frames of {width}×{height} px kept in memory together need about "
                         f"{human_bytes(need)}; {human_bytes(avail)} is available ({_budget_note()}): give fewer frames")
