"""3D views of the rigs (pyvista): the same rig description as the renderer and the truth.

``build_scene(rig, pose=..., face=...)`` → :class:`RigScene` (meshes, labels, traced beams,
viewpoints); ``rig_picture(rig_or_path, out_png)`` renders it off screen; ``rigsim view RIG``
is the command (docs/view.md).
"""

from rigsim.errors import ViewError
from rigsim.view.api import build_scene, export_scene, load_view_rig, rig_picture, show_scene
from rigsim.view.scene import Beam, Item, Label, RigScene, ViewSpec

__all__ = ["build_scene", "rig_picture", "export_scene", "show_scene", "load_view_rig", "RigScene", "Item", "Label",
           "Beam", "ViewSpec", "ViewError"]
