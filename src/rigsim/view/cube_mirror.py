"""3D scene of the turntable + mirror-cube rigs (seeds 000 and 001) at one turntable pose.

Everything is placed by the code that places it for the renderer and the truth:

* turntable: :class:`rigsim.rig.turntable.TurntableModel` (true axes, misalignments included);
* cube, its true face normals: :func:`rigsim.truth.cube_mirror.placement.cube_pose`,
  :func:`~rigsim.truth.cube_mirror.placement.face_in_rot`, the renderer's own mesh
  (:func:`rigsim.render.cube_mirror.diaphragm.true_cube_mesh`, measured faces turned to their true
  normals);
* seed 000: screen, hole and aiming camera from
  :func:`rigsim.render.cube_mirror.diaphragm.diaphragm_geometry` (``diaphragm_layout`` inside), the
  beam through the hole from :func:`rigsim.truth.cube_mirror.placement.trace_return_spot`;
* seed 001: autocollimator from :func:`rigsim.optics.autocollimator.autocollimator_layout`, the
  target from :func:`~rigsim.optics.autocollimator.mirror_target`, the central ray through the
  singlet from :class:`~rigsim.optics.autocollimator.AutocollimatorOptics`' exact trace.

Not in the rig file, so drawn schematically (docs/view.md): the sun sensor's body (a box on the
inner frame, centred above the cube, its boresight and frame axes true), camera and
autocollimator housings, turntable rings (radii chosen for legibility; the axis directions and
angles are true), the simulator housing.

Poses are TRUE turntable angles in degrees (``{"X": 181.4, "Y": 0.55}``), as for
``rigsim render sun-sensor --pose``.
"""

from __future__ import annotations

import math

import numpy as np

from rigsim.files.numbers import parse_float
from rigsim.errors import GeometryError, ViewError
from rigsim.frames import ARCSEC_PER_RAD
from rigsim.optics.cube import DOCUMENT_FACE_NAMES, FACE_NORMALS, reflect
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.truth.cube_mirror.placement import cube_pose, face_in_rot, plane_hit, trace_return_spot
from rigsim.truth.cube_mirror.realization import Realization, realization_from_rig
from rigsim.view import primitives as P
from rigsim.view.scene import COLOURS, Beam, RigScene, ViewSpec

__all__ = ["build_cube_rig_scene", "resolve_pose_deg", "resolve_face", "POSE_KEYWORDS"]

POSE_KEYWORDS = ("start", "null", "nominal")
"""Named poses: ``start`` (procedure.search_start_deg of the face: where the rendered null search
begins; default), ``null`` (the face's exact null: its true normal along the beam), ``nominal``
(procedure.nominal_poses_deg)."""

SENSOR_BOX_MM = (34.0, 34.0, 22.0)
_FACE_TINT = {"X": "#F2B8B8", "Y": "#BCE2BC", "Z": "#B8D2EE"}
_AXIS_COLOUR = {"X": COLOURS["axis_x"], "Y": COLOURS["axis_y"], "Z": COLOURS["axis_z"]}
_PRIME = "'"  # VTK's bundled font has no U+2032/U+2033: ASCII primes in labels


def resolve_face(rig: CubeMirrorRig, face) -> int:
    """Index into ``procedure.faces`` of ``face`` (None → 0; a face name like "+Y"; or an index)."""
    faces = list(rig.procedure.faces)
    if face is None:
        return 0
    if isinstance(face, (int, np.integer)) and not isinstance(face, bool):
        if 0 <= int(face) < len(faces):
            return int(face)
        raise ViewError(f"--face = {face}: allowed 0..{len(faces) - 1} or one of {faces} (procedure.faces)")
    f = str(face).strip()
    if f in ("X", "Y", "Z"):
        f = "+" + f
    if f in faces:
        return faces.index(f)
    raise ViewError(f"--face = {face!r}: allowed one of {faces} (the rig's measured faces, procedure.faces)")


def _null_pose_rad(rig: CubeMirrorRig, real: Realization, fi: int) -> dict:
    if rig.procedure.method == "diaphragm":
        from rigsim.truth.cube_mirror.placement import diaphragm_layout

        return dict(diaphragm_layout(rig, real, fi).null_pose_rad)
    from rigsim.truth.cube_mirror.autocollimator import autocollimator_layout

    return dict(autocollimator_layout(rig, real, "face", rig.procedure.faces[fi]).reference_pose_rad)


