"""The null search of a cube face: measure, move the turntable, repeat (seed 000 Table 1, seed 001 step C).

The loop is the same for the diaphragm screen (measured: hole/spot centre offset in aiming-camera
pixels) and the autocollimator (measured: its two readings in arcsec). It sees what the operator
sees: the turntable's *readings* and the measurements, plus the operator's nominal model of the
rig; never the true pose. At each step:

1. ``measure(reading)`` returns the measured 2-vector at the turntable's current state;
2. if both components are below ``threshold`` the face is nulled and the reading is recorded
   (θ1, θ2);
3. otherwise the feedback rule moves the free axes by Δr = −J⁻¹·m, where J = ∂model/∂r is the
   Jacobian of the operator's nominal prediction of the measurement (:func:`offset_model`,
   :func:`reading_model`), rounded to ``command_resolution_rad`` (Table 1 moves in 0.001° steps).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from rigsim.frames import ARCSEC_PER_RAD
from rigsim.optics.autocollimator import a_frame_basis, exact_reading_rad
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import NOMINAL_D, TurntableModel, TurntableReading, as_reading

__all__ = ["SearchStep", "SearchResult", "null_search", "numerical_jacobian", "reflected_offset_mm",
           "offset_model", "reading_model"]


@dataclass
class SearchStep:
    iteration: int
    reading_deg: dict[str, float]
    measured: np.ndarray  # (2,) in SearchResult.unit
    seconds: float = 0.0
    flags: dict = field(default_factory=dict)


@dataclass
class SearchResult:
    face: str
    unit: str  # "px" (diaphragm offset) or "arcsec" (autocollimator reading)
    free_axes: list[str]
    threshold: float
    steps: list[SearchStep]
    converged: bool
    final_reading_rad: TurntableReading
    message: str = ""

    @property
    def n_frames(self) -> int:
        return len(self.steps)

    @property
    def final_measured(self) -> np.ndarray:
        return self.steps[-1].measured


def numerical_jacobian(model: Callable[[Mapping], np.ndarray], reading_rad: Mapping, free: list[str],
                       h_rad: float = 1e-6) -> np.ndarray:
    """∂model/∂reading (model units per rad) by central differences over the free axes."""
    J = np.empty((2, len(free)))
    for j, a in enumerate(free):
        p, m = dict(reading_rad), dict(reading_rad)
        p[a] += h_rad
        m[a] -= h_rad
        J[:, j] = (np.asarray(model(p)) - np.asarray(model(m))) / (2.0 * h_rad)
    return J


def _quantise(x: float, step: float, origin: float = 0.0) -> float:
    """Commands are whole steps from the start reading (a relative move of k increments)."""
    return x if step <= 0 else origin + round((x - origin) / step) * step


def null_search(
    measure: Callable[[TurntableReading], tuple[np.ndarray, dict]],
    model: Callable[[Mapping], np.ndarray],
    start_reading_rad: Mapping[str, float],
    free: list[str],
    *,
    face: str,
    unit: str,
    threshold: float,
    command_resolution_rad: float = 0.0,
    max_iterations: int = 15,
    progress: Callable[[int], None] | None = None,
) -> SearchResult:
    """Run the feedback loop (module docstring). ``measure(reading)`` → (measured (2,), flags); it
    raises :class:`~rigsim.errors.SearchError` when nothing can be measured. ``model(reading)`` is
    the operator's nominal prediction (same units as ``measure``)."""
    if not (threshold > 0):
        raise ValueError(f"threshold = {threshold!r}: must be > 0")
    q = float(command_resolution_rad)
    r = dict(as_reading(start_reading_rad))
    origin = dict(r)
    steps: list[SearchStep] = []
    converged = False
    message = ""
    visited = set()
    for it in range(int(max_iterations)):
        t0 = time.perf_counter()
        m, flags = measure(TurntableReading(r))
        m = np.asarray(m, float)
        steps.append(SearchStep(it, {k: math.degrees(v) for k, v in r.items()}, m, time.perf_counter() - t0,
                                dict(flags)))
        if progress:
            progress(1)
        if np.all(np.abs(m) < threshold):
            converged = True
            break
        J = numerical_jacobian(model, r, free)
        dx, *_ = np.linalg.lstsq(J, -m, rcond=None)
        new = dict(r)
        for a, d in zip(free, dx):
            new[a] = _quantise(r[a] + float(d), q, origin[a])
        key = tuple(round((new[a] - origin[a]) / q) if q > 0 else new[a] for a in free)
        if key in visited or all(new[a] == r[a] for a in free):
            # the rounded Newton step lands where we have been: step the axis whose predicted
            # effect is largest by one command increment in the right direction
            if q <= 0:
                message = "the feedback step vanished before the threshold was reached"
                break
            effect = np.abs(J * q).sum(axis=0)
            j = int(np.argmax(effect))
            new = dict(r)
            new[free[j]] = r[free[j]] + math.copysign(q, float(dx[j]) if dx[j] != 0 else 1.0)
        visited.add(tuple(round((r[a] - origin[a]) / q) if q > 0 else r[a] for a in free))
        r = new
    else:
        message = f"not below {threshold:g} {unit} after {max_iterations} frames"
    if not converged and not message:
        message = f"not below {threshold:g} {unit} after {len(steps)} frames"
    return SearchResult(face, unit, list(free), float(threshold), steps, converged, TurntableReading(r), message)


