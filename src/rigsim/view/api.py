"""Public entry points of rigsim.view and the per-family builder registry (the extension point).

A rig family plugs in with :func:`register_view_builder` (rig class path → builder path, both
``"module:attr"`` strings, imported lazily). A builder is called as
``builder(rig, pose=..., face=..., **options) -> RigScene``; families without a turntable
reject ``pose``/``face`` with a :class:`~rigsim.view.scene.ViewError`.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from rigsim.errors import ViewError
from rigsim.view.scene import RigScene

__all__ = ["register_view_builder", "builder_for", "load_view_rig", "build_scene", "rig_picture", "export_scene",
           "show_scene", "VIEW_BUILDERS", "parse_size"]

VIEW_BUILDERS: dict[str, str] = {}
"""rig class ("module:Class") → scene builder ("module:function")."""

# Fallback loaders, by seed_document, for when rigsim.rig.load.load_any_rig cannot load a family
# that has a view builder (e.g. its RIG_FAMILIES entry points at a parser that moved).
FALLBACK_LOADERS: dict[str, str] = {"003": "rigsim.rig.load:load_boresight_rig"}


def register_view_builder(rig_class: str, builder: str) -> None:
    VIEW_BUILDERS[rig_class] = builder


register_view_builder("rigsim.rig.cube_mirror:CubeMirrorRig", "rigsim.view.cube_mirror:build_cube_rig_scene")
register_view_builder("rigsim.rig.star:StarRig", "rigsim.view.star:build_star_scene")
register_view_builder("rigsim.rig.boresight:BoresightRig", "rigsim.view.boresight:build_boresight_scene")


def _resolve(path: str):
    mod, attr = path.split(":")
    return getattr(importlib.import_module(mod), attr)


def builder_for(rig):
    for cls_path, b in VIEW_BUILDERS.items():
        try:
            cls = _resolve(cls_path)
        except (ImportError, AttributeError):
            continue
        if isinstance(rig, cls):
            return _resolve(b)
    raise ViewError(f"no 3D view for a rig of type {type(rig).__name__} "
                    f"(rigsim.view knows {sorted(c.split(':')[1] for c in VIEW_BUILDERS)})")


def load_view_rig(rig_or_path):
    """A rig object as is, or load a path / default rig name (any family)."""
    if not isinstance(rig_or_path, (str, Path)):
        return rig_or_path
    import tomllib

    from rigsim.errors import RigError
    from rigsim.rig.load import load_any_rig, resolve_rig_path

    try:
        return load_any_rig(rig_or_path)
    except RigError as exc:
        if "has no loader" not in str(exc):
            raise
        path = resolve_rig_path(rig_or_path)
        sd = str(tomllib.loads(path.read_text("utf-8")).get("seed_document", ""))
        if sd not in FALLBACK_LOADERS:
            raise
        try:
            loader = _resolve(FALLBACK_LOADERS[sd])
        except (ImportError, AttributeError):
            raise exc from None
        return loader(path)


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
            w, h = (int(p) for p in parts)
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