def resolve_pose_deg(rig: CubeMirrorRig, real: Realization, pose, fi: int) -> tuple[dict[str, float], str]:
    """The full pose (every axis, degrees, true angles) and a word saying where it comes from.

    ``pose``: None / "start" / "null" / "nominal", or a mapping {label: degrees} that overrides
    the start pose axis by axis (axes not named keep their start value).
    """
    labels = [a.label for a in rig.turntable.axes]
    start = {lab: 0.0 for lab in labels}
    start.update(rig.procedure.search_start[fi])
    if pose is None or (isinstance(pose, str) and pose.strip().lower() == "start"):
        return start, "start of the null search"
    if isinstance(pose, str):
        key = pose.strip().lower()
        if key == "nominal":
            out = {lab: 0.0 for lab in labels}
            out.update(rig.procedure.nominal_poses_deg[fi])
            return out, "nominal pose"
        if key == "null":
            null = _null_pose_rad(rig, real, fi)
            return {lab: math.degrees(null.get(lab, 0.0)) for lab in labels}, "exact null of the face"
        raise ViewError(f"--pose = {pose!r}: allowed {', '.join(POSE_KEYWORDS)} or LABEL=DEGREES[,LABEL=DEGREES] "
                        f"(axes {labels})")
    out = dict(start)
    axes = {a.label: a for a in rig.turntable.axes}
    for k, v in dict(pose).items():
        if k not in axes:
            raise ViewError(f"--pose axis {k!r}: this turntable has axes {labels}")
        try:
            val = parse_float(v) if isinstance(v, str) else float(v)
        except (TypeError, ValueError):
            raise ViewError(f"--pose {k} = {v!r}: not a number of degrees in ASCII digits") from None
        lo, hi = axes[k].range_deg
        if not (math.isfinite(val) and lo <= val <= hi):
            raise ViewError(f"--pose {k} = {v}: allowed range is {lo:g} to {hi:g} degrees "
                            f"(turntable axis {axes[k].name!r} range_deg)")
        out[k] = val
    return out, "given pose"


# ------------------------------------------------------------------------------------------
# parts
# ------------------------------------------------------------------------------------------

def _turntable(scene: RigScene, rig: CubeMirrorRig, real: Realization, pose_rad: dict, pose_deg: dict) -> float:
    """Gimbal rings, axis lines with their angles, base; returns the outer ring radius."""
    axes = real.turntable.axes
    n = len(axes)
    radii = [290.0, 230.0, 170.0][-n:] if n <= 3 else list(np.linspace(300, 150, n))
    R = np.eye(3)
    spec = {a.label: a for a in rig.turntable.axes}
    for k, ax in enumerate(axes):
        a_rot = R @ ax.direction  # the axis is fixed in its parent frame
        R = R @ ax.matrix(pose_rad.get(ax.label, 0.0))
        if k + 1 < n:
            other = R @ axes[k + 1].direction
        else:
            other = R @ np.cross(ax.direction, axes[k - 1].direction)
        other = P.unit(other - (other @ a_rot) * a_rot)
        r = radii[k]
        name = spec[ax.label].name
        scene.add(f"turntable:{name}_ring", P.ring(np.zeros(3), a_rot, other, r, 9.0), group="turntable",
                  views=("overview",), color=COLOURS["turntable"], smooth_shading=True, specular=0.3)
        ext = r + (60.0 if k == 0 else 25.0)
        scene.add(f"turntable:{name}_axis", P.cylinder(-ext * a_rot, ext * a_rot, 2.5, 24), group="turntable",
                  views=("overview",), color=COLOURS["turntable_axis"])
        for s in (-1.0, 1.0):  # bearings where the axis meets its ring
            scene.add(f"turntable:{name}_bearing{'+' if s > 0 else '-'}",
                      P.cylinder(s * (r - 12.0) * a_rot, s * (r + 12.0) * a_rot, 9.0, 32),
                      group="turntable", views=("overview",), color="#5A5A5A")
        end = (ext + 8.0) * a_rot * (-1.0 if (n == 2 and k == 1) else 1.0)  # keeps the labels apart
        end = end - 30.0 * k * (n > 2) * np.array([0.0, 1.0, 0.0])
        scene.label(f"{name} axis {ax.label}{_PRIME} = {pose_deg[ax.label]:.3f}\u00b0", end, views=("overview",),
                    font_size=12)
        if k == 0:  # pillars of the base at the ends of the outer axis
            for s in (-1.0, 1.0):
                scene.add(f"turntable:base{'+' if s > 0 else '-'}",
                          P.box(s * (r + 40.0) * a_rot, np.column_stack(_frame_from(a_rot)), (30.0, 50.0, 50.0)),
                          group="turntable", views=("overview",), color="#9A9A9A")
    return radii[0]


def _label_offset_dir(v) -> np.ndarray:
    """Unit direction of ``v`` across the beam (Z'), or +Y' when ``v`` is nearly along the beam."""
    v = np.asarray(v, float) * np.array([1.0, 1.0, 0.0])
    n = np.linalg.norm(v)
    return v / n if n > 10.0 else np.array([0.0, 1.0, 0.0])


