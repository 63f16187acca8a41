"""Public entry points of rigsim.view: build, picture, export or show the 3D scene of any rig.

Each rig family has a scene builder in this package (``view/cube_mirror.py``, ``view/boresight.py``,
``view/star.py``) called as ``builder(rig, pose=..., face=..., **options) -> RigScene``; families
without a turntable reject ``pose``/``face`` with a :class:`~rigsim.errors.ViewError`.
"""

from __future__ import annotations

from pathlib import Path

from rigsim.errors import ViewError
from rigsim.rig.boresight import BoresightRig
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.star import StarRig
from rigsim.view.scene import RigScene

__all__ = ["builder_for", "load_view_rig", "build_scene", "rig_picture", "export_scene", "show_scene",
           "parse_size"]


def builder_for(rig):
    """The scene builder of ``rig``'s family (imported on first use: pyvista is slow to import)."""
    if isinstance(rig, CubeMirrorRig):
        from rigsim.view.cube_mirror import build_cube_rig_scene

        return build_cube_rig_scene
    if isinstance(rig, BoresightRig):
        from rigsim.view.boresight import build_boresight_scene

        return build_boresight_scene
    if isinstance(rig, StarRig):
        from rigsim.view.star import build_star_scene

        return build_star_scene
    raise ViewError(f"no 3D view for a rig of type {type(rig).__name__} "
                    "(rigsim.view knows CubeMirrorRig, BoresightRig and StarRig)")


def load_view_rig(rig_or_path):
    """A rig object as is, or load a path / default rig name (any family)."""
    if not isinstance(rig_or_path, (str, Path)):
        return rig_or_path
    from rigsim.rig.load import load_any_rig

    return load_any_rig(rig_or_path)


def build_scene(rig_or_path, *, pose=None, face=None, **options) -> RigScene:
    """The :class:`RigScene` of any supported rig (path, default-rig name or rig object).

    ``pose``: cube rigs only — None/"start", "null", "nominal" or {axis label: true degrees}.
    ``face``: cube rigs only — the measured face the instrument is set up for.
    """
    rig = load_view_rig(rig_or_path)
    return builder_for(rig)(rig, pose=pose, face=face, **options)


def parse_size(size) -> tuple[int, int]:
    """(w, h) or "WxH" → two ints in 64..8192."""
    if isinstance(size, str):
        parts = size.lower().replace("\u00d7", "x").split("x")
        try:
            from rigsim.files.numbers import parse_int

            w, h = (parse_int(p) for p in parts)
        except ValueError:
            raise ViewError(f"--size = {size!r}: expected WIDTHxHEIGHT in pixels, e.g. 1200x800") from None
    else:
        try:
            w, h = (int(v) for v in size)
        except (TypeError, ValueError):
            raise ViewError(f"size = {size!r}: expected (width, height) in pixels") from None
    for nm, v in (("width", w), ("height", h)):
        if not 64 <= v <= 8192:
            raise ViewError(f"--size {nm} = {v}: allowed range is 64 to 8192 pixels")
    return w, h


def rig_picture(rig_or_path, out_png, *, pose_deg=None, size=(1200, 800), face=None, views=None) -> Path:
    """Render a rig picture off screen (EGL when there is no display) and return its path.

    ``rig_or_path``: a rig object (any supported family) or a path / default rig name;
    ``pose_deg``: cube rigs — {axis label: true degrees} (other axes keep the start pose) or
    "start" / "null" / "nominal"; ``size``: (width, height) px; ``face``: cube rigs — which
    measured face the instrument is set up for; ``views``: subset of the scene's view names.
    """
    from rigsim.view.plot import screenshot

    scene = build_scene(rig_or_path, pose=pose_deg, face=face)
    return screenshot(scene, out_png, size=parse_size(size), views=views)


def export_scene(scene_or_rig, path, *, pose=None, face=None) -> Path:
    from rigsim.view.plot import export_scene as _export

    scene = scene_or_rig if isinstance(scene_or_rig, RigScene) else build_scene(scene_or_rig, pose=pose, face=face)
    return _export(scene, path)


def show_scene(scene_or_rig, *, pose=None, face=None, size=(1400, 900)) -> None:
    from rigsim.view.plot import show

    scene = scene_or_rig if isinstance(scene_or_rig, RigScene) else build_scene(scene_or_rig, pose=pose, face=face)
    show(scene, size=parse_size(size))
