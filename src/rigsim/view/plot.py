"""Put a :class:`~rigsim.view.scene.RigScene` on a ``pyvista.Plotter``; screenshots and exports.

Layout: the overview takes the top of the window; the other views (close-ups) share the bottom
row. Each viewport gets the items and labels tagged for it, a title, a scale bar in the plane
of the view (true millimetres) and, in the overview, the legend and the notes.
"""

from __future__ import annotations

import math
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from rigsim.errors import ViewError
from rigsim.files.atomic import atomic_write_bytes, output_folder
from rigsim.files.outputs import check_target
from rigsim.view.display import has_display, prepare_offscreen
from rigsim.view.scene import COLOURS, RigScene, ViewSpec

__all__ = ["make_plotter", "populate", "screenshot", "save_screenshot", "export_scene", "show", "EXPORT_SUFFIXES",
           "html_available"]

EXPORT_SUFFIXES = (".gltf", ".vtkjs", ".vtm", ".html")
BACKGROUND = ("#FFFFFF", "#E4EAF1")  # bottom, top


def _layout(n: int, size) -> dict:
    if n == 1:
        return {"shape": (1, 1)}
    if n == 2:
        return {"shape": (1, 2), "col_weights": [3, 2]}
    return {"shape": (2, n - 1), "groups": [(0, np.s_[:])], "row_weights": [3, 2]}


def _subplots(n: int) -> list[tuple[int, int]]:
    if n == 1:
        return [(0, 0)]
    if n == 2:
        return [(0, 0), (0, 1)]
    return [(0, 0)] + [(1, k) for k in range(n - 1)]


def make_plotter(scene: RigScene, *, off_screen: bool = True, size=(1200, 800), views: list[str] | None = None,
                 labels: bool = True):
    """A plotter showing ``views`` (default: all of the scene's, overview first)."""
    if off_screen:
        prepare_offscreen()
    import pyvista as pv

    specs = scene.views if views is None else [scene.view(v) for v in views]
    if not specs:
        raise ViewError("the scene has no views")
    theme = pv.themes.DocumentTheme()
    theme.font.color = COLOURS["text"]
    pl = pv.Plotter(off_screen=off_screen, window_size=[int(size[0]), int(size[1])], theme=theme,
                    border=True, border_color="#9AA5B1", border_width=1.0, **_layout(len(specs), size))
    for spec, (i, j) in zip(specs, _subplots(len(specs))):
        pl.subplot(i, j)
        populate(pl, scene, spec, labels=labels, overview=spec is specs[0])
    pl.subplot(0, 0)
    return pl


def _viewport_aspect(pl) -> float:
    vp = pl.renderer.GetViewport()  # (xmin, ymin, xmax, ymax) fractions
    w, h = pl.window_size
    return max((vp[2] - vp[0]) * w, 1.0) / max((vp[3] - vp[1]) * h, 1.0)