def _frame_from(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    e1, e2 = P.perp_basis(a)
    return P.unit(a), e1, e2


def _triad(scene: RigScene, prefix: str, origin, R_cols, length: float, names, views, group: str,
           label_views=None, font_size: int = 12, shaft: float | None = None) -> None:
    for i, (nm, col) in enumerate(zip(names, (COLOURS["axis_x"], COLOURS["axis_y"], COLOURS["axis_z"]))):
        d = R_cols[:, i]
        scene.add(f"{prefix}:{'xyz'[i]}", P.arrow(origin, d, length, shaft_radius=shaft), group=group, views=views,
                  color=col, smooth_shading=True)
        if nm:
            scene.label(nm, np.asarray(origin) + (length + 6.0) * d, views=label_views or views, font_size=font_size,
                        colour=col)


def _sensor(scene: RigScene, rig: CubeMirrorRig, real: Realization, R_rm: np.ndarray) -> np.ndarray:
    """Schematic sun-sensor body on the inner frame; true measurement frame. Returns its top centre."""
    c_cube = np.asarray(rig.cube.centre_in_mount_mm, float)
    R_rot_from_sun = R_rm @ real.R_sun_from_mount.T
    z = R_rot_from_sun[:, 2]
    top_mount = np.array([c_cube[0], c_cube[1], 0.0])
    top = R_rm @ top_mount
    centre = top - 0.5 * SENSOR_BOX_MM[2] * z
    scene.add("sensor:body", P.box(centre, R_rot_from_sun, SENSOR_BOX_MM), group="sensor",
              color=COLOURS["sensor"], specular=0.4, legend=None)
    scene.add("sensor:lens", P.cylinder(top, top + 5.0 * z, 7.0, 48), group="sensor", color="#202A44",
              specular=0.8)
    _triad(scene, "sensor:frame", top + 5.0 * z, R_rot_from_sun, 42.0, ("x_sun", "y_sun", "z_sun (boresight)"),
           views=("*",), group="sensor", label_views=("cube",), font_size=11, shaft=1.0)
    u = _label_offset_dir(top - R_rm @ c_cube)
    scene.label("sun sensor", top + 75.0 * u, views=("overview",), font_size=13)
    scene.label("sun sensor (body schematic)", centre - np.array([0.0, 48.0, 0.0]), views=("cube",), font_size=12)
    return top


def _cube(scene: RigScene, rig: CubeMirrorRig, real: Realization, pose_rad: dict, measured: str) -> None:
    from rigsim.truth.cube_mirror.diaphragm import true_cube_mesh

    cp = cube_pose(rig, real, pose_rad)
    R_rm = real.turntable.R_rot_from_mount(pose_rad)
    tm = true_cube_mesh(rig, real)
    mesh = P.transform(P.from_trimesh(tm), cp.R, cp.t)
    # tint each face by its axis (±X red, ±Y green, ±Z blue: the colours of the normal arrows)
    fn = np.asarray(tm.face_normals, float)
    axis = np.argmax(np.abs(fn), axis=1)
    rgb = np.array([[int(_FACE_TINT[a][i:i + 2], 16) for i in (1, 3, 5)] for a in "XYZ"], dtype=np.uint8)
    mesh.cell_data["face_rgb"] = rgb[axis]
    scene.add("cube", mesh, group="cube", scalars="face_rgb", rgb=True, show_edges=True, edge_color="#555555",
              line_width=1.0, specular=0.6, legend=None)
    edge = rig.cube.edge_mm
    for f, n0 in FACE_NORMALS.items():
        if f in real.face_normals_mount:
            centre, n = face_in_rot(rig, real, f, pose_rad)
        else:
            centre, n = cp.apply(0.5 * edge * n0), cp.R @ n0
        ax = f[1]
        strong = f in real.face_normals_mount
        scene.add(f"cube:normal{f}", P.arrow(centre, n, 1.3 * edge if strong else 0.8 * edge,
                                              shaft_radius=0.7 if strong else 0.45),
                  group="cube", color=_AXIS_COLOUR[ax], opacity=1.0 if strong else 0.55, smooth_shading=True)
        if strong:
            tag = " (measured here)" if f == measured else ""
            scene.label(f"n {f} ({DOCUMENT_FACE_NAMES[f]} face){tag}", centre + (1.3 * edge + 5.0) * n,
                        views=("cube",), font_size=12, colour=_AXIS_COLOUR[ax])
    c_m = np.asarray(rig.cube.centre_in_mount_mm, float)
    u = _label_offset_dir(R_rm @ np.array([c_m[0], c_m[1], 0.0]) - cp.t)  # cube → sensor (as in _sensor)
    scene.label(f"mirror cube {edge:g} mm", cp.t - 75.0 * u, views=("overview",), font_size=13)


def _simulator(scene: RigScene, exit_centre, d, rig: CubeMirrorRig, note: str, length: float = 140.0) -> None:
    r = 0.5 * rig.sun_simulator.aperture_mm
    exit_centre = np.asarray(exit_centre, float)
    scene.add("sun_simulator:housing", P.cylinder(exit_centre + 1.0 * d, exit_centre + length * d, r, 96),
              group="sun_simulator", views=("overview",), color=COLOURS["simulator"], opacity=0.9, specular=0.2)
    scene.add("sun_simulator:exit", P.disk(exit_centre + 0.5 * d, -d, r), group="sun_simulator",
              views=("overview", "cube", "screen"), color="#FFF3B0", lighting=False)
    scene.label(f"sun simulator \u00d8{2 * r:g} mm, {rig.sun_simulator.collimation_full_angle_arcmin:g}'{note}",
                exit_centre + (length + 20.0) * d + np.array([0.0, r + 45.0, 0.0]), views=("overview",), font_size=13)


# ------------------------------------------------------------------------------------------
# seed 000: diaphragm screen
# ------------------------------------------------------------------------------------------

def _diaphragm(scene: RigScene, rig: CubeMirrorRig, real: Realization, fi: int, pose_rad: dict) -> dict:
    from rigsim.optics.meshes import screen_with_hole_mesh
    from rigsim.truth.cube_mirror.diaphragm import diaphragm_geometry

    geom = diaphragm_geometry(rig, real, fi)
    lay = geom.layout
    ds = rig.diaphragm_screen
    r = geom.hole_radius_mm
    hole = np.asarray(lay.hole_centre_mm, float)
    d = np.asarray(real.d_sun_rot, float)
    ez = np.array([0.0, 0.0, 1.0])
    screen = P.from_trimesh(screen_with_hole_mesh(ds.width_mm, ds.height_mm, r, sides=128))
    screen = P.transform(screen, np.eye(3), hole)
    scene.add("screen", screen, group="screen", color=COLOURS["screen"], specular=0.0, ambient=0.45, diffuse=0.6)
    scene.add("screen:outline", P.polyline(hole + np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [-1, -1, 0]])
                                           * np.array([ds.width_mm / 2, ds.height_mm / 2, 0.0])),
              group="screen", color="#6B6B6B", line_width=2.0)
    scene.add("screen:hole_rim", P.polyline(P.circle_points(hole - 0.02 * ez, [1, 0, 0], [0, 1, 0], r, 128)),
              group="screen", color="#000000", line_width=2.5)
    scene.label(f"diaphragm screen {ds.width_mm:g}\u00d7{ds.height_mm:g} mm, hole \u00d8{ds.hole_diameter_mm:g} mm",
                hole + np.array([0.0, 0.5 * ds.height_mm + 15.0, 0.0]), views=("overview",), font_size=13)
    scene.label(f"hole \u00d8{ds.hole_diameter_mm:g} mm", hole + np.array([-r * 1.1, r * 1.25, -0.5]),
                views=("screen",), font_size=13)
    _simulator(scene, lay.simulator_exit_mm, d, rig, f" (exit {ds.distance_from_simulator_mm:g} mm behind the screen)")

    info: dict = {"hole_centre_mm": hole, "z_screen_mm": lay.z_screen_mm, "null_pose_rad": dict(lay.null_pose_rad)}
    try:
        sp = trace_return_spot(rig, real, lay, pose_rad)
    except GeometryError as exc:
        scene.warnings.append(f"no return spot at this pose: {exc}")
        sp = None
    if sp is not None:
        inc = np.vstack([lay.simulator_exit_mm, hole, sp.hit_on_face_mm])
        scene.add_beam(Beam("incident", inc, "incident", r, "rigsim.truth.cube_mirror.placement.trace_return_spot",
                            "sun-simulator pencil through the hole to the cube face"),
                       tube_views=("cube", "screen"), legend="incident beam")
        scene.add_beam(Beam("reflected", np.vstack([sp.hit_on_face_mm, sp.spot_mm]), "reflected", r,
                            "rigsim.truth.cube_mirror.placement.trace_return_spot", "reflected by the face back to the screen"),
                       tube_views=("cube", "screen"), legend="reflected beam")
        inc_angle = math.acos(min(1.0, abs(float(sp.reflected_dir @ lay.screen_normal))))
        spot_r = r / math.cos(inc_angle)
        scene.add("screen:spot", P.disk(sp.spot_mm - 0.03 * ez, -ez, spot_r), group="screen",
                  color=COLOURS["reflected"], opacity=0.85, lighting=False)
        off = np.round(np.asarray(sp.offset_mm, float), 9) + 0.0  # no '-0.000'
        tilt = sp.tilt_rad * ARCSEC_PER_RAD
        info.update(spot_mm=np.asarray(sp.spot_mm), offset_mm=off, tilt_arcsec=tilt, on_face=sp.on_face)
        scene.notes.append(f"face {lay.face}: normal {tilt:.1f} arcsec from the beam; return spot "
                           f"{np.linalg.norm(off):.3f} mm from the hole centre "
                           f"(dX' {off[0]:+.3f}, dY' {off[1]:+.3f} mm)")
        if not sp.on_face:
            scene.warnings.append(f"the beam's central ray misses face {lay.face} at this pose")
        # the real return spot: the 32′ simulator spreads it (diaphragm_geometry's divergent trace)
        try:
            gdiv = diaphragm_geometry(rig, real, fi, beam="divergent")
            tr = gdiv.trace(pose_rad)
            if tr.returned:
                scene.add("screen:divergent_spot", P.polyline(P.circle_points(sp.spot_mm - 0.04 * ez, [1, 0, 0], [0, 1, 0],
                                                                              tr.spot_radius_mm, 160)),
                          group="screen", views=("screen",), color=COLOURS["reflected"], line_width=2.0)
                scene.label(f"edge of the {rig.sun_simulator.collimation_full_angle_arcmin:g}' divergent spot "
                            f"(\u00d8{2 * tr.spot_radius_mm:.1f} mm)",
                            sp.spot_mm + tr.spot_radius_mm * np.array([0.62, -0.78, 0.0]) - 0.5 * ez,
                            views=("screen",), font_size=12, colour=COLOURS["reflected"])
                info["divergent_spot_radius_mm"] = tr.spot_radius_mm
        except (GeometryError, ValueError):
            pass
        scene.label("return spot (pencil)", sp.spot_mm + np.array([spot_r * 0.7, -spot_r * 1.9, -0.5]),
                    views=("screen",), font_size=12, colour=COLOURS["reflected"])
        # lab axes in the screen close-up (seen from the cube, +X' points to the left)
        h = 1.15 * info.get("divergent_spot_radius_mm", 5.0)
        o = np.array([0.5 * (hole[0] + sp.spot_mm[0]) - 0.8 * h, 0.5 * (hole[1] + sp.spot_mm[1]) - 0.75 * h,
                      lay.z_screen_mm - 0.5])
        for nm, e, col in (("X'", np.array([1.0, 0.0, 0.0]), COLOURS["axis_x"]), ("Y'", np.array([0.0, 1.0, 0.0]),
                                                                                   COLOURS["axis_y"])):
            scene.add(f"screen:axis_{nm[0]}", P.arrow(o, e, 0.3 * h, shaft_radius=0.008 * h), group="frames",
                      views=("screen",), color=col, lighting=False)
            scene.label(nm, o + 0.36 * h * e, views=("screen",), font_size=12, colour=col)
    null = {k: math.degrees(v) for k, v in lay.null_pose_rad.items()}
    scene.notes.append(f"exact null of face {lay.face}: " + ", ".join(f"{k}={v:.4f}\u00b0" for k, v in null.items()))

    # aiming camera (numpy twin of the rendered camera): body, field on the screen
    cam = geom.camera
    C = cam.centre + geom.shift_mm
    Rw = cam.R_world_from_cam
    fwd = Rw[:, 2]
    W, H = cam.width, cam.height
    corners_uv = np.array([[-0.5, -0.5], [W - 0.5, -0.5], [W - 0.5, H - 0.5], [-0.5, H - 0.5]])
    st = geom.uv_to_screen(corners_uv)
    foot = np.column_stack([hole[0] + st[:, 0], hole[1] + st[:, 1], np.full(4, lay.z_screen_mm)]) - 0.05 * ez
    scene.add("aiming_camera:lens", P.cylinder(C - 28.0 * fwd, C, 13.0, 48), group="aiming_camera",
              color="#1B2A3A", specular=0.6)
    scene.add("aiming_camera:body", P.box(C - 28.0 * fwd - 35.0 * fwd, Rw, (46.0, 46.0, 70.0)), group="aiming_camera",
              color=COLOURS["camera"], specular=0.3)
    scene.add("aiming_camera:field", P.frustum_lines(C, foot), group="aiming_camera", views=("overview",),
              color=COLOURS["camera"], line_width=1.5, opacity=0.8)
    scene.add("aiming_camera:footprint", P.polyline(np.vstack([foot, foot[:1]])), group="aiming_camera",
              views=("screen",), color=COLOURS["camera"], line_width=2.5)
    ac = rig.aiming_camera
    scene.label(f"aiming camera, {ac.view_angle_deg:g}\u00b0 off the screen normal", C - 60.0 * fwd
                + np.array([0.0, -75.0, 0.0]), views=("overview",), font_size=13)
    fw = np.linalg.norm(foot[1] - foot[0])
    fh = np.linalg.norm(foot[2] - foot[1])
    scene.label(f"aiming-camera field {fw:.1f}\u00d7{fh:.1f} mm", foot[3] + np.array([0.0, 0.4, -0.5]),
                views=("screen",), font_size=12, colour="#2878A8")
    info["aiming_camera_centre_mm"] = C
    info["screen_focus_mm"] = hole
    return info


