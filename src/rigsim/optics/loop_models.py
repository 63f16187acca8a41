"""The two loop models of seed 003: which physics turns a camera state (E, Δf) into spots.

``"physical"`` (default)
    rigsim's exact ray trace of the laser loop (:func:`~rigsim.optics.line_camera.loop_trace`):
    each path an autocollimator on its own prism facet, the in-focus loop focal length F + Δf/Kf.
    A focal change moves both off-axis spots radially, in y *and* in x.
``"paper"``
    the loop the paper's equations imply, as rigsim reads them (consistent reading): the linear
    small-angle model whose exact inverse is eqs 1–4. A focal change scales the spots' separation
    in y only (eq 1); a camera rotation moves the return beams by twice the rotation about every
    axis, with the paper's gains 2F/cos²β (α, eq 2), 2F/cos²ω (β, eq 3) and the lever arm L/2 (γ,
    eq 4). (α, β, γ) are the intrinsic XYZ Euler angles of E; the displacements carry tan of them
    so that eqs 2–4's arctan invert them exactly. docs/boresight.md derives it.

Both return focal-plane landing points (..., 2 detectors, 2) mm and spots in rigsim pixels
(..., 2, 2) like :func:`~rigsim.optics.line_camera.spots_uv`.
"""

from __future__ import annotations

import math

import numpy as np

from rigsim.optics.line_camera import CameraGeometry, euler_xyz, loop_trace, spots_uv

__all__ = ["LOOP_MODELS", "check_loop_model", "loop_spots_uv", "paper_loop_displacement", "paper_loop_trace"]

LOOP_MODELS = ("physical", "paper")


def check_loop_model(loop_model: str) -> str:
    """``loop_model`` itself, or ValueError naming the allowed values."""
    if loop_model not in LOOP_MODELS:
        raise ValueError(f"loop_model = {loop_model!r}: allowed {LOOP_MODELS}")
    return loop_model


def paper_loop_displacement(geom: CameraGeometry, E_hrc=None, delta_f_mm=0.0) -> np.ndarray:
    """Focal-plane displacement (..., 2 detectors, 2) mm of both spots under the paper's loop.

    With s = (+1, −1) for (M1, M2) and (α, β, γ) the XYZ Euler angles of ``E_hrc``:
    Δx = 2F·tan β / cos²ω + s·L·tan γ, Δy = −2F·tan α / cos²β_h + s·(Δf/Kf)·L/F (β_h: half the
    angle between OA0 and OB0; L = Lc1 − Lc2)."""
    E = np.eye(3) if E_hrc is None else np.asarray(E_hrc, float)
    ang = euler_xyz(E)
    ta, tb, tg = np.tan(ang[..., 0]), np.tan(ang[..., 1]), np.tan(ang[..., 2])
    dF = np.asarray(delta_f_mm, float) / geom.telecentric_factor
    F, L = geom.F, geom.L_mm
    gain_a = 2.0 * F / math.cos(geom.beta_half_angle_rad) ** 2
    gain_b = 2.0 * F / math.cos(geom.off_axis_rad) ** 2
    common_x = gain_b * tb
    common_y = -gain_a * ta
    diff_x = L * tg
    diff_y = dF * L / F
    batch = np.broadcast_shapes(ta.shape, dF.shape)
    out = np.empty(batch + (2, 2))
    for j, s in enumerate((1.0, -1.0)):
        out[..., j, 0] = common_x + s * diff_x
        out[..., j, 1] = common_y + s * diff_y
    return out


def paper_loop_trace(geom: CameraGeometry, E_hrc=None, delta_f_mm=0.0) -> np.ndarray:
    """Focal-plane landing points (..., 2, 2) mm under the paper's loop: the reference landing
    points of the exact trace plus :func:`paper_loop_displacement`."""
    return loop_trace(geom) + paper_loop_displacement(geom, E_hrc, delta_f_mm)


def loop_spots_uv(geom: CameraGeometry, E_hrc=None, delta_f_mm=0.0, tilt_rad=None,
                  loop_model: str = "physical") -> np.ndarray:
    """Spot positions in rigsim pixels (..., 2 detectors [M1, M2], 2 [u, v]) under ``loop_model``;
    ``"physical"`` is :func:`~rigsim.optics.line_camera.spots_uv` itself."""
    if check_loop_model(loop_model) == "physical":
        return spots_uv(geom, E_hrc, delta_f_mm, tilt_rad)
    P = paper_loop_trace(geom, E_hrc, delta_f_mm)
    return geom.xy_to_uv(geom.focal_to_xy(P, tilt_rad))
