"""What a cube-mirror rig's geometry implies before anything is rendered: the sun sensor's field
and the sun's image size, how many sweep poses land on the detector, the hole against the cube
face, the aiming camera's or autocollimator's field, and the distance chain. ``rigsim rig check``
prints it; :func:`check_geometry` refuses what cannot work, naming the fields."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rigsim.errors import RigError
from rigsim.optics.screen_return import hole_pull_gain
from rigsim.optics.sun_disk import max_spot_extent_px, sun_window_px
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import NOMINAL_D, TurntableModel

MIN_SWEEP_POSES = 8  # the sun-sensor least squares needs at least this many points
MIN_SUN_IMAGE_PX = 2.0  # a sun image narrower than this lights fewer than the 3 connected pixels a frame spot needs
MAX_HOLE_PULL_GAIN = 1.5  # above: the return is mostly lost into the hole near the null (a warning)


@dataclass(frozen=True)
class GeometryLine:
    item: str
    value: str
    status: str = "ok"  # "ok", "warning" (works, but probably not what was meant) or "error"
    fields: tuple[str, ...] = ()


def _field_deg(cam) -> tuple[float, float, float]:
    """Half field of view (deg) along u, along v and to the corner (from the true camera model)."""
    w, h = cam.width - 1.0, cam.height - 1.0
    pts = np.array([[0.0, cam.cy], [w, cam.cy], [cam.cx, 0.0], [cam.cx, h], [0.0, 0.0], [w, 0.0], [0.0, h], [w, h]])
    d = cam.unproject(pts)
    ang = np.degrees(np.arccos(np.clip(d[:, 2], -1.0, 1.0)))
    return float(np.nanmax(ang[:2])), float(np.nanmax(ang[2:4])), float(np.nanmax(ang[4:]))


def sweep_landing(rig: CubeMirrorRig, margin_px: float = 3.0) -> tuple[int, int]:
    """(poses whose sun image centre lands on the detector at least ``margin_px`` inside, poses)."""
    p = rig.procedure
    k = round(p.sweep_range_deg / p.sweep_step_deg)
    vals = np.radians(np.arange(-k, k + 1) * p.sweep_step_deg)
    A, B = np.meshgrid(vals, vals, indexing="ij")
    pose = {p.sweep_axes[0]: A.ravel(), p.sweep_axes[1]: B.ravel()}
    tt = TurntableModel.nominal_for(rig.turntable)
    cam = rig.sun_sensor.camera()
    R_sm = rig.R_sun_from_mount()
    n = A.size
    R = np.broadcast_to(tt.R_rot_from_mount(pose), (n, 3, 3))  # every pose at once
    s = np.einsum("ij,nkj,k->ni", R_sm, R, np.asarray(NOMINAL_D, float))  # R_sm @ R.T @ d per pose
    uv, ok = cam.project_valid(s)
    return int(np.count_nonzero(ok & cam.on_detector(uv, margin_px=margin_px))), n


def geometry_summary(rig: CubeMirrorRig) -> list[GeometryLine]:
    """The geometry in lines an engineer reads, each with its status and the fields it comes from."""
    ss, cube, proc = rig.sun_sensor, rig.cube, rig.procedure
    cam = ss.camera()
    full = math.radians(rig.sun_simulator.collimation_full_angle_arcmin / 60.0)
    fu, fv, fd = _field_deg(cam)
    out = [GeometryLine("sun sensor", f"{cam.width}×{cam.height} px of {ss.pixel_pitch_um:g} µm, f = {ss.focal_length_mm:g} mm "
                        f"({ss.fx_px:.1f} px); half field ±{fu:.1f}° × ±{fv:.1f}°, corner {fd:.1f}°")]
    on_axis = 2 * math.tan(full / 2) * ss.fx_px
    ext = max_spot_extent_px(cam, full)
    small = on_axis < MIN_SUN_IMAGE_PX
    out.append(GeometryLine("sun image", f"Ø {on_axis:.2f} px on axis, up to {ext:.1f} px across the field; "
                            f"render window {sun_window_px(cam, full)} px"
                            + (f" (the centroid needs at least {MIN_SUN_IMAGE_PX:g} px: a longer focal length or smaller "
                               "pixels)" if small else ""), "error" if small else "ok",
                            ("sun_sensor.focal_length_mm", "sun_sensor.pixel_pitch_um",
                             "sun_simulator.collimation_full_angle_arcmin")))
    landed, n = sweep_landing(rig)
    fields = ("procedure.sweep_range_deg", "procedure.sweep_step_deg", "sun_sensor.focal_length_mm",
              "sun_sensor.resolution_px", "sun_sensor.pixel_pitch_um")
    # a sweep mostly off the detector is a sweep range meant for another sensor: refuse it
    status = "error" if landed < max(MIN_SWEEP_POSES, 0.25 * n) else ("warning" if landed < 0.5 * n else "ok")
    out.append(GeometryLine("sweep", f"±{proc.sweep_range_deg:g}° every {proc.sweep_step_deg:g}° about "
                            f"{'/'.join(proc.sweep_axes)}: {landed} of {n} poses put the sun on the detector"
                            + ("" if status == "ok" else (
                                " (no pose at all: does the sensor face away from the sun simulator? check "
                                "sun_sensor.R_sun_from_mount)" if landed == 0 else
                                f" (the field is ±{fu:.1f}° × ±{fv:.1f}°: sweep within it)")), status,
                            (*fields, "sun_sensor.R_sun_from_mount") if landed == 0 else fields))
    # the sensor's optical centre is the mount's origin: a cube around it would blind it
    d = math.dist(cube.centre_in_mount_mm, (0.0, 0.0, 0.0))
    engulfs = d <= cube.edge_mm * math.sqrt(3) / 2
    out.append(GeometryLine("cube", f"{cube.edge_mm:g} mm faces, centre {cube.centre_in_mount_mm} mm in the mount "
                            f"({d:.1f} mm from the sensor); faces {' and '.join(proc.faces)}"
                            + (": the cube reaches the sensor's optical centre (the mount's origin)" if engulfs else ""),
                            "error" if engulfs else "ok", ("cube.centre_in_mount_mm", "cube.edge_mm")))
    if proc.method == "diaphragm":
        ds, ac = rig.diaphragm_screen, rig.aiming_camera
        hole_ok = ds.hole_diameter_mm <= cube.edge_mm
        out.append(GeometryLine("hole vs face", f"Ø {ds.hole_diameter_mm:g} mm beam on a {cube.edge_mm:g} mm face"
                                + ("" if hole_ok else ": the beam overfills the face, the returned spot is clipped"),
                                "ok" if hole_ok else "error", ("diaphragm_screen.hole_diameter_mm", "cube.edge_mm")))
        blur = 2 * ds.distance_to_cube_mm * math.tan(full / 2)
        gain = hole_pull_gain(ds.hole_diameter_mm / 2, blur)
        pulled = gain > MAX_HOLE_PULL_GAIN
        out.append(GeometryLine("return vs hole", f"divergence blur R = {blur:.2f} mm around the Ø {ds.hole_diameter_mm:g} mm "
                                f"pencil: near the null the visible return reads {gain:.2f}× the geometric offset"
                                + (" (most of the return falls back into the hole: the null is still unbiased, but "
                                   "the concentricity threshold means less than it says; a longer screen distance or a "
                                   "smaller hole helps)" if pulled else ""), "warning" if pulled else "ok",
                                ("diaphragm_screen.hole_diameter_mm", "diaphragm_screen.distance_to_cube_mm",
                                 "sun_simulator.collimation_full_angle_arcmin")))
        ret = ds.hole_diameter_mm + 2 * blur
        fw, fh = (r * ac.object_pixel_mm for r in ac.resolution_px)
        fits = ret < min(fw, fh)
        out.append(GeometryLine("aiming camera", f"{ac.resolution_px[0]}×{ac.resolution_px[1]} px at "
                                f"{ac.object_pixel_mm * 1000:.1f} µm on the screen: field {fw:.1f} × {fh:.1f} mm; the divergent "
                                f"return is Ø {ret:.1f} mm", "ok" if fits else "error",
                                ("aiming_camera.resolution_px", "aiming_camera.pixel_pitch_um",
                                 "diaphragm_screen.distance_to_cube_mm", "sun_simulator.collimation_full_angle_arcmin")))
        out.append(GeometryLine("distance chain", f"sun simulator → screen {ds.distance_from_simulator_mm:g} mm, screen → "
                                f"cube {ds.distance_to_cube_mm:g} mm (lever arm: 1 px = "
                                f"{ac.object_pixel_mm / (2 * ds.distance_to_cube_mm) * 206264.8:.2f}″ of face tilt)"))
    else:
        a, pm = rig.autocollimator, rig.plane_mirror
        # the return moves by f·tan(2·tilt) on the detector: half the field's angle is the face-tilt range
        half = math.degrees(math.atan(0.5 * min(a.resolution_px) * a.pixel_pitch_um * 1e-3 / a.focal_length_mm)) / 2
        out.append(GeometryLine("autocollimator", f"f = {a.focal_length_mm:g} mm, {a.resolution_px[0]}×{a.resolution_px[1]} px "
                                f"of {a.pixel_pitch_um:g} µm: measures face tilts up to ±{half * 3600:.0f}″; "
                                f"aperture Ø {a.aperture_mm:g} mm at {a.distance_mm:g} mm"))
        fno = a.focal_length_mm / a.aperture_mm
        out.append(GeometryLine("objective", f"f/{fno:.2f} plano-convex singlet" + (
            "" if fno >= 1.5 else ": faster than f/1.5, beyond the singlet rigsim models"), "ok" if fno >= 1.5 else "error",
            ("autocollimator.focal_length_mm", "autocollimator.aperture_mm")))
        face_fill = min(a.aperture_mm, cube.edge_mm)
        out.append(GeometryLine("beam vs face", f"Ø {a.aperture_mm:g} mm beam, {cube.edge_mm:g} mm face: "
                                f"{face_fill:g} mm of it returns; plane mirror Ø {pm.diameter_mm:g} mm"))
    return out


def check_geometry(rig: CubeMirrorRig, source="<rig>") -> list[GeometryLine]:
    """:func:`geometry_summary`, raising :class:`RigError` (naming the fields) on any error line."""
    lines = geometry_summary(rig)
    bad = [g for g in lines if g.status == "error"]
    if bad:
        raise RigError(source, [f"{', '.join(g.fields)}: {g.item}: {g.value}" for g in bad])
    return lines