# ------------------------------------------------------------------------------------------
# seed 001: autocollimator
# ------------------------------------------------------------------------------------------

def autocollimator_central_ray(rig: CubeMirrorRig, real: Realization, face: str, pose_rad: dict, optics=None, layout=None):
    """The autocollimator's axial ray at ``pose_rad`` by the exact model, in the rot frame.

    Returns (incident points [reticle, stop plane, mirror], reflected points [mirror, stop plane,
    detector plane], info). The reticle → stop and mirror points come from
    ``AutocollimatorOptics``' outgoing trace and ``mirror_target``; the detector point from its
    return trace (refraction in the singlet included; the drawn segment through the lens joins
    the traced stop-plane and detector-plane points with a straight line).
    """
    from rigsim.optics.autocollimator import AutocollimatorOptics
    from rigsim.truth.cube_mirror.autocollimator import autocollimator_layout, mirror_target

    lay = layout if layout is not None else autocollimator_layout(rig, real, "face", face)
    opt = optics if optics is not None else AutocollimatorOptics(rig.autocollimator)
    m = mirror_target(rig, real, lay, pose_rad)
    P3, d2, _, ok = opt._outgoing(np.array([[0.0, 0.0, 1.0]]))
    if not ok[0]:
        raise GeometryError("the autocollimator's axial ray does not leave the objective")
    p_stop, d_out = P3[0], d2[0]
    H, s = plane_hit(p_stop, d_out, m.centre, m.normal)
    if s <= 0:
        raise GeometryError(f"cube face {face} is behind the autocollimator at this pose")
    on_mirror = bool(m.inside(H))
    r = reflect(d_out, m.normal)
    xy, _, ok2 = opt._return(H[None], r[None])
    info = {"on_mirror": on_mirror, "returns": bool(ok2[0]), "tilt_rad": m.tilt_rad(), "mirror": m, "layout": lay,
            "optics": opt}
    to_rot = lambda p: lay.origin_rot + np.asarray(p, float) @ lay.R_rot_from_A.T  # noqa: E731
    inc = to_rot(np.vstack([opt.source_position, p_stop, H]))
    if r[2] >= 0:
        raise GeometryError(f"the reflection off face {face} does not return towards the autocollimator")
    back_stop, _ = plane_hit(H, r, np.array([0.0, 0.0, opt.objective.z_stop]), np.array([0.0, 0.0, 1.0]))
    det = np.array([xy[0, 0], xy[0, 1], opt.z_detector])
    refl = to_rot(np.vstack([H, back_stop, det]))
    info["detector_xy_mm"] = xy[0]
    info["detector_uv"] = opt.xy_to_uv(xy[0])
    return inc, refl, info


