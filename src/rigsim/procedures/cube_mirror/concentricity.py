"""Seed 000 steps 2–3 on rendered frames: the hole/spot concentricity search (Table 1).

* :func:`rigsim.imaging.screen.hole_spot_offset` — the image side: the hole centre on the hole
  frame (spot blocked), the spot centre on the spot frame minus the hole frame, both on the screen
  plane through the aiming camera's homography; their difference in object pixels (Table 1's x, y).
* :func:`rigsim.estimation.null_search.offset_model` — the operator's nominal prediction of the
  offset vs the turntable reading, whose Jacobian drives the feedback rule.
* :class:`OffsetMeasurer` — measure(true pose) on rendered frames, or the Monte-Carlo surrogate
  (exact offset + measured noise) used by the error budget.
* :func:`concentricity_search` — one face, start to null.

The aiming camera's mounting error (paper's σ3) enters as the equivalent null bias of the
analytic model (``Realization.null_bias_rad``): the operator's "concentric" is off by the offset
that bias produces, so the measured offset is reduced by it.
"""

from __future__ import annotations

import math

import numpy as np

from rigsim.errors import SearchError
from rigsim.estimation.null_search import offset_model, reflected_offset_mm
from rigsim.optics.aiming import nominal_screen_homography
from rigsim.procedures.cube_mirror.null_files import measure_concentricity
from rigsim.procedures.cube_mirror.nulls import TracedSearch, traced_search
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import TurntableReading, pose_deg_to_rad
from rigsim.truth.cube_mirror.realization import Realization, tilt

FREE_AXES = ("X", "Y")


def null_bias_offset_px(rig: CubeMirrorRig, real: Realization, face_index: int) -> np.ndarray:
    """The offset (px) at which the biased operator sees concentricity: the face normal tilted from
    the beam by the equivalent null bias."""
    d = real.d_sun_rot
    n = tilt(d, real.null_bias_rad[face_index])
    return reflected_offset_mm(n, d, rig.diaphragm_screen.distance_to_cube_mm) / rig.aiming_camera.object_pixel_mm


# ------------------------------------------------------------------ measurer

