"""3D scene of the boresight rig (seed 003): two line-array cameras, the shared prism, laser loops.

Geometry from :mod:`rigsim.optics.line_camera` (the exact in-focus loop model that is the truth
of seed 003): each camera is its ideal thin lens at the OTA origin with the focal plane at
z = −F, the CMOS detectors M1/M2 at the ends of the CCD line, and for each detector a laser
loop: emitter (at the reference point A1/B1) → parallel to the axis to the lens plane → towards
the back focal point → its prism facet (normal to its beam, ``facet_normals_ota``) → back →
lens → landing point (``loop_trace``; at the reference it is the emitter itself). The facet sits
``facet_distance_mm`` from the lens plane along the beam, as the renderer places it.

Placement of the cameras in the prism frame: ``R_prism_from_ota = R_prism_from_hrc ·
R_ota_from_hrcᵀ``; the paper gives no prism geometry, so each camera is translated to put the
midpoint of its two facets ``PAIR_OFFSET_MM`` from the prism centre along the prism's X (the two
pairs side by side on a schematic prism body). The loop of one camera is unaffected by that
choice (each loop is an autocollimator). Scale is true; the lens is drawn as its outline only
(the real camera is a folded three-mirror system; rigsim models it as an ideal lens).
"""

from __future__ import annotations

import math

import numpy as np

from rigsim.errors import ViewError
from rigsim.view import primitives as P
from rigsim.view.scene import COLOURS, Beam, RigScene, ViewSpec, _pose_text

__all__ = ["build_boresight_scene", "PAIR_OFFSET_MM", "camera_placement", "laser_loops"]

PAIR_OFFSET_MM = 60.0
FACET_HALF_MM = 25.0
_CAM_COLOURS = ("#0072B2", "#009E73", "#8E44AD")


def camera_placement(geom, index: int) -> tuple[np.ndarray, np.ndarray]:
    """(R_prism_from_ota, lens centre in the prism frame) of camera ``index`` (see module doc)."""
    R = geom.R_prism_from_hrc @ geom.R_ota_from_hrc.T
    facets, _ = _facet_points(geom)
    mid = facets.mean(0)
    side = PAIR_OFFSET_MM * (1.0 if index % 2 == 0 else -1.0)
    return R, -R @ mid + np.array([side, 0.0, 0.0])


def _facet_points(geom) -> tuple[np.ndarray, np.ndarray]:
    from rigsim.optics.line_camera import facet_normals_ota

    e = geom.emitter_mm
    f0 = facet_normals_ota(geom)
    u_out = -f0
    pts = np.column_stack([e[:, 0], e[:, 1], np.zeros(2)]) + (geom.facet_distance_mm / u_out[:, 2])[:, None] * u_out
    return pts, f0