def _autocollimator(scene: RigScene, rig: CubeMirrorRig, real: Realization, fi: int, pose_rad: dict) -> dict:
    from rigsim.optics.autocollimator import AutocollimatorOptics
    from rigsim.optics.meshes import lens_mesh
    from rigsim.truth.cube_mirror.autocollimator import autocollimator_layout

    face = rig.procedure.faces[fi]
    lay = autocollimator_layout(rig, real, "face", face)
    opt = AutocollimatorOptics(rig.autocollimator)
    ob = opt.objective
    RA, OA = lay.R_rot_from_A, lay.origin_rot

    def to_rot(p):
        return OA + np.asarray(p, float) @ RA.T

    zA = RA[:, 2]
    lens = P.transform(P.from_trimesh(lens_mesh(ob, n_rings=10, n_seg=96)), RA, OA)
    scene.add("autocollimator:objective", lens, group="autocollimator", color="#A8D8EA", opacity=0.6,
              smooth_shading=True, specular=0.8)
    scene.add("autocollimator:stop", P.annulus(to_rot([0, 0, ob.z_stop]), zA, ob.stop_radius_mm, ob.lens_radius_mm + 8.0),
              group="autocollimator", color="#2F2F2F")
    tube_r = ob.lens_radius_mm + 8.0
    scene.add("autocollimator:housing", P.cylinder(to_rot([0, 0, opt.z_detector - 30.0]), to_rot([0, 0, ob.z_flat - 1.0]),
                                                   tube_r, 96, capping=False),
              group="autocollimator", views=("overview",), color=COLOURS["autocollimator"], opacity=0.35,
              specular=0.3)
    scene.add("autocollimator:back", P.disk(to_rot([0, 0, opt.z_detector - 30.0]), -zA, tube_r),
              group="autocollimator", views=("overview",), color=COLOURS["autocollimator"], opacity=0.6)
    hw, hh = 0.5 * opt.width * opt.pitch_mm, 0.5 * opt.height * opt.pitch_mm
    det_c = to_rot([0.0, 0.0, opt.z_detector])
    scene.add("autocollimator:detector", P.quad(det_c, RA[:, 0], RA[:, 1], hw, hh), group="autocollimator",
              color="#39424E", specular=0.2)
    # marks in the detector close-up sit just behind the detector plane: that view looks at the
    # detector from behind, so that it reads like a frame (u to the right, v down)
    scene.add("autocollimator:axis_mark", P.segments(
        [det_c - 0.4 * RA[:, 0] - 0.01 * zA, det_c - 0.4 * RA[:, 1] - 0.01 * zA],
        [det_c + 0.4 * RA[:, 0] - 0.01 * zA, det_c + 0.4 * RA[:, 1] - 0.01 * zA]),
        group="autocollimator", views=("detector",), color="#FFFFFF", line_width=2.0)
    ac = rig.autocollimator
    scene.label(f"autocollimator\nf {ac.focal_length_mm:g} mm, \u00d8{ac.aperture_mm:g} mm, {ac.distance_mm:g} mm "
                "from the face", to_rot([0.0, -tube_r - 30.0, opt.z_detector - 30.0]), views=("overview",), font_size=13)
    scene.label(f"detector {opt.width}\u00d7{opt.height} px ({2 * hw:.1f}\u00d7{2 * hh:.1f} mm)",
                to_rot([-0.6 * hw, -hh - 0.3, opt.z_detector - 0.05]), views=("detector",), font_size=12)
    scene.label("optical axis", to_rot([-1.7, -0.45, opt.z_detector - 0.05]), views=("detector",), font_size=11, colour="#404040")

    # the collimated beam (stop-limited) up to the face plane, to scale
    m_mid = to_rot([0.0, 0.0, lay.anchor_A[2]])
    scene.add("autocollimator:beam", P.cylinder(to_rot([0, 0, ob.z_stop]), m_mid, ob.stop_radius_mm, 96, capping=False),
              group="beam", views=("overview", "cube"), color=COLOURS["incident"], opacity=0.13)

    # plane mirror on the inner frame (step A reference)
    info: dict = {"layout": lay}
    if real.plane_mirror_normal_mount is not None and rig.plane_mirror is not None:
        R_rm = real.turntable.R_rot_from_mount(pose_rad)
        c = R_rm @ np.asarray(lay.plane_mirror_centre_mount_mm, float)
        nrm = P.unit(R_rm @ real.plane_mirror_normal_mount)
        rad = 0.5 * rig.plane_mirror.diameter_mm
        scene.add("plane_mirror", P.disk(c + 0.05 * nrm, nrm, rad), group="plane_mirror", color=COLOURS["mirror"],
                  specular=0.9)
        scene.add("plane_mirror:body", P.cylinder(c - 6.0 * nrm, c, rad, 96), group="plane_mirror", color="#6E7B88")
        scene.add("plane_mirror:normal", P.arrow(c, nrm, 35.0, shaft_radius=0.7), group="plane_mirror",
                  color="#34495E", smooth_shading=True)
        away = c - cube_pose(rig, real, pose_rad).t
        away = away - (away @ nrm) * nrm
        away = away / np.linalg.norm(away) if np.linalg.norm(away) > 1e-6 else P.perp_basis(nrm)[0]
        scene.label("plane mirror (step A)", c + (rad + 12.0) * away, views=("cube",), font_size=12)
    _simulator(scene, real.d_sun_rot * rig.sun_simulator.distance_mm, real.d_sun_rot, rig, " (step B)")

    try:
        inc, refl, tr = autocollimator_central_ray(rig, real, face, pose_rad, optics=opt, layout=lay)
    except GeometryError as exc:
        scene.warnings.append(f"no return at this pose: {exc}")
        return info
    scene.add_beam(Beam("incident", inc, "incident", 0.0, "rigsim.optics.autocollimator.AutocollimatorOptics (exact trace)",
                        "axial ray: reticle → objective → face"), legend="incident beam (axial ray; shaded: \u00d8"
                                                                           f"{ac.aperture_mm:g} mm beam)")
    scene.add_beam(Beam("reflected", refl, "reflected", 0.0, "rigsim.optics.autocollimator.AutocollimatorOptics (exact trace)",
                        "reflected axial ray: face → objective → detector"), legend="reflected beam")
    scene.add("autocollimator:return_spot", P.disk(refl[-1] - 0.03 * zA, -zA, 0.07), group="beam",
              views=("detector",), color=COLOURS["reflected"], lighting=False)
    scene.add("autocollimator:return_ring", P.polyline(P.circle_points(refl[-1] - 0.03 * zA, RA[:, 0], RA[:, 1], 0.16, 64)),
              group="beam", views=("detector",), color=COLOURS["reflected"], line_width=2.0)
    scene.label("return of the axial ray", refl[-1] + 0.3 * RA[:, 0] + 0.75 * RA[:, 1] - 0.05 * zA,
                views=("detector",), font_size=12, colour=COLOURS["reflected"])
    th = tr["tilt_rad"] * ARCSEC_PER_RAD
    dxy = tr["detector_xy_mm"]
    scene.notes.append(f"face {face}: true autocollimator reading X {th[0]:+.1f}, Y {th[1]:+.1f} arcsec; "
                       f"axial ray returns {1e3 * np.hypot(*dxy):.0f} \u00b5m from the axis on the detector")
    if not tr["on_mirror"]:
        scene.warnings.append(f"the axial ray misses face {face} at this pose")
    if not tr["returns"]:
        scene.warnings.append("the reflected axial ray does not come back through the objective")
    null = {k: math.degrees(v) for k, v in lay.reference_pose_rad.items()}
    scene.notes.append(f"exact null of face {face}: " + ", ".join(f"{k}={v:.4f}\u00b0" for k, v in null.items()))
    info.update(tilt_arcsec=th, detector_xy_mm=dxy, detector_centre_mm=det_c, detector_frame=RA)
    return info


