"""3D scene of the star-sensor rig (seed 004): the sensor, its field of view and catalogue stars.

Frame: the sensor's camera frame at the first attitude of the rig's sequence (rigsim's camera
convention: x = +u, y = +v, z = boresight), millimetres, the pinhole at the origin. The
attitude is the one ``rigsim run star-calibration --seed 0`` renders first
(:func:`rigsim.truth.star.from_rig` with the pipeline's seed), the stars are
:meth:`rigsim.truth.star.StarSky.field` of it: catalogue directions at the observation epoch and
their true image positions (distortion included).

Drawn: the detector where it physically sits (z = −f, the image inverted through the pinhole),
a schematic barrel and baffle, the field-of-view frustum (the detector's edge unprojected by the
true camera, to ``RAY_LENGTH_MM``), every field star as a dot at that distance, and the brightest
``n_bright`` as rays: catalogue direction → pinhole → true image point on the detector.
Stars are at infinity: the ray length is a drawing choice.
"""

from __future__ import annotations

import math

import numpy as np

from rigsim.errors import ViewError
from rigsim.view import primitives as P
from rigsim.view.scene import COLOURS, Beam, RigScene, ViewSpec, _pose_text

__all__ = ["build_star_scene", "RAY_LENGTH_MM", "first_attitude"]

RAY_LENGTH_MM = 400.0


def first_attitude(rig, seed: int = 0) -> np.ndarray:
    """R_cam_from_icrs of the first frame ``rigsim run star-calibration --seed SEED`` renders."""
    from rigsim.optics import attitude as att

    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 4004]))
    return att.from_rig(rig.sequence, rng, jitter=False).R_cam_from_icrs[0]  # the commanded attitude


def image_point_mm(sensor, uv) -> np.ndarray:
    """Physical detector point (camera frame, mm) of pixel ``uv``: z = −f, inverted through the
    pinhole (rigsim's pixel (u, v) is the upright image, docs/conventions.md)."""
    uv = np.asarray(uv, float)
    u0, v0 = sensor.principal_point_px
    p = sensor.pixel_pitch_um * 1e-3
    out = np.empty(uv.shape[:-1] + (3,))
    out[..., 0] = -(uv[..., 0] - u0) * p
    out[..., 1] = -(uv[..., 1] - v0) * p
    out[..., 2] = -sensor.focal_length_mm
    return out