def laser_loops(geom, E_hrc=None, delta_f_mm: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per detector (M1, M2): (outgoing points, returning points) in the OTA frame, mm.

    Outgoing: emitter → lens plane → facet. Returning: facet → lens plane → landing point, the
    landing point from :func:`rigsim.optics.line_camera.loop_trace` (the exact model)."""
    from rigsim.optics.line_camera import loop_trace

    facets, f0 = _facet_points(geom)
    e = geom.emitter_mm
    C = geom.R_ota_from_hrc
    E = np.eye(3) if E_hrc is None else np.asarray(E_hrc, float)
    E_ota = C @ E @ C.T
    land = loop_trace(geom, E_hrc, delta_f_mm)
    Fp = geom.F + delta_f_mm / geom.telecentric_factor
    out = []
    for j in range(2):
        u_out = -f0[j]
        f = E_ota.T @ f0[j]
        ub = u_out - 2.0 * (u_out @ f) * f
        Q = facets[j] - facets[j][2] / ub[2] * ub
        go = np.array([[e[j, 0], e[j, 1], -geom.F], [e[j, 0], e[j, 1], 0.0], facets[j]])
        back = np.array([facets[j], Q, [land[j, 0], land[j, 1], -Fp]])
        out.append((go, back))
    return out


def build_boresight_scene(rig, *, pose=None, face=None) -> RigScene:
    if pose is not None:
        raise ViewError(f"--pose = {_pose_text(pose)}: the boresight rig (seed 003) has no turntable; the view shows the "
                        "reference state (no camera rotation, no focal change)")
    if face is not None:
        raise ViewError(f"--face = {face!r}: the boresight rig (seed 003) has no mirror cube")
    from rigsim.optics.line_camera import CameraGeometry

    scene = RigScene(rig.name, "003", f"{rig.name} (seed 003): {len(rig.cameras)} line-array cameras, shared prism, "
                                      "laser loops at the reference", "prism frame, mm (schematic placement of "
                                                                       "the prism; each camera's loop exact)")
    ey = np.array([0.0, 1.0, 0.0])
    facet_all = []
    det_views = []
    for i, cam in enumerate(rig.cameras):
        g = CameraGeometry.from_rig(cam)
        R, O = camera_placement(g, i)
        col = _CAM_COLOURS[i % len(_CAM_COLOURS)]

        def to_p(p, R=R, O=O):
            return O + np.asarray(p, float) @ R.T

        e = g.emitter_mm
        r_lens = 1.08 * float(np.max(np.hypot(e[:, 0], e[:, 1])))
        scene.add(f"{cam.name}:lens", P.polyline(to_p(P.circle_points(np.zeros(3), [1, 0, 0], [0, 1, 0], r_lens, 160))),
                  group="camera", views=("overview",), color=col, line_width=3.0)
        # the light cone of the (unfolded) camera: lens aperture -> focal-plane region
        ring_lens = P.circle_points(np.zeros(3), [1, 0, 0], [0, 1, 0], r_lens, 96)[:-1]
        ring_fp = P.circle_points(np.array([g.centers_mm[0, 0], 0.0, -g.F]), [1, 0, 0], [0, 1, 0],
                                  0.5 * g.L_mm + 0.5 * g.height_px * g.pitch_mm, 96)[:-1]
        scene.add(f"{cam.name}:envelope", P.transform(P.ruled(ring_lens, ring_fp), R, O), group="camera",
                  views=("overview",), color=col, opacity=0.10, lighting=False)
        scene.add(f"{cam.name}:axis", P.polyline(to_p(np.array([[0, 0, 0], [0, 0, -g.F]]))), group="camera",
                  views=("overview",), color=col, line_width=1.0, opacity=0.6)
        c = g.centers_mm
        half_w = 0.5 * g.width_px * g.pitch_mm
        half_h = 0.5 * g.height_px * g.pitch_mm
        x0 = c[0, 0]
        fp = np.array([[x0 - 3 * half_w, c[1, 1] - 2 * half_h, -g.F], [x0 + 3 * half_w, c[1, 1] - 2 * half_h, -g.F],
                       [x0 + 3 * half_w, c[0, 1] + 2 * half_h, -g.F], [x0 - 3 * half_w, c[0, 1] + 2 * half_h, -g.F]])
        scene.add(f"{cam.name}:focal_plane", P.polyline(to_p(np.vstack([fp, fp[:1]]))), group="camera", color=col,
                  line_width=2.0)
        scene.add(f"{cam.name}:ccd_line", P.polyline(to_p(np.array([[x0, c[1, 1] + half_h, -g.F],
                                                                     [x0, c[0, 1] - half_h, -g.F]]))),
                  group="camera", color="#404040", line_width=3.0)
        for j, nm in enumerate(("M1", "M2")):
            t = g.tilt_rad[j]
            e1 = np.array([math.cos(t), math.sin(t), 0.0])
            e2 = np.array([-math.sin(t), math.cos(t), 0.0])
            q = P.quad(np.array([c[j, 0], c[j, 1], -g.F]), e1, e2, half_w, half_h)
            scene.add(f"{cam.name}:{nm}", P.transform(q, R, O), group="camera", color="#2D3440")
            scene.label(f"{cam.name} {nm}", to_p([c[j, 0], c[j, 1] + (1.0 if j == 0 else -1.0) * (half_h + 60.0), -g.F]),
                        views=("overview",), font_size=11, colour=col)
            det_views.append((f"{cam.name}_{nm}", to_p([c[j, 0], c[j, 1], -g.F]), R, half_w))
            em = np.array([e[j, 0], e[j, 1], -g.F + 0.5])
            scene.add(f"{cam.name}:{nm}_emitter", P.segments(to_p(em + np.array([[-1.5, 0, 0], [0, -1.5, 0]])),
                                                             to_p(em + np.array([[1.5, 0, 0], [0, 1.5, 0]]))),
                      group="camera", views=("detector",), color="#FFFFFF", line_width=2.0)
        scene.label(f"{cam.name} camera: F {g.F:g} mm, off-axis {math.degrees(g.off_axis_rad):g}\u00b0, "
                    f"L {g.L_mm:g} mm", to_p([0.0, -r_lens - 120.0, -0.5 * g.F]), views=("overview",), font_size=12,
                    colour=col)
        scene.label(f"{cam.name} lens (ideal, outline)", to_p([0.0, r_lens + 60.0, 0.0]), views=("overview",),
                    font_size=11, colour=col)
        facets, f0 = _facet_points(g)
        for j in range(2):
            n = R @ f0[j]
            a = P.unit(np.cross(n, ey))
            b = np.cross(n, a)
            scene.add(f"prism:facet_{cam.name}_{j + 1}", P.quad(to_p(facets[j]), a, b, FACET_HALF_MM, FACET_HALF_MM),
                      group="prism", color=col, opacity=0.85, specular=0.8)
            scene.add(f"prism:normal_{cam.name}_{j + 1}", P.arrow(to_p(facets[j]), n, 80.0, shaft_radius=1.5),
                      group="prism", views=("prism",), color=col, smooth_shading=True)
            scene.label(f"facet {cam.name} M{j + 1}", to_p(facets[j]) + 50.0 * n + np.array([0.0, 40.0, 0.0]),
                        views=("prism",), font_size=12, colour=col)
            facet_all.append(to_p(facets[j]))
        for j, (go, back) in enumerate(laser_loops(g)):
            scene.add(f"{cam.name}:M{j + 1}_spot", P.disk(to_p(back[-1] + np.array([0.0, 0.0, 1.0])), R[:, 2],
                                                        rig.laser.core_radius_um * 1e-3),
                      group="beam", views=("detector",), color=COLOURS["reflected"], lighting=False)
            scene.add_beam(Beam(f"{cam.name}_M{j + 1}_out", to_p(go), "incident", 0.0,
                                "rigsim.optics.line_camera (facet_normals_ota)", "emitter -> lens -> facet"),
                           line_width=4.0, legend="laser, outgoing" if (i == 0 and j == 0) else None)
            scene.add_beam(Beam(f"{cam.name}_M{j + 1}_back", to_p(back), "reflected", 0.0,
                                "rigsim.optics.line_camera.loop_trace", "facet -> lens -> landing point"),
                           line_width=4.0, legend="laser, returned by its facet" if (i == 0 and j == 0) else None)
    fa = np.array(facet_all)
    lo, hi = fa.min(0) - 60.0, fa.max(0) + 60.0
    scene.add("prism:body", P.box(0.5 * (lo + hi), np.eye(3), hi - lo), group="prism", color="#B8C9D9", opacity=0.18)
    scene.label("central prism (schematic body; facets exact)", np.array([hi[0] + 200.0, 0.0, lo[2] - 1100.0]),
                views=("overview",), font_size=12)
    scene.notes.append("each facet is normal to its own laser beam: at the reference every loop returns onto its "
                       "emitter (autocollimation)")
    scene.notes.append("the real cameras are folded three-mirror systems; rigsim's model (and this view) unfolds "
                       "each into an ideal lens of focal length F")
    scene.info["legend_extra"] = [(f"{c.name} camera", _CAM_COLOURS[i % 3]) for i, c in enumerate(rig.cameras)]

    lo, hi = scene.bounds("overview")
    scene.views.append(ViewSpec("overview", "cameras and prism (true scale)", 0.5 * (lo + hi),
                                P.unit(np.array([0.15, 1.0, 0.3])), np.array([1.0, 0.0, 0.0]),
                                float(np.max(hi - lo)), scale_bar_mm=1000.0))
    m1 = fa[0::2]  # the M1 facet of each camera (same end of the prism)
    scene.views.append(ViewSpec("prism", "close-up: the M1 facets of the prism (one per camera), seen from the "
                                "cameras", m1.mean(0), P.unit(np.array([-0.35, 0.35, -1.0])), np.array([0.0, 1.0, 0.0]),
                                float(np.max(np.ptp(m1, axis=0))) + 220.0, scale_bar_mm=50.0))
    name, centre, R, half_w = det_views[0]
    scene.views.append(ViewSpec("detector", f"close-up: {name.replace('_', ' ')} (emitter = return spot at the "
                                             "reference)", centre, R[:, 2], R[:, 1], 2.6 * half_w, parallel=True,
                                scale_bar_mm=10.0, eye_distance_mm=300.0))
    return scene
