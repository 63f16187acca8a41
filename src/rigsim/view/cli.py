"""``rigsim view RIG``: the 3D view of a rig (registered by rigsim.cli through add_cli)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from rigsim.errors import CliError
from rigsim.files.atomic import output_folder

__all__ = ["add_cli", "cmd_view", "parse_pose_arg"]

EPILOG = """\
examples:
  rigsim view sun_sensor_2axis_diaphragm --screenshot renders/rig.png       off screen (EGL without a display)
  rigsim view sun_sensor_2axis_diaphragm --pose null --face +Y --screenshot y.png
  rigsim view sun_sensor_2axis_diaphragm --pose X=181.398,Y=0.528 --window    interactive (needs a display)
  rigsim view sun_sensor_3axis_autocollimator --export rig.gltf             glTF 2.0 (also .vtkjs, .vtm)
  rigsim view star_sensor --screenshot star.png

--pose: true turntable angles in degrees; axes not named keep the start pose. Keywords: start (default:
the face's search_start_deg), null (the face's exact null), nominal (nominal_poses_deg). docs/view.md.
"""


def parse_pose_arg(text: str | None):
    """'X=10,Y=-5' → {'X': '10', 'Y': '-5'} (values checked by the builder); keywords pass through."""
    if text is None:
        return None
    t = text.strip()
    if "=" not in t:
        return t
    pose = {}
    for part in t.split(","):
        if "=" not in part:
            raise CliError(f"--pose = {text!r}: expected LABEL=DEGREES[,LABEL=DEGREES] (e.g. X=181.4,Y=0.55) "
                                "or one of start, null, nominal")
        k, v = (x.strip() for x in part.split("=", 1))
        if k in pose:
            raise CliError(f"--pose = {text!r}: axis {k!r} given twice")
        pose[k] = v
    return pose


def add_cli(groups: dict) -> None:
    """Add the command to the parser groups {"top", "run", "render"} of ``rigsim``."""
    top = groups["top"]
    p = top.add_parser("view", help="3D view of a rig: turntable, sensor, cube, screen/autocollimator, traced beams",
                       description="Show a rig in 3D (pyvista), built from the same rig file as the renderer; beam "
                                   "paths from the analytic trace at the chosen pose. Without --screenshot/--export/"
                                   "--html it opens a window (needs a display).",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("rig", metavar="RIG", help="rig file path or default rig name (rigsim rig list)")
    p.add_argument("--pose", default=None, help="cube rigs: start | null | nominal | LABEL=DEG[,LABEL=DEG] (true angles)")
    p.add_argument("--face", default=None, help="cube rigs: the measured face the instrument is set up for "
                                                "(e.g. +Z, +Y, --face=-Z; default the first of procedure.faces)")
    p.add_argument("--screenshot", default=None, metavar="PNG", help="render off screen to this PNG")
    p.add_argument("--html", default=None, metavar="HTML", help="interactive HTML export (needs trame-pyvista)")
    p.add_argument("--export", default=None, metavar="FILE", help="3D export: .gltf, .vtkjs or .vtm")
    p.add_argument("--size", default="1200x800", metavar="WxH", help="picture / window size in pixels")
    p.add_argument("--window", action="store_true", help="open the interactive window (needs a display)")
    p.set_defaults(func=cmd_view)
    from rigsim.files.outputs import declare

    declare(p, "screenshot", suffixes=(".png",))
    declare(p, "html", suffixes=(".html",))
    declare(p, "export", suffixes=(".gltf", ".vtkjs", ".vtm"))


def _check_outputs(args) -> None:
    from rigsim.errors import ViewError
    from rigsim.view.plot import html_available

    if args.screenshot is not None and Path(args.screenshot).suffix.lower() != ".png":
        raise ViewError(f"--screenshot = {args.screenshot!r}: must end in .png")
    if args.export is not None and Path(args.export).suffix.lower() not in (".gltf", ".vtkjs", ".vtm"):
        raise ViewError(f"--export = {args.export!r}: allowed suffixes are .gltf, .vtkjs, .vtm")
    if args.html is not None:
        if Path(args.html).suffix.lower() != ".html":
            raise ViewError(f"--html = {args.html!r}: must end in .html")
        if not html_available():
            raise ViewError(
                "--html: not available here: pyvista 0.49 writes HTML through the 'trame-pyvista' package, which is "
                "not installed (and not a rigsim dependency). Offline alternatives: --export FILE.gltf "
                "(self-contained glTF 2.0: Blender, three.js viewers) or --export FILE.vtkjs (ParaView Glance)")
    from rigsim.view.display import has_display

    wants_window = args.window or not (args.screenshot or args.export or args.html)
    if wants_window and not has_display():
        why = "--window" if args.window else "without --screenshot/--export/--html, rigsim view opens a window; it"
        raise ViewError(f"{why} needs a display (DISPLAY/WAYLAND_DISPLAY not set); use --screenshot out.png "
                        "(off screen) or --export out.gltf")
    args._wants_window = wants_window


def cmd_view(args) -> int:
    from rigsim.view.api import build_scene, parse_size

    size = parse_size(args.size)
    pose = parse_pose_arg(args.pose)
    _check_outputs(args)
    t0 = time.perf_counter()
    scene = build_scene(args.rig, pose=pose, face=args.face)
    print(scene.title)
    for line in scene.notes:
        print(f"  {line}")
    for w in scene.warnings:
        print(f"  WARNING: {w}")
    if args.screenshot:
        from rigsim.view.display import render_window_class
        from rigsim.view.plot import make_plotter

        from rigsim.view.plot import save_screenshot

        out = Path(args.screenshot)
        output_folder(out.parent)
        pl = make_plotter(scene, off_screen=True, size=size)
        try:
            save_screenshot(pl, out)
            rw = render_window_class(pl)
        finally:
            pl.close()
        print(f"wrote {out} ({size[0]}x{size[1]}, off screen via {rw}, {time.perf_counter() - t0:.1f} s)")
    for path in (args.export, args.html):
        if path:
            from rigsim.view.plot import export_scene

            print(f"wrote {export_scene(scene, path)}")
    if args._wants_window:
        from rigsim.view.plot import show

        show(scene, size=size)
    return 0
