"""R(cube←rot) from the turntable angles at which two cube faces were nulled.

At the null of a face, its outward normal is parallel to the reference direction ``d``
(towards the sun simulator, seed 000; along the autocollimator axis, seed 001), so the
normal in the mount frame is  r = R_rot_from_mount(θ)ᵀ d  — seed 000 eqs 7–8 with the
beam direction in place of n2 (the printed eq 8 rotates n2 and is degenerate; see
docs/readings.md). The nesting order of the axes is the reading ``axis_order``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from rigsim.estimation.triad import triad
from rigsim.optics.cube import FACE_NORMALS
from rigsim.rig.turntable import TurntableModel, as_reading

AXIS_ORDERS_2AXIS = {
    "XY": "seed 000 eq 7 as printed and its frame definition: X' is the outer axis and carries Y' (default)",
    "YX": "seed 000 step text ('inner frame turned 180°/90°' applied to θ1/θ3): Y' carries X'",
}
AXIS_ORDERS_3AXIS = {
    "YXZ": "seed 001 frame definition: outer Y' carries middle X' carries inner Z' (default)",
    "XYZ": "seed 001 eq 8 as printed (Rot(Y')⁻¹Rot(X')⁻¹): X' carries Y'",
}


EQ8_READINGS = {
    "beam": "each null's normal is R_rot_from_mount(θ)ᵀ·d, the beam direction, for both faces (default: at a null "
            "the face normal is parallel to the beam, whatever the face)",
    "printed": "seed 000 eqs 7–8 as printed: each null rotates its own face normal, r_i = R_rot_from_mount(θ_i)ᵀ·n_i "
               "(degenerate: the two r's end up nearly parallel)",
}


def normal_in_mount(model: TurntableModel, pose_rad: Mapping[str, float], d_rot=(0.0, 0.0, 1.0)) -> np.ndarray:
    R = model.R_rot_from_mount(pose_rad)
    d = np.asarray(d_rot, float)
    return R.T @ (d / np.linalg.norm(d))


def cube_from_rot_triad(
    poses_rad: Sequence[Mapping[str, float]],
    faces: Sequence[str],
    axis_order: str,
    d_rot=(0.0, 0.0, 1.0),
    eq8: str = "beam",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """TRIAD R(cube←rot) from the turntable readings at two nulls. Returns (R, r1, r2).

    ``poses_rad``: two :class:`~rigsim.rig.turntable.TurntableReading` (or mappings {label: rad});
    a :class:`~rigsim.rig.turntable.TruePose` is refused. ``eq8``: the reading of the normals
    (:data:`EQ8_READINGS`)."""
    if eq8 not in EQ8_READINGS:
        raise ValueError(f"eq8 = {eq8!r}: allowed {', '.join(EQ8_READINGS)}")
    model = TurntableModel.nominal(list(axis_order))
    n1, n2 = FACE_NORMALS[faces[0]], FACE_NORMALS[faces[1]]
    d1, d2 = (d_rot, d_rot) if eq8 == "beam" else (n1, n2)
    r1 = normal_in_mount(model, as_reading(poses_rad[0]), d1)
    r2 = normal_in_mount(model, as_reading(poses_rad[1]), d2)
    return triad(n1, n2, r1, r2), r1, r2