def _frame_axes(spec: ViewSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    back = spec.direction / np.linalg.norm(spec.direction)  # focus → eye
    up = spec.up - (spec.up @ back) * back
    up /= np.linalg.norm(up)
    right = np.cross(up, back)
    return right, up, back


def set_camera(pl, spec: ViewSpec, scene: RigScene | None = None) -> dict:
    """Aim the current renderer's camera; returns the visible half-width/height at the focus."""
    right, up, back = _frame_axes(spec)
    aspect = _viewport_aspect(pl)
    half = 0.5 * spec.extent_mm
    focus = np.asarray(spec.focus, float)
    if scene is not None and spec.name == scene.views[0].name:
        # fit the overview's bounding box as projected on the view plane
        pts = scene.points(spec.name)
        anchors = [lab.point for lab in scene.labels if lab.shown_in(spec.name)]
        if anchors:  # label anchors inside the frame too, with room above them for the text
            a = np.asarray(anchors, float)
            pts = np.vstack([pts, a, a + 0.04 * spec.extent_mm * up])
        pr = (pts - focus) @ np.column_stack([right, up])
        cmin, cmax = pr.min(0), pr.max(0)
        focus = focus + 0.5 * (cmin[0] + cmax[0]) * right + 0.5 * (cmin[1] + cmax[1]) * up
        hw, hh = 0.5 * (cmax[0] - cmin[0]), 0.5 * (cmax[1] - cmin[1])
        half_h = max(hh, hw / aspect) * 1.04
        if not spec.parallel:  # perspective: the eye distance at which every point is inside the frustum
            q = pts - focus
            t = math.tan(0.5 * math.radians(spec.view_angle_deg)) / 1.06  # 6 % margin
            dist = float(np.max(q @ back + np.maximum(np.abs(q @ up) / t, np.abs(q @ right) / (t * aspect))))
            half_h = dist * math.tan(0.5 * math.radians(spec.view_angle_deg))
    else:
        half_h = half * max(1.0, 1.0 / aspect)
    cam = pl.camera
    if spec.parallel:
        pl.enable_parallel_projection()
        dist = spec.eye_distance_mm if spec.eye_distance_mm else 10.0 * half_h + 100.0
        cam.parallel_scale = half_h
    else:
        va = math.radians(spec.view_angle_deg)
        cam.view_angle = spec.view_angle_deg
        dist = half_h / math.tan(0.5 * va)
    cam.focal_point = tuple(focus)
    cam.position = tuple(focus + dist * back)
    cam.up = tuple(up)
    pl.renderer.ResetCameraClippingRange()
    if spec.depth_mm:
        cam.clipping_range = (max(1e-3, dist - spec.depth_mm), dist + spec.depth_mm)
    return {"focus": focus, "half_h": half_h, "half_w": half_h * aspect, "right": right, "up": up, "back": back,
            "dist": dist}


def _scale_bar(pl, spec: ViewSpec, cam: dict) -> None:
    import pyvista as pv

    L = spec.scale_bar_mm
    if not L:
        return
    right, up = cam["right"], cam["up"]
    hw, hh = cam["half_w"], cam["half_h"]
    while L > 0.6 * hw and L > 1e-3:
        L /= 2.0
    # lower-right corner, in the plane through the focus (true length there)
    p0 = cam["focus"] + (hw * 0.85 - L) * right - hh * 0.86 * up
    p1 = p0 + L * right
    tick = 0.04 * hh * up
    pts = np.array([p0, p1, p0 - tick, p0 + tick, p1 - tick, p1 + tick])
    bar = pv.PolyData(pts, lines=np.array([2, 0, 1, 2, 2, 3, 2, 4, 5]))
    pl.add_mesh(bar, color="#202020", line_width=3, name=f"scale_bar:{spec.name}", lighting=False)
    txt = f"{L:g} mm" if L >= 1 else f"{L * 1000:g} \u00b5m"
    pl.add_point_labels([0.5 * (p0 + p1) + 0.07 * hh * up], [txt], font_size=12, show_points=False,
                        shape_opacity=0.0, always_visible=True, bold=False, text_color="#202020",
                        name=f"scale_bar_label:{spec.name}")


def populate(pl, scene: RigScene, spec: ViewSpec, *, labels: bool = True, overview: bool = False,
             all_items: bool = False) -> dict:
    """Add the items, labels, title (and for the overview: legend, notes) of one view to the
    current renderer, and aim its camera."""
    pl.set_background(BACKGROUND[0], top=BACKGROUND[1])
    for it in scene.items:
        if all_items or it.shown_in(spec.name):
            actor = pl.add_mesh(it.mesh, name=it.name, **it.style)
            if it.on_top:  # drawn over coincident geometry (a reflected ray on its incident ray)
                m = actor.GetMapper()
                m.SetResolveCoincidentTopologyToPolygonOffset()
                m.SetRelativeCoincidentTopologyLineOffsetParameters(0.0, -66000.0)
    if labels:
        for k, lab in enumerate(scene.labels):
            if lab.shown_in(spec.name):
                pl.add_point_labels([lab.point], [lab.text], font_size=lab.font_size, text_color=lab.colour,
                                    show_points=False, shape_color="#FFFFFF", shape_opacity=0.72, margin=2,
                                    always_visible=True, bold=False, name=f"label:{spec.name}:{k}")
    cam = set_camera(pl, spec, scene)
    if labels:
        _scale_bar(pl, spec, cam)
    w, h = pl.window_size
    fs_small = max(8, int(round(min(w, 1.6 * h) / 130)))
    if overview:
        pl.add_text(scene.title, position="upper_left", font_size=fs_small + 1, color=COLOURS["text"], name="title")
        lines = list(scene.notes) + [f"WARNING: {x}" for x in scene.warnings]
        lines.append(scene.frame + "; positions and angles true, housings schematic (docs/view.md)")
        pl.add_text("\n".join(lines), position="lower_left", font_size=fs_small, color="#303030", name="notes")
        entries = [(it.legend, it.style.get("color", "#000000")) for it in scene.items
                   if it.legend and (it.shown_in(spec.name) or all_items)]
        entries += scene.info.get("legend_extra", [])
        _legend(pl, entries, fs_small + 1)
    else:
        pl.add_text(spec.title, position="upper_left", font_size=fs_small, color=COLOURS["text"],
                    name=f"title:{spec.name}")
    return cam


def _legend(pl, entries, font_size: int) -> None:
    """Legend as coloured text lines in the upper-right corner (pyvista's legend box clips its text
    in subplot layouts)."""
    for k, (text, colour) in enumerate(entries):
        a = pl.add_text(text, position=(0.985, 0.90 - 0.05 * k), viewport=True, font_size=font_size, color=colour,
                        name=f"legend:{k}")
        a.SetTextScaleModeToNone()  # pyvista scales viewport-positioned text with the viewport
        a.GetTextProperty().SetFontSize(int(round(font_size * 1.35)))
        a.GetTextProperty().SetJustificationToRight()
        a.GetTextProperty().SetBackgroundColor(1.0, 1.0, 1.0)
        a.GetTextProperty().SetBackgroundOpacity(0.75)


# ------------------------------------------------------------------------------------------
# outputs
# ------------------------------------------------------------------------------------------

def screenshot(scene: RigScene, out_png, *, size=(1200, 800), views: list[str] | None = None) -> Path:
    """Render the scene off screen to a PNG (RGB)."""
    out = Path(out_png)
    if out.suffix.lower() != ".png":
        raise ViewError(f"--screenshot = {str(out_png)!r}: must be a .png file")
    check_target(out)
    output_folder(out.parent)
    pl = make_plotter(scene, off_screen=True, size=size, views=views)
    try:
        save_screenshot(pl, out)
    finally:
        pl.close()
    return out


def save_screenshot(pl, out: Path) -> None:
    """The plotter's picture as a PNG at ``out``: VTK writes it in a temporary folder, then one atomic write of its
    bytes (never through a link, never over a device node)."""
    with tempfile.TemporaryDirectory() as tmp:
        pl.screenshot(str(Path(tmp) / "shot.png"), return_img=False)
        atomic_write_bytes(out, (Path(tmp) / "shot.png").read_bytes())


def html_available() -> bool:
    """pyvista's HTML export needs the ``trame-pyvista`` package (and trame's vtk.js bundle)."""
    import importlib.util

    return importlib.util.find_spec("trame_pyvista") is not None


def _single(scene: RigScene, labels: bool = False):
    prepare_offscreen()
    import pyvista as pv

    pl = pv.Plotter(off_screen=True, window_size=[800, 600])
    populate(pl, scene, scene.views[0], labels=labels, overview=False, all_items=True)
    return pl


def export_scene(scene: RigScene, path) -> Path:
    """Write the scene to ``path``; the suffix picks the format:

    * ``.gltf`` — glTF 2.0 with the buffers inlined (one self-contained file; Blender, three.js
      viewers, Windows 3D Viewer), in metres, one node per item named after it; colours and opacity
      kept, labels not (they are 2D overlays);
    * ``.vtkjs`` — vtk.js scene archive (zip), opens in ParaView Glance / vtk.js OfflineLocalView;
    * ``.vtm``  — VTK multiblock of every item as its own named block (float64 points, e.g. for
      ParaView; no colours);
    * ``.html`` — pyvista's interactive HTML, only when ``trame-pyvista`` is installed (it is not a
      rigsim dependency).
    """
    out = Path(path)
    suf = out.suffix.lower()
    if suf not in EXPORT_SUFFIXES:
        raise ViewError(f"export file {str(path)!r}: allowed suffixes are {', '.join(EXPORT_SUFFIXES)}")
    check_target(out)
    output_folder(out.parent)
    if suf == ".vtm":
        import pyvista as pv

        mb = pv.MultiBlock()
        for it in scene.items:
            mb[it.name] = it.mesh
        mb.save(str(out))
        return out
    if suf == ".html" and not html_available():
        raise ViewError(
            "--html needs the Python package 'trame-pyvista' (pyvista 0.49 exports HTML through trame), which is not "
            "installed and not a rigsim dependency; use --export out.gltf (self-contained glTF 2.0) or "
            "--export out.vtkjs (vtk.js scene for ParaView Glance) instead, or pip install trame-pyvista")
    pl = _single(scene)
    try:
        if suf == ".gltf":
            with tempfile.TemporaryDirectory() as tmp:  # VTK writes the file itself: then one atomic write
                g = Path(tmp) / "scene.gltf"
                pl.export_gltf(str(g), inline_data=True, rotate_scene=False)
                gltf_in_metres(g, [it.name for it in scene.items], scene.rig_name)
                atomic_write_bytes(out, g.read_bytes())
        elif suf == ".vtkjs":
            import vtk

            with tempfile.TemporaryDirectory() as tmp:
                d = Path(tmp) / "scene"
                ex = vtk.vtkJSONSceneExporter()
                ex.SetRenderWindow(pl.render_window)
                ex.SetFileName(str(d))
                ex.Write()
                import io

                buf = io.BytesIO()
                with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
                    for f in sorted(d.rglob("*")):
                        if f.is_file():
                            z.write(f, Path("scene") / f.relative_to(d))
                atomic_write_bytes(out, buf.getvalue())
        else:  # .html with trame-pyvista present
            pl.trame.export_html(str(out))
            html_overlay(out, scene)
    finally:
        pl.close()
    return out


def html_overlay(path, scene: RigScene) -> None:
    """Title the vtk.js page with the rig (not "VTK.js | Example") and lay the PNG's title, notes and legend over
    the 3D view (vtk.js drops VTK's 2D text)."""
    import html as h
    import re

    from rigsim.files.atomic import atomic_write_text

    path = Path(path)
    text = path.read_text()
    entries = [(it.legend, it.style.get("color", "#000000")) for it in scene.items if it.legend]
    entries += scene.info.get("legend_extra", [])
    notes = list(scene.notes) + [f"WARNING: {x}" for x in scene.warnings]
    notes.append(scene.frame + "; positions and angles true, housings schematic")
    box = ("position:fixed;z-index:2147483647;background:rgba(255,255,255,0.82);padding:6px 9px;border-radius:4px;"
           "font:13px sans-serif;color:#202020;pointer-events:none;max-width:46vw")
    legend = "".join(f'<div><span style="display:inline-block;width:12px;height:12px;margin-right:6px;'
                     f'background:{h.escape(str(c))}"></span>{h.escape(str(t))}</div>' for t, c in entries)
    overlay = (f'<div id="rigsim-title" style="{box};top:8px;left:8px"><b>{h.escape(scene.title)}</b></div>'
               f'<div id="rigsim-legend" style="{box};top:8px;right:8px">{legend}</div>'
               f'<div id="rigsim-notes" style="{box};bottom:8px;left:8px">{"<br>".join(h.escape(n) for n in notes)}</div>')
    text = re.sub(r"<title>.*?</title>", f"<title>rigsim — {h.escape(scene.title)}</title>", text, count=1, flags=re.S)
    # the viewer empties <body> when it starts: the overlay is (re)added by a script once it has
    import json

    script = ("<script>(function(){var o=" + json.dumps(overlay).replace("</", "<\\/") + ";"
              "function ensure(){if(document.body&&!document.getElementById('rigsim-title'))"
              "document.body.insertAdjacentHTML('beforeend',o);}"
              "new MutationObserver(ensure).observe(document.documentElement,{childList:true,subtree:true});"
              "window.addEventListener('load',ensure);ensure();})();</script>")
    text = text.replace("</body>", script + "</body>", 1) if "</body>" in text else text + script
    atomic_write_text(path, text)


def gltf_in_metres(path, names: list[str], title: str) -> None:
    """Rewrite a glTF written by VTK (millimetres, meshes named mesh0…) in glTF's unit, metres: the meshes under
    one root node scaled by 1/1000 and named after the scene's items (turntable axes, cube faces, beams,
    cameras); the camera node's position converted to metres."""
    import json

    from rigsim.files.atomic import atomic_write_text

    path = Path(path)
    g = json.loads(path.read_text())
    nodes = g.get("nodes", [])
    mesh_nodes = [i for i, n in enumerate(nodes) if "mesh" in n]
    if len(mesh_nodes) == len(names):  # VTK writes the renderer's actors in the order they were added
        for i, name in zip(mesh_nodes, names):
            nodes[i]["name"] = name
            g["meshes"][nodes[i]["mesh"]]["name"] = name
    for n in nodes:
        if "camera" in n and "matrix" in n:
            n["matrix"] = [*n["matrix"][:12], *(x / 1000.0 for x in n["matrix"][12:15]), n["matrix"][15]]
    root = len(nodes)
    nodes.append({"name": f"{title} (metres)", "scale": [0.001, 0.001, 0.001], "children": mesh_nodes})
    for sc in g.get("scenes", []):
        sc["name"] = title
        sc["nodes"] = [root] + [i for i in range(root) if "camera" in nodes[i]]
    for i in range(root):  # the old root ("Renderer Node") is no longer in the scene: keep it empty
        if "children" in nodes[i] and i not in mesh_nodes:
            nodes[i]["children"] = []
    g.setdefault("asset", {})["generator"] = "rigsim (VTK glTF exporter, converted to metres)"
    atomic_write_text(path, json.dumps(g))


def show(scene: RigScene, *, size=(1400, 900)) -> None:
    """Open the interactive window (needs a display)."""
    if not has_display():
        raise ViewError("--window needs a display (neither DISPLAY nor WAYLAND_DISPLAY is set); "
                        "use --screenshot out.png or --export out.gltf on this machine")
    pl = make_plotter(scene, off_screen=False, size=size)
    pl.show(title=f"rigsim view: {scene.rig_name}")