class OffsetMeasurer:
    """``measure(true_pose_rad) -> (measured px (2,), exact px (2,), flags)`` for one face.

    ``renderer`` (a :class:`~rigsim.render.cube_mirror.aiming.ConcentricityRenderer`): rendered frames,
    fitted by :func:`hole_spot_offset` (``spot_method="model"``: the spot by its forward model,
    :func:`measure_concentricity`). ``renderer=None``: the surrogate — the exact trace plus
    N(0, ``sigma_px``) per axis — for Monte-Carlo budgets whose noise was measured on renders.
    Raises :class:`SearchError` when the spot cannot be measured (off the detector, cut by its
    edge, beam off the face, saturated). ``geometry``: this face's
    :func:`~rigsim.truth.cube_mirror.diaphragm.diaphragm_geometry` if the caller already has it
    (its layout is then not solved again). ``flat_dn``: the mean of the screen's flat frames when
    another face's search took them (else they are rendered on first use, ``[aiming_camera] flat_frames``).
    """

    def __init__(self, rig: CubeMirrorRig, real: Realization, face_index: int, *, renderer=None, seed: int = 0,
                 sigma_px: float = 0.0, rng: np.random.Generator | None = None, noiseless: bool = False,
                 keep_frames: bool = False, on_frame=None, geometry=None, spot_method: str = "moments",
                 flat_dn: np.ndarray | None = None):
        from rigsim.truth.cube_mirror.placement import diaphragm_layout

        self.rig, self.real, self.face_index = rig, real, int(face_index)
        self.face = rig.procedure.faces[face_index]
        self.renderer = renderer
        self.seed = int(seed)
        self.sigma_px = float(sigma_px)
        self.rng = rng if rng is not None else np.random.default_rng(seed)
        self.noiseless = noiseless
        self.spot_method = spot_method  # "moments" (default) or "model": measure_concentricity's method
        self.bias_px = null_bias_offset_px(rig, real, face_index)
        self.layout = geometry.layout if geometry is not None else diaphragm_layout(rig, real, face_index)
        # the operator's screen → image homography: from the nominal aiming-camera spec only
        self.H_screen_to_uv = nominal_screen_homography(rig.aiming_camera)
        self.calls = 0
        self._geom = geometry
        self.keep_frames = keep_frames
        self.frames: list = []
        self.on_frame = on_frame  # on_frame(kind, dn, info): every rendered frame with the reading it was taken at
        self.last_reading: dict = {}
        self.flat_dn = flat_dn  # the mean flat frame (_flat); another face's search may pass its own

    def _flat(self) -> np.ndarray | None:
        """The mean of the rig's ``[aiming_camera] flat_frames`` frames of the screen under a lamp,
        rendered once (None: no flat)."""
        n = self.rig.aiming_camera.flat_frames
        if self.renderer is None or n == 0:
            return None
        if self.flat_dn is None:
            # taken once, before the first face's search, at its first reading (a flat depends on
            # neither: every face's search uses it)
            info = {"face": self.face, "reading_deg": {a: math.degrees(v) for a, v in self.last_reading.items()},
                    "null_offset_px": np.asarray(self.bias_px, float).tolist()}
            total = None
            for f in self.renderer.render_flats(n, seed=self.seed, noiseless=self.noiseless):
                if self.on_frame is not None:
                    self.on_frame("aiming-flat", f.dn, info)
                total = f.dn.astype(float) if total is None else total + f.dn
            self.flat_dn = total / n
        return self.flat_dn

    def _in_view(self, offset_px: np.ndarray) -> bool:
        """Does the divergent spot (radius hole + path·tan(α/2)) lie inside the camera's field?"""
        if self._geom is None:
            from rigsim.truth.cube_mirror.diaphragm import diaphragm_geometry

            self._geom = diaphragm_geometry(self.rig, self.real, self.face_index)
        from rigsim.render.cube_mirror.aiming import divergence_radius_mm

        g = self._geom
        R = g.hole_radius_mm + divergence_radius_mm(
            self.rig, math.radians(self.rig.sun_simulator.collimation_full_angle_arcmin / 60.0))
        c = np.asarray(offset_px, float) * self.rig.aiming_camera.object_pixel_mm
        pts = c + R * np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
        return bool(np.all(g.camera.on_detector(g.screen_to_uv(pts))))

    def exact_px(self, true_pose_rad: dict) -> np.ndarray:
        from rigsim.truth.cube_mirror.placement import trace_return_spot

        sp = trace_return_spot(self.rig, self.real, self.layout, true_pose_rad)
        return np.asarray(sp.offset_mm, float) / self.rig.aiming_camera.object_pixel_mm

    def __call__(self, true_pose_rad: dict):
        k = self.calls
        self.calls += 1
        pose_txt = ", ".join(f"{a}={math.degrees(v):.4f}°" for a, v in true_pose_rad.items())
        if self.renderer is None:
            try:
                exact = self.exact_px(true_pose_rad)
            except Exception as e:  # GeometryError from the trace
                raise SearchError(f"face {self.face}: no return spot at true pose {pose_txt}: {e}") from e
            if not self._in_view(exact):
                raise SearchError(
                    f"face {self.face}: the returned spot ({exact[0]:.0f}, {exact[1]:.0f}) px from the hole is not wholly "
                    f"in the aiming camera's view at true pose {pose_txt}. Start the search closer to the null "
                    "(procedure.search_start_deg) or widen the aiming camera's field.")
            return exact + self.rng.normal(0.0, self.sigma_px, 2) - self.bias_px, exact, {}
        fr = self.renderer.render(true_pose_rad, seed=int(np.random.SeedSequence([self.seed, k]).generate_state(1)[0]),
                                  hole_seed=self.seed, noiseless=self.noiseless, warn=False)
        bad = [f for f in ("beam_misses_face", "beam_clipped_by_face", "spot_not_returned", "spot_off_detector",
                           "spot_cut_by_edge", "hole_off_detector", "hole_cut_by_edge", "saturated") if fr.flags.get(f)]
        if bad:
            raise SearchError(
                f"face {self.face}: cannot measure the hole/spot offset at true pose {pose_txt}: {', '.join(bad)}. "
                "Start the search closer to the null (procedure.search_start_deg) or widen the aiming camera's field.")
        m = measure_concentricity(self.rig, fr.hole.dn, fr.spot.dn, method=self.spot_method,
                                  flat_dn=self._flat())  # `rigsim concentricity`
        if self.on_frame is not None:
            info = {"reading_deg": {a: math.degrees(v) for a, v in self.last_reading.items()},
                    "measured_offset_px": np.asarray(m["offset_px"]).tolist(), "face": self.face,
                    "null_offset_px": np.asarray(self.bias_px, float).tolist()}
            self.on_frame("aiming-hole", fr.hole.dn, info)
            self.on_frame("aiming-spot", fr.spot.dn, info)
        if not np.all(np.isfinite(m["offset_px"])):
            raise SearchError(f"face {self.face}: no spot found in the aiming-camera frame at true pose {pose_txt}")
        exact = np.asarray(fr.truth.offset_mm, float) / self.rig.aiming_camera.object_pixel_mm
        if self.keep_frames:
            self.frames.append(fr)
        flags = {"render_seconds": fr.seconds.get("total", 0.0), "spot_overlaps_hole": fr.flags.get("spot_overlaps_hole")}
        return m["offset_px"] - self.bias_px, exact, flags


