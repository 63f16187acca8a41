"""Meshes for the rig scenes, built with trimesh and written as binary PLY.

Flat mirrors need per-face normals: RENDERING-NOTES.md measured that interpolated vertex
normals break the reflection, so every mesh here has split vertices per face (flat shading)
and the scene entries set ``face_normals = True``.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import trimesh

from rigsim.files.atomic import output_folder
from rigsim.optics.meshes import cube_mesh

DEFAULT_MESH_DIR = Path.home() / ".cache" / "rigsim" / "meshes"


def _write(mesh: trimesh.Trimesh, name: str, out_dir: Path | None) -> Path:
    out_dir = Path(out_dir) if out_dir is not None else DEFAULT_MESH_DIR
    output_folder(out_dir)
    data = mesh.export(file_type="ply", encoding="binary")
    digest = hashlib.sha1(data).hexdigest()[:12]
    path = out_dir / f"{name}-{digest}.ply"
    if not path.is_file() or path.is_symlink():
        from rigsim.files.atomic import atomic_write_bytes

        atomic_write_bytes(path, data)
    return path


def cube_ply(edge_mm: float, out_dir: Path | None = None) -> Path:
    return _write(cube_mesh(edge_mm), f"cube_{edge_mm:g}mm", out_dir)


def mesh_ply(mesh: trimesh.Trimesh, name: str, out_dir: Path | None = None) -> Path:
    """Write any trimesh mesh (content-addressed file name, so repeated builds reuse it)."""
    return _write(mesh, name, out_dir)