# ------------------------------------------------------------------------------------------
# the scene
# ------------------------------------------------------------------------------------------

def build_cube_rig_scene(rig: CubeMirrorRig, *, pose=None, face=None, real: Realization | None = None) -> RigScene:
    """Scene of a seed-000/001 rig at a turntable pose (see the module docstring).

    ``pose``: None/"start" (default), "null", "nominal", or {label: degrees} (true angles;
    overrides the start pose axis by axis). ``face``: which measured face the instrument is set
    up for ("+Z", "+Y" or an index into procedure.faces; default the first).
    """
    real = real if real is not None else realization_from_rig(rig)
    fi = resolve_face(rig, face)
    face_name = rig.procedure.faces[fi]
    pose_deg, pose_kind = resolve_pose_deg(rig, real, pose, fi)
    pose_rad = {k: math.radians(v) for k, v in pose_deg.items()}
    R_rm = real.turntable.R_rot_from_mount(pose_rad)
    pose_txt = ", ".join(f"{k}{_PRIME}={v:.3f}\u00b0" for k, v in pose_deg.items())
    scene = RigScene(rig.name, rig.seed_document,
                     f"{rig.name} (seed {rig.seed_document}): pose {pose_txt} (true) \u2014 {pose_kind}, face {face_name}",
                     "rot (lab) frame, mm: origin at the turntable axes, +Z' towards the source",
                     pose_deg=pose_deg)
    scene.info.update(face=face_name, face_index=fi, pose_kind=pose_kind, pose_rad=pose_rad)

    r_outer = _turntable(scene, rig, real, pose_rad, pose_deg)
    scene.info["sensor_top_mm"] = _sensor(scene, rig, real, R_rm)
    scene.info["legend_extra"] = [("face normals, frame axes: x red, y green, z blue", "#404040")]
    _cube(scene, rig, real, pose_rad, face_name)
    # the rot frame, under the turntable
    tri_o = np.array([0.0, -(r_outer + 110.0), 0.0])
    _triad(scene, "rot_frame", tri_o, np.eye(3), 70.0, (f"X{_PRIME}", f"Y{_PRIME}", f"Z{_PRIME} (to the source)"),
           views=("overview",), group="frames", shaft=2.0)
    scene.label("rot frame", tri_o + np.array([-10.0, -25.0, 0.0]), views=("overview",), font_size=12)

    if rig.procedure.method == "diaphragm":
        info = _diaphragm(scene, rig, real, fi, pose_rad)
    else:
        info = _autocollimator(scene, rig, real, fi, pose_rad)
    scene.info.update(info)

    # viewpoints ------------------------------------------------------------------------------
    c_cube = cube_pose(rig, real, pose_rad).t
    lo, hi = scene.bounds("overview")
    focus = 0.5 * (lo + hi)
    look = P.unit(np.array([1.0, 0.75, -0.8]))
    ext = float(np.max(hi - lo))
    scene.views.append(ViewSpec("overview", "rig overview (true scale)", focus, look, np.array([0.0, 1.0, 0.0]),
                                ext * 0.92, view_angle_deg=30.0, scale_bar_mm=100.0))
    cube_focus = 0.5 * (c_cube + scene.info["sensor_top_mm"])
    scene.views.append(ViewSpec("cube", "close-up: sensor and cube (face normals)", cube_focus,
                                P.unit(np.array([1.0, 0.6, -0.55])), np.array([0.0, 1.0, 0.0]), 150.0,
                                view_angle_deg=30.0, scale_bar_mm=20.0))
    if rig.procedure.method == "diaphragm":
        hole = info["screen_focus_mm"]
        half = max(info.get("divergent_spot_radius_mm", 5.0) * 1.15, 4.0)
        spot = info.get("spot_mm", hole)
        f = 0.5 * (hole + spot)
        scene.views.append(ViewSpec("screen", "close-up: the screen seen from the cube (hole and return spot)",
                                    np.array([f[0], f[1], hole[2]]), np.array([0.0, 0.0, -1.0]),
                                    np.array([0.0, 1.0, 0.0]), 2.0 * half, parallel=True, scale_bar_mm=2.0))
    else:
        det_c = info.get("detector_centre_mm")
        if det_c is not None:
            RA = info["detector_frame"]
            scene.views.append(ViewSpec("detector", "close-up: the autocollimator detector, as its frames show it "
                                        "(u right, v down)", det_c, -RA[:, 2], -RA[:, 1], 1.15 * rig.autocollimator.resolution_px[0]
                                        * rig.autocollimator.pixel_pitch_um * 1e-3, parallel=True, scale_bar_mm=1.0,
                                        eye_distance_mm=20.0, depth_mm=5.0))
    return scene

