"""The glTF export is in metres (glTF's unit: Blender and three.js take it at its size) with one node per scene
item, named after it: every named node's vertices are that item's mesh (checked against the scene), and trimesh
reads the whole scene 1000× smaller than the millimetre scene."""

import json

import numpy as np
import pytest

from rigsim.view.plot import export_scene
from rigsim.view.api import build_scene


@pytest.mark.parametrize("rig", ["sun_sensor_2axis_diaphragm", "sun_sensor_3axis_autocollimator"])
def test_gltf_is_in_metres_with_named_nodes(tmp_path, rig):
    import trimesh

    scene = build_scene(rig)
    out = export_scene(scene, tmp_path / "rig.gltf")
    g = json.loads(out.read_text())
    names = {n.get("name"): n for n in g["nodes"]}
    items = {it.name: it for it in scene.items}
    assert set(items) <= set(names)
    for name, it in items.items():  # each node holds its item's vertices (millimetres, under the 1/1000 root)
        acc = g["accessors"][g["meshes"][names[name]["mesh"]]["primitives"][0]["attributes"]["POSITION"]]
        b = np.asarray(it.mesh.bounds).reshape(3, 2).T
        tol = 1e-3 * (1 + float(np.abs(b).max()))  # float32 positions
        np.testing.assert_allclose(acc["min"], b[0], atol=tol, err_msg=name)
        np.testing.assert_allclose(acc["max"], b[1], atol=tol, err_msg=name)
    root = next(n for n in g["nodes"] if n.get("scale") == [0.001, 0.001, 0.001])
    assert root["name"] == f"{scene.rig_name} (metres)"
    tm = trimesh.load(out, force="scene")
    lo = np.min([np.asarray(it.mesh.bounds).reshape(3, 2)[:, 0] for it in scene.items], axis=0)
    hi = np.max([np.asarray(it.mesh.bounds).reshape(3, 2)[:, 1] for it in scene.items], axis=0)
    np.testing.assert_allclose(tm.bounds, np.stack([lo, hi]) / 1000.0, rtol=1e-3, atol=1e-4)