def concentricity_search(rig: CubeMirrorRig, real: Realization, face_index: int, measure: OffsetMeasurer,
                         encoder_error_rad: dict[str, float], *, axis_order: str | None = None,
                         threshold_px: float | None = None, start_offset_rad: dict | None = None,
                         progress=None) -> TracedSearch:
    """Null one face (Table 1): start at ``procedure.search_start[face_index]`` (plus
    ``start_offset_rad``, the Monte-Carlo's scatter of the coarse alignment) and move X′, Y′."""
    proc = rig.procedure
    start = pose_deg_to_rad(proc.search_start[face_index])
    for k, v in (start_offset_rad or {}).items():
        start[k] = start.get(k, 0.0) + float(v)
    for a in rig.turntable.axes:
        start.setdefault(a.label, 0.0)
    free = [a for a in FREE_AXES if a in start]
    thr = rig.aiming_camera.concentric_threshold_px if threshold_px is None else float(threshold_px)
    start = TurntableReading(start)
    return traced_search(measure, offset_model(rig, start, axis_order), start, free,
                         real.reading_to_true(encoder_error_rad, free),
                         face=proc.faces[face_index], unit="px", threshold=thr,
                         command_resolution_rad=math.radians(proc.command_resolution_deg),
                         max_iterations=proc.max_search_iterations, progress=progress)


def table1_text(results: list[TracedSearch]) -> str:
    """The iteration log in the form of the paper's Table 1 (θ in degrees, offsets in px), with
    the exact offsets (truth) beside the measured ones."""
    lines = []
    for res in results:
        a, b = res.free_axes
        lines.append(f"face {res.face} ({'converged' if res.converged else 'NOT converged: ' + res.message})")
        u = "″" if res.unit == "arcsec" else " px"
        lines.append(f"  {'#':>2} {a + ' (°)':>11} {b + ' (°)':>10} {'x' + u:>8} {'y' + u:>8}   {'exact x':>8} {'exact y':>8}")
        for row in res.table_rows():
            lines.append(f"  {row[0]:>2} {row[1]:>11.4f} {row[2]:>10.4f} {row[3]:>8.3f} {row[4]:>8.3f}   {row[5]:>8.3f} {row[6]:>8.3f}")
    return "\n".join(lines)
