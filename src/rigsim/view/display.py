"""Display detection and off-screen set-up for VTK.

Measured on these machines (docs/view.md): no X server, Mesa's EGL (llvmpipe, software) works
through ``vtkEGLRenderWindow``; OSMesa is not installed. VTK 9.7 falls back to EGL by itself
after failing to open X (with a warning); an *empty* ``VTK_DEFAULT_OPENGL_WINDOW`` makes it fail.
:func:`prepare_offscreen` therefore selects EGL explicitly when there is no display, before the
first render window exists.
"""

from __future__ import annotations

import os
import sys

__all__ = ["has_display", "prepare_offscreen", "render_window_class"]

EGL_WINDOW = "vtkEGLRenderWindow"


def has_display() -> bool:
    """True when an interactive window can be opened (X11/Wayland display, or macOS/Windows)."""
    if sys.platform in ("win32", "darwin"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def prepare_offscreen() -> None:
    """Choose EGL for off-screen rendering when no display exists (idempotent; call before the
    first ``pyvista.Plotter``). A user's own non-empty ``VTK_DEFAULT_OPENGL_WINDOW`` is kept."""
    if not has_display() and not os.environ.get("VTK_DEFAULT_OPENGL_WINDOW"):
        os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = EGL_WINDOW


def render_window_class(plotter) -> str:
    """The VTK render-window class a plotter ended up with (e.g. ``vtkEGLRenderWindow``)."""
    try:
        return plotter.render_window.GetClassName()
    except Exception:  # noqa: BLE001 - closed plotter
        return "unknown"
