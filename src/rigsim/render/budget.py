"""What a render will need, known before it starts: memory per rendering process and disk per frame.
Measured figures and the model's derivation are in docs/reliability.md ("Work bounded up front")."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from rigsim.errors import ResourceError
from rigsim.files.memory import HEADROOM, available_bytes
from rigsim.files.memory import human_bytes as _gb

BASE_BYTES = 350e6      # an interpreter with Mitsuba and the rig loaded, film and detector buffers aside
BYTES_PER_PIXEL = 115   # film, photon, noise and fixed-pattern buffers (float64) and the 16-bit frame
DISK_BYTES_PER_PIXEL = 2.0  # a 16-bit image stored uncompressed (PNG and FITS are at most this, plus headers)
SIDECAR_BYTES = 16_384


def process_bytes(pixels: int) -> float:
    """Peak resident memory of one process rendering frames of ``pixels`` detector pixels."""
    return BASE_BYTES + BYTES_PER_PIXEL * int(pixels)


def fit_processes(requested: int, pixels: int, what: str) -> int:
    """How many processes of ``pixels``-pixel frames fit in the available memory (at most ``requested``).
    Refuses, naming ``what``, when not even one does."""
    avail = available_bytes()
    per = process_bytes(pixels)
    if avail is None:
        return requested
    fit = int(HEADROOM * avail // per)
    if fit < 1:
        raise ResourceError(f"{what}: a frame of {pixels / 1e6:.1f} Mpx needs about {_gb(per)} of memory to render; "
                            f"this machine has {_gb(avail)} available")
    return max(1, min(int(requested), fit))


def check_memory(resolution_px, field: str) -> None:
    """Refuse a detector of ``resolution_px`` (width, height) whose frames cannot be rendered in the available
    memory, naming the rig ``field``: before any render starts, rather than an out-of-memory kill."""
    w, h = (int(x) for x in resolution_px)
    fit_processes(1, w * h, f"{field} = [{w}, {h}]")


def check_disk(folder, n_frames: int, pixels: int, what: str) -> float:
    """Refuse, naming ``what``, ``n_frames`` frames of ``pixels`` pixels that cannot fit on ``folder``'s disk.
    Returns the estimate in bytes (an upper bound: frames stored uncompressed)."""
    need = int(n_frames) * (DISK_BYTES_PER_PIXEL * int(pixels) + SIDECAR_BYTES)
    probe = Path(folder)
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    try:
        free = shutil.disk_usage(probe).free
    except OSError:
        return need
    if need > free:
        raise ResourceError(f"{what}: {n_frames} frames of {pixels / 1e6:.1f} Mpx need up to {_gb(need)}; "
                            f"{probe} has {_gb(free)} free (fewer frames, or another --out)")
    return need


def cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1
