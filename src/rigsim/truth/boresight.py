"""The true state of the seed-003 rig over the thermal-vacuum orbit scenario: each camera's rotation
against the prism and its focal change at every measurement time."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.frames import ARCSEC_PER_RAD
from rigsim.optics.line_camera import CameraGeometry, relative_rotation, small_angles_arcsec
from rigsim.rig.boresight import BoresightRig

AS = ARCSEC_PER_RAD


# ------------------------------------------------------------------------------ orbit scenario
@dataclass
class OrbitTruth:
    t_min: np.ndarray
    E: list                      # per camera (n, 3, 3): rotation against the prism seen by the camera
    delta_f_mm: list             # per camera (n,)
    relative: np.ndarray         # (n, 3) true change of the angle between the cameras (arcsec, C1 axes)
    relative_R: np.ndarray       # (n, 3, 3)


def orbit_truth(rig: BoresightRig, geoms: list[CameraGeometry], t_min=None) -> OrbitTruth:
    """Thermal drift over the orbit: a sinusoidal relative rotation of camera 2 against camera 1
    (pitch about Y, roll about X, peak-to-peak from ``rig.orbit``), a common drift of both cameras
    and the prism's own drift (both cancel in the relative angle), and each camera's Δf."""
    o = rig.orbit
    if t_min is None:
        t_min = np.linspace(0.0, o.orbits * o.period_min, o.measurements)
    t = np.asarray(t_min, float)
    ph = 2 * np.pi * t / o.period_min + math.radians(o.phase_deg)
    rel = np.column_stack([0.5 * o.relative_roll_pp_arcsec * np.sin(ph + 1.0),
                           0.5 * o.relative_pitch_pp_arcsec * np.sin(ph), np.zeros_like(t)])
    R_rel = Rotation.from_rotvec(rel / AS).as_matrix()
    common = 0.5 * o.camera_drift_pp_arcsec * np.column_stack([np.sin(ph + 0.4), np.sin(ph + 2.0), np.sin(ph + 3.5)])
    prism = 0.5 * o.prism_drift_pp_arcsec * np.column_stack([np.sin(ph + 1.3), np.sin(ph - 0.7), np.sin(ph + 2.6)])
    dC1 = Rotation.from_rotvec(common / AS).as_matrix()
    dP = Rotation.from_rotvec(prism / AS).as_matrix()
    g1 = geoms[0]
    g2 = geoms[1] if len(geoms) > 1 else geoms[0]
    R1, R2 = g1.R_prism_from_hrc, g2.R_prism_from_hrc
    dC2 = R2.T @ R1 @ dC1 @ R_rel @ R1.T @ R2
    E1 = R1.T @ np.swapaxes(dP, 1, 2) @ R1 @ dC1
    E2 = R2.T @ np.swapaxes(dP, 1, 2) @ R2 @ dC2
    f_pp = o.focal_pp_um * 1e-3
    df1 = 0.5 * f_pp * np.sin(ph - 0.5)
    df2 = 0.5 * f_pp * np.sin(ph + 0.9)
    Rrel_true = relative_rotation(E1, E2, g1, g2)
    return OrbitTruth(t, [E1, E2], [df1, df2], small_angles_arcsec(Rrel_true), Rrel_true)