# ------------------------------------------------------------------ the operators' nominal models

def reflected_offset_mm(n_rot: np.ndarray, d_rot: np.ndarray, lever_mm: float) -> np.ndarray:
    """Where the beam (−d) reflected by a face of normal n lands on a screen ⟂ d at ``lever_mm``
    from the face, relative to the hole (screen axes X′, Y′), for a lab frame with d ≈ +Z′."""
    n = n_rot / np.linalg.norm(n_rot)
    r = 2.0 * float(d_rot @ n) * n - d_rot
    return lever_mm * r[:2] / r[2]


def offset_model(rig: CubeMirrorRig, start_reading_rad: Mapping, axis_order: str | None = None
                 ) -> Callable[[Mapping], np.ndarray]:
    """Seed 000: the operator's nominal prediction of the hole/spot offset (aiming-camera px) vs the
    turntable reading (rad): ideal turntable (nesting ``axis_order``), nominal beam along +Z′, the
    face's normal estimated as R_nom(start)ᵀ·d (the face is assumed nulled at the start)."""
    nom = TurntableModel.nominal_for(rig.turntable, axis_order)
    n_mount = nom.R_rot_from_mount(as_reading(start_reading_rad)).T @ NOMINAL_D
    L = rig.diaphragm_screen.distance_to_cube_mm
    px = rig.aiming_camera.object_pixel_mm

    def model(reading_rad: Mapping) -> np.ndarray:
        return reflected_offset_mm(nom.R_rot_from_mount(reading_rad) @ n_mount, NOMINAL_D, L) / px

    return model


def reading_model(rig: CubeMirrorRig, face: str, start_reading_rad: Mapping[str, float],
                  axis_order: str | None = None) -> Callable[[Mapping], np.ndarray]:
    """Seed 001: the operator's nominal prediction of the autocollimator reading (arcsec) vs the
    turntable reading (rad): ideal turntable (nesting ``axis_order``), axis along +Z′ with the A
    frame built from it as the layout does, and the face's normal in the mount estimated as
    R_nom(start)ᵀ·d (the face is assumed nulled at the start). Zero at the start."""
    if face not in rig.procedure.faces:
        raise ValueError(f"face {face!r} is not one of the procedure's faces {rig.procedure.faces}")
    tt = TurntableModel.nominal_for(rig.turntable, axis_order)
    R = a_frame_basis(NOMINAL_D)
    n_est = tt.R_rot_from_mount(as_reading(start_reading_rad)).T @ NOMINAL_D

    def model(reading_rad: Mapping) -> np.ndarray:
        return exact_reading_rad(R, tt.R_rot_from_mount(reading_rad) @ n_est) * ARCSEC_PER_RAD

    return model