def build_star_scene(rig, *, pose=None, face=None, n_bright: int = 6, seed: int = 0, sky=None) -> RigScene:
    if pose is not None:
        raise ViewError(f"--pose = {_pose_text(pose)}: the star-sensor rig (seed 004) has no turntable; the view shows the "
                        "first attitude of its sequence")
    if face is not None:
        raise ViewError(f"--face = {face!r}: the star-sensor rig (seed 004) has no mirror cube")
    if not 0 <= int(n_bright) <= 50:
        raise ViewError(f"n_bright = {n_bright}: allowed range is 0 to 50")
    from rigsim.optics.attitude import boresight_radec
    from rigsim.truth.star import StarSky

    s = rig.sensor
    sky = sky if sky is not None else StarSky(rig)
    R0 = first_attitude(rig, seed)
    field = sky.field(R0)
    ra, dec = boresight_radec(R0)
    f = s.focal_length_mm
    W, H = s.resolution_px
    cam = s.camera()
    L = RAY_LENGTH_MM
    fov = s.fov_deg
    scene = RigScene(rig.name, "004",
                     f"{rig.name} (seed 004): first attitude of the sequence, boresight RA {float(ra):.2f}\u00b0, "
                     f"Dec {float(dec):+.2f}\u00b0 \u2014 {len(field)} catalogue stars on the detector",
                     "camera frame, mm: pinhole at the origin, z = boresight, x = +u, y = +v")
    scene.info.update(R_cam_from_icrs=R0, field=field, ray_length_mm=L)

    # sensor: detector at z = -f (physical, inverted image), barrel, baffle, aperture
    corners_uv = np.array([[-0.5, -0.5], [W - 0.5, -0.5], [W - 0.5, H - 0.5], [-0.5, H - 0.5]])
    det = image_point_mm(s, corners_uv)
    scene.add("sensor:detector", P.quad(det.mean(0), [1, 0, 0], [0, 1, 0], 0.5 * W * s.pixel_pitch_um * 1e-3,
                                         0.5 * H * s.pixel_pitch_um * 1e-3),
              group="sensor", color="#2D3440", specular=0.2)
    r_ap = 0.5 * s.aperture_diameter_mm
    half_det = 0.5 * math.hypot(W, H) * s.pixel_pitch_um * 1e-3
    r_barrel = max(r_ap, half_det) + 6.0
    ez = np.array([0.0, 0.0, 1.0])
    scene.add("sensor:barrel", P.cylinder(-(f + 12.0) * ez, -2.0 * ez, r_barrel, 96, capping=False), group="sensor",
              views=("overview",), color=COLOURS["sensor"], opacity=0.35)
    scene.add("sensor:lens", P.annulus(np.zeros(3), ez, r_ap, r_barrel), group="sensor", color="#202A44")
    baffle_len = 2.2 * r_barrel / math.tan(math.radians(0.5 * max(fov)) + 0.02)
    r_baffle_out = r_barrel + baffle_len * math.tan(math.radians(0.5 * max(fov)) + 0.02)
    scene.add("sensor:baffle", P.cylinder(np.zeros(3), baffle_len * ez, r_baffle_out, 96, capping=False).clip(
        normal=-ez, origin=np.zeros(3)), group="sensor", views=("overview",), color=COLOURS["sensor"], opacity=0.12)
    scene.label(f"star sensor f {f:g} mm, \u00d8{s.aperture_diameter_mm:g} mm, {W}\u00d7{H} px "
                f"(FOV {fov[0]:.1f}\u00b0\u00d7{fov[1]:.1f}\u00b0)", np.array([0.0, r_barrel + 25.0, -f]),
                views=("overview",), font_size=13)
    scene.label("detector (z = -f)", det[2] + np.array([0.0, 2.0, 0.0]), views=("overview",), font_size=11)

    # field of view: the detector's edge unprojected by the true camera (distortion included)
    k = np.linspace(0.0, 1.0, 33)[:-1]
    edge_uv = np.vstack([corners_uv[i] + k[:, None] * (corners_uv[(i + 1) % 4] - corners_uv[i]) for i in range(4)])
    dirs = cam.unproject(edge_uv)
    rim = L * dirs / dirs[:, 2:3] * (1.0 / np.linalg.norm(dirs / dirs[:, 2:3], axis=1))[:, None]
    scene.add("fov:outline", P.polyline(np.vstack([rim, rim[:1]])), group="fov", color=COLOURS["frustum"],
              line_width=2.0, legend="field of view (detector edge, true camera)")
    scene.add("fov:edges", P.segments(np.zeros((4, 3)), rim[::32]), group="fov", color=COLOURS["frustum"],
              line_width=1.5)
    scene.add("fov:boresight", P.arrow(np.zeros(3), ez, L * 1.08, shaft_radius=0.8), group="fov",
              views=("overview",), color=COLOURS["axis_z"])
    scene.label("boresight z", L * 1.12 * ez, views=("overview",), font_size=12, colour=COLOURS["axis_z"])
    # celestial north and the sky's frame at this attitude
    north = R0 @ np.array([0.0, 0.0, 1.0])
    scene.add("sky:north", P.arrow(np.zeros(3), north, 0.45 * L, shaft_radius=0.8), group="sky",
              views=("overview",), color="#7F3FBF")
    scene.label("to the celestial north pole", 0.48 * L * north, views=("overview",), font_size=11,
                colour="#7F3FBF")

    # stars
    d = field.dirs_cam
    mag = field.mag
    scene.add("stars:all", P.pv.PolyData(L * d), group="stars", color=COLOURS["star"], point_size=6.0,
              render_points_as_spheres=True, legend=f"catalogue stars, Hp \u2264 {rig.sky.magnitude_limit:g} "
                                                    "(drawn at 400 mm)")
    order = np.argsort(mag)[: int(n_bright)]
    img = image_point_mm(s, field.uv)
    # the detector close-up looks at the detector from behind so that it reads like a frame (u right,
    # v down): its marks sit just behind the detector plane
    scene.add("stars:images", P.pv.PolyData(img - 0.01 * ez), group="stars", views=("detector",),
              color="#FFD24D", point_size=5.0, render_points_as_spheres=True)
    for rank, i in enumerate(order):
        pts = np.vstack([L * d[i], np.zeros(3), img[i]])
        scene.add_beam(Beam(f"star_HIP{int(field.hip[i])}", pts, "incident", 0.0, "rigsim.truth.star.StarSky.field",
                            "catalogue direction -> pinhole -> true image point"), line_width=2.5,
                       line_views=("overview",),
                       legend="brightest stars: direction -> pinhole -> image" if rank == 0 else None)
        scene.add(f"stars:bright{rank}", P.pv.Sphere(radius=max(1.5, 5.0 - 0.6 * mag[i]), center=L * d[i]),
                  group="stars", color=COLOURS["star"])
        scene.label(f"HIP {int(field.hip[i])} (Hp {mag[i]:.1f})", L * d[i] + np.array([0.0, -6.0, 0.0]),
                    views=("overview",), font_size=11)
        scene.label(f"HIP {int(field.hip[i])}", img[i] + np.array([0.0, 0.25, -0.02]), views=("detector",),
                    font_size=11)
    scene.notes.append(f"{len(field)} stars with Hp \u2264 {rig.sky.magnitude_limit:g} imaged; brightest Hp "
                       f"{float(mag.min()):.2f}; rays from the {len(order)} brightest")
    scene.notes.append(f"principal point ({s.principal_point_px[0]:.1f}, {s.principal_point_px[1]:.1f}) px, "
                       f"k1 {s.k1:+g}, k2 {s.k2:+g} (true)")
    scene.info["legend_extra"] = []

    look = P.unit(np.array([1.0, -0.55, -0.45]))
    lo, hi = scene.bounds("overview")
    scene.views.append(ViewSpec("overview", "star sensor and its field of view", 0.5 * (lo + hi), look,
                                np.array([0.0, -1.0, 0.0]), float(np.max(hi - lo)), scale_bar_mm=50.0))
    scene.views.append(ViewSpec("detector", "the detector as its frames show it (u right, v down): true star images",
                                det.mean(0), -ez, np.array([0.0, 1.0, 0.0]),
                                1.08 * max(W, H) * s.pixel_pitch_um * 1e-3, parallel=True, scale_bar_mm=2.0,
                                eye_distance_mm=20.0, depth_mm=5.0))
    return scene
