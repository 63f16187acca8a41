"""Seed 001 steps A and C on rendered autocollimator frames (or a fast surrogate of them).

Step A — align the autocollimator on the inner-frame plane mirror. Every turntable axis *reads*
zero (true pose :func:`~rigsim.optics.autocollimator.reference_pose_rad`). The instrument starts
pointing along ``tilt(NOMINAL_D, N(0, setup_error_arcsec, 2))``. Loop: render the plane mirror
with the instrument's current (true) axis, centroid the spot on the DN frame, convert it to a
reading; if both components are below the threshold, stop; otherwise the operator turns the
instrument on its legs so that its axis goes to the normal the reading implies. The final axis
is the reference direction d of step C.

Step C — null one cube face: :func:`~rigsim.estimation.null_search.null_search` on the middle (X′)
and outer (Y′) axes, starting at ``procedure.search_start_deg``, measuring the autocollimator's
two readings (arcsec) and stepping with the Jacobian of the operator's *nominal* model
(:func:`reading_model`). The readings of the turntable at the null are θ1, θ2 (θ3, θ4).

Model choices (docs/autocollimation.md):

* relative moves are exact: the turntable and the instrument's legs put the axis where the
  operator asks, to far better than the reading's 0.1″. The turntable's absolute error is in
  its *reading* (encoder bias + one error per face search, as in the analytic campaign:
  reading = true + bias + error); the axes that are not adjusted are set and read exactly;
* the reading error is what the instrument makes of the rendered frame: Mitsuba's Monte-Carlo
  noise, the detector (shot, read, fixed-pattern noise, quantisation), the centroid (thresholded
  centre of mass on a DN frame, no truth; a projected cross-hair, recognised on the frame by its
  size, by two line fits: :func:`rigsim.imaging.reticle.measure_reticle`) and the instrument's calibration (exact for a large
  flat mirror, 0.09 % high on a 25 mm cube face away from null);
* ``rendered=False`` is the surrogate for Monte-Carlo budgets: reading = the exact reading
  (closed form from the true normal and the true axis, the instrument's convention)
  + N(0, reading_sigma_arcsec) per component, and the same range check as the frame pipeline.

Estimation never sees truth here: the feedback uses only readings and the nominal model. The
truth (exact readings) is carried alongside for the logs and the tests.
"""

from __future__ import annotations

import math
import tempfile
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from rigsim.errors import SearchError
from rigsim.estimation.null_search import reading_model
from rigsim.frames import ARCSEC_PER_RAD, RAD_PER_ARCSEC
from rigsim.imaging.reticle import measure_reticle
from rigsim.imaging.spot import SpotMeasurement, measure_spot
from rigsim.optics.autocollimator import a_frame_basis, exact_reading_rad, normal_from_reading
from rigsim.procedures.cube_mirror.null_files import autocollimator_roi_px, read_autocollimator
from rigsim.procedures.cube_mirror.nulls import TracedSearch, traced_search
from rigsim.rig.cube_mirror import CubeMirrorRig
from rigsim.rig.turntable import NOMINAL_D, TurntableReading, pose_deg_to_rad
from rigsim.truth.cube_mirror.realization import Realization, tilt

__all__ = ["DEFAULT_SPP", "FaceReadingMeasurer", "StepAResult", "autocollimator_face_search", "step_a_align"]

DEFAULT_SPP = 1024
"""Stratified samples per pixel of the rendered frames (the renderer's default; 0.005 px rms
rendering noise on the spot centroid, docs/render_autocollimator.md)."""


def _fmt_pose(pose_rad: Mapping[str, float]) -> str:
    return ", ".join(f"{k} = {math.degrees(v):.5f}°" for k, v in pose_rad.items())


def _derived_seed(seed: int, k: int) -> int:
    """Seed of the k-th frame of a run started with ``seed`` (reproducible, independent streams)."""
    return int(np.random.SeedSequence([int(seed), int(k)]).generate_state(1)[0] & 0x7FFFFFFF)


def _range_half_rad(rig: CubeMirrorRig, margin_px: float) -> np.ndarray:
    """Half measuring range (θx, θy) keeping the spot centre ``margin_px`` inside the detector
    (paraxial: offset = f·tan(2θ)), as the frame pipeline needs it (half its centroid window,
    :func:`autocollimator_roi_px`)."""
    ac = rig.autocollimator
    pitch = ac.pixel_pitch_um * 1e-3
    W, H = ac.resolution_px
    return np.array([0.5 * math.atan(max(0.5 * W - margin_px, 0.0) * pitch / ac.focal_length_mm),
                     0.5 * math.atan(max(0.5 * H - margin_px, 0.0) * pitch / ac.focal_length_mm)])


def _optics(rig: CubeMirrorRig):
    from rigsim.optics.autocollimator import AutocollimatorOptics
    from rigsim.rig.effects_autocollimator import beam_splitter_of

    return AutocollimatorOptics(rig.autocollimator, beam_splitter=beam_splitter_of(rig))


# ------------------------------------------------------------------------------ step A
@dataclass
class StepAResult:
    """Step A: the autocollimator aligned on the plane mirror.

    ``axis_rot`` is the instrument's *true* final axis (unit, rot frame, from the mirror towards
    the instrument): what step C uses. ``axes_rot[k]`` is the axis while frame k was taken;
    ``measured_arcsec[k]`` its reading (from the frame, or the surrogate), ``exact_arcsec[k]`` the
    exact reading (truth: the plane mirror's true normal in that A frame)."""

    axis_rot: np.ndarray
    initial_axis_rot: np.ndarray
    plane_mirror_normal_rot: np.ndarray  # truth, for the log
    axes_rot: np.ndarray  # (n, 3)
    measured_arcsec: np.ndarray  # (n, 2)
    exact_arcsec: np.ndarray  # (n, 2)
    converged: bool
    threshold_arcsec: float
    rendered: bool
    seconds: float
    frame_seconds: list[float] = field(default_factory=list)
    build_seconds: list[float] = field(default_factory=list)  # renderer builds (rendered only)
    frame_info: list[dict] = field(default_factory=list)
    message: str = ""

    @property
    def n_frames(self) -> int:
        return len(self.measured_arcsec)

    @property
    def axis_error_arcsec(self) -> float:
        """Angle between the final axis and the plane mirror's true normal (truth)."""
        c = float(np.clip(self.axis_rot @ self.plane_mirror_normal_rot, -1.0, 1.0))
        return math.degrees(math.acos(c)) * 3600.0

    def as_dict(self) -> dict:
        return {"axis_rot": self.axis_rot.tolist(), "initial_axis_rot": self.initial_axis_rot.tolist(),
                "axis_error_arcsec": self.axis_error_arcsec, "converged": self.converged,
                "threshold_arcsec": self.threshold_arcsec, "rendered": self.rendered, "seconds": self.seconds,
                "message": self.message,
                "frames": [{"axis_rot": a.tolist(), "measured_arcsec": m.tolist(), "exact_arcsec": e.tolist(),
                            "seconds": s, **inf}
                           for a, m, e, s, inf in zip(self.axes_rot, self.measured_arcsec, self.exact_arcsec,
                                                      self.frame_seconds, self.frame_info)]}


def step_a_align(rig: CubeMirrorRig, real: Realization, rng: np.random.Generator, *, rendered: bool = True,
                 reading_sigma_arcsec: float = 0.0, max_iterations: int | None = None,
                 threshold_arcsec: float | None = None, spp: int | None = None, noiseless: bool = False,
                 progress: Callable[[int], None] | None = None) -> StepAResult:
    """Seed 001 step A (module docstring). ``rng`` draws the instrument's initial pointing
    (``rig.autocollimator.setup_error_arcsec`` 1σ per axis) and one base seed for the frames
    (the detector noise and Mitsuba) or the surrogate's reading noise; the same generator state
    gives the same result. ``noiseless`` drops the detector's random terms (rendered only).
    The operator re-aims the instrument after every frame that does not read below
    ``threshold_arcsec`` (default ``rig.autocollimator.null_threshold_arcsec``), at most
    ``max_iterations`` frames (default ``rig.procedure.max_search_iterations``); not converging
    is reported (``converged = False``, ``message``), not raised. Raises :class:`SearchError`
    when a frame has no measurable spot."""
    if rig.autocollimator is None or rig.plane_mirror is None or real.plane_mirror_normal_mount is None:
        raise ValueError(f"rig {rig.name!r}: step A needs an autocollimator and a plane mirror on the inner frame")
    from rigsim.truth.cube_mirror.autocollimator import reference_pose_rad

    ac = rig.autocollimator
    thr = float(ac.null_threshold_arcsec if threshold_arcsec is None else threshold_arcsec)
    if not thr > 0:
        raise ValueError(f"threshold_arcsec = {threshold_arcsec!r}: must be > 0")
    n_max = int(rig.procedure.max_search_iterations if max_iterations is None else max_iterations)
    if n_max < 1:
        raise ValueError(f"max_iterations = {max_iterations!r}: must be >= 1")
    if reading_sigma_arcsec < 0:
        raise ValueError(f"reading_sigma_arcsec = {reading_sigma_arcsec!r}: must be >= 0")
    spp = DEFAULT_SPP if spp is None else int(spp)
    t_start = time.perf_counter()
    setup = rng.normal(0.0, ac.setup_error_arcsec * RAD_PER_ARCSEC, 2)
    base_seed = int(rng.integers(2**31))
    d = tilt(NOMINAL_D, setup)
    d0 = d.copy()
    pose = reference_pose_rad(rig, real)
    pm = real.turntable.R_rot_from_mount(pose) @ real.plane_mirror_normal_mount
    pm /= np.linalg.norm(pm)
    roi_px = autocollimator_roi_px(rig, "plane_mirror")
    half = _range_half_rad(rig, roi_px / 2.0)
    axes, meas, exact, secs, builds, info = [], [], [], [], [], []
    converged = False
    message = ""
    optics = _optics(rig) if rendered else None
    source_photons = None
    with tempfile.TemporaryDirectory(prefix="rigsim_stepA_") as mesh_dir:
        for k in range(n_max):
            t0 = time.perf_counter()
            R = a_frame_basis(d)
            ex = exact_reading_rad(R, pm)
            fi: dict = {"seed": _derived_seed(base_seed, k)}
            if rendered:
                from rigsim.render.cube_mirror.autocollimator import AutocollimatorRenderer
                from rigsim.truth.cube_mirror.autocollimator import autocollimator_layout

                tb = time.perf_counter()
                layout = autocollimator_layout(rig, real, "plane_mirror", axis_rot=d,
                                               objective_vertex_z_mm=optics.objective.z_vertex)
                # the instrument moved: a new layout, so a new scene (0.2-0.3 s against ~1 s per
                # frame; docs/autocollimation.md). Brightness stays as set on the first frame.
                r = AutocollimatorRenderer(rig, real, "plane_mirror", spp=spp, optics=optics, layout=layout,
                                           source_photons=source_photons, mesh_dir=mesh_dir)
                source_photons = r.source_photons
                builds.append(time.perf_counter() - tb)
                with warnings.catch_warnings(record=True) as wl:
                    warnings.simplefilter("always")
                    frame = r.render_frame(pose, seed=fi["seed"], noiseless=noiseless)
                sm = measure_spot(frame.dn, ac.detector, roi_px=roi_px)
                sm = measure_reticle(frame.dn, sm, roi_px) or sm  # a cross-hair: its centre, not its centroid
                fi.update(_frame_info(frame, sm, wl))
                if not sm.ok:
                    raise SearchError(
                        f"step A (plane mirror): {sm.problem} at frame {k}, all axes reading zero "
                        f"(true pose {_fmt_pose(pose)}); exact reading ({ex[0] * ARCSEC_PER_RAD:+.2f}″, "
                        f"{ex[1] * ARCSEC_PER_RAD:+.2f}″); truth flags: {_true_flags(frame)}. "
                        "Reduce autocollimator.setup_error_arcsec or check the plane mirror's tilt")
                m = optics.reading(sm.uv)
            else:
                if np.any(np.abs(ex) > half):
                    raise SearchError(
                        f"step A (plane mirror): the spot is off the detector at frame {k} (exact reading "
                        f"({ex[0] * ARCSEC_PER_RAD:+.1f}″, {ex[1] * ARCSEC_PER_RAD:+.1f}″) beyond the measuring "
                        f"range ±{half[0] * ARCSEC_PER_RAD:.0f}″ × ±{half[1] * ARCSEC_PER_RAD:.0f}″); reduce "
                        "autocollimator.setup_error_arcsec")
                noise = np.random.default_rng(fi["seed"]).normal(0.0, reading_sigma_arcsec * RAD_PER_ARCSEC, 2)
                m = ex + noise
            axes.append(d.copy())
            meas.append(np.asarray(m, float) * ARCSEC_PER_RAD)
            exact.append(ex * ARCSEC_PER_RAD)
            secs.append(time.perf_counter() - t0)
            info.append(fi)
            if progress:
                progress(1)
            if np.all(np.abs(meas[-1]) < thr):
                converged = True
                break
            # the operator turns the instrument onto the normal its reading implies
            d = normal_from_reading(R, m)
        else:
            message = f"step A: not below {thr:g}″ after {n_max} frames"
    # not converged: the instrument stays where the last frame was taken (its reading is known)
    final = axes[-1]
    return StepAResult(final, d0, pm, np.array(axes), np.array(meas), np.array(exact), converged, thr,
                       bool(rendered), time.perf_counter() - t_start, secs, builds, info, message)


def _true_flags(frame) -> list[str]:
    f = frame.sidecar.get("flags", {})
    return sorted(k for k, v in f.items() if v is True) or ["none"]


def _frame_info(frame, sm: SpotMeasurement, wl) -> dict:
    return {"uv": None if sm.uv is None else [float(x) for x in sm.uv], "centroid_flags": int(sm.flags),
            "n_detections": int(sm.n_detections), "peak_dn": float(sm.peak_dn),
            "background_dn": float(sm.background_dn), "background_rms_dn": float(sm.background_rms_dn),
            "render_seconds": float(frame.extra["window"].seconds), "truth_flags": _true_flags(frame),
            "warnings": [str(w.message) for w in wl]}


# ------------------------------------------------------------------------------ step C
class FaceReadingMeasurer:
    """``measure(true_pose_rad) -> (measured_arcsec (2,), exact_arcsec (2,), info dict)`` for
    cube face ``face`` seen by an autocollimator whose true axis is ``axis_rot`` (step A's).

    ``rendered=True``: render the DN frame (Mitsuba + detector; ``noiseless`` drops the
    detector's random terms), centroid it (:func:`measure_spot`, no truth; ``spot_method="model"``:
    the spot's forward-model fit, :func:`read_autocollimator`; ``"model_renderer"``: the same with the
    image as rigsim's renderer draws it) and convert with the
    instrument's calibrated reading. ``rendered=False``: the exact reading +
    N(0, ``reading_sigma_arcsec``) per component. Call k uses the seed derived from (``seed``, k):
    a run is reproducible from ``seed``. Raises :class:`SearchError` naming the face and the pose
    when there is no usable spot (off the detector or at its edge, beam missing the face,
    saturated frame, spot larger than the render window): never a wrong centroid."""

    def __init__(self, rig: CubeMirrorRig, real: Realization, face: str, axis_rot, *, rendered: bool = True,
                 reading_sigma_arcsec: float = 0.0, seed: int = 0, spp: int | None = None,
                 noiseless: bool = False, optics=None, mesh_dir=None, on_frame=None, spot_method: str = "tcom"):
        if rig.autocollimator is None:
            raise ValueError(f"rig {rig.name!r} has no autocollimator")
        if face not in real.face_normals_mount:
            raise ValueError(f"face {face!r} has no true normal in this realisation (faces: {sorted(real.face_normals_mount)})")
        if reading_sigma_arcsec < 0:
            raise ValueError(f"reading_sigma_arcsec = {reading_sigma_arcsec!r}: must be >= 0")
        self.rig, self.real, self.face = rig, real, face
        self.axis_rot = np.asarray(axis_rot, float) / np.linalg.norm(axis_rot)
        self.R_rot_from_A = a_frame_basis(self.axis_rot)
        self.rendered = bool(rendered)
        self.reading_sigma_arcsec = float(reading_sigma_arcsec)
        self.seed = int(seed)
        self.noiseless = bool(noiseless)
        if spot_method not in ("tcom", "model", "model_renderer"):
            raise ValueError(f"spot_method = {spot_method!r}: 'tcom', 'model' or 'model_renderer'")
        self.spot_method = spot_method  # read_autocollimator's method; "model_renderer": the model of rigsim's frames
        self.calls = 0
        self.on_frame = on_frame  # on_frame(kind, dn, info): every rendered frame with the reading it was taken at
        self.last_reading: dict = {}
        self.roi_px = autocollimator_roi_px(rig, "face")
        self.half_range_rad = _range_half_rad(rig, self.roi_px / 2.0)
        self.renderer = None
        self.build_seconds = 0.0
        if self.rendered:
            from rigsim.render.cube_mirror.autocollimator import AutocollimatorRenderer
            from rigsim.truth.cube_mirror.autocollimator import autocollimator_layout

            t0 = time.perf_counter()
            self.optics = optics or _optics(rig)
            layout = autocollimator_layout(rig, real, "face", face, axis_rot=self.axis_rot,
                                           objective_vertex_z_mm=self.optics.objective.z_vertex)
            self.renderer = AutocollimatorRenderer(rig, real, "face", face, spp=DEFAULT_SPP if spp is None else int(spp),
                                                   optics=self.optics, layout=layout, mesh_dir=mesh_dir)
            self.build_seconds = time.perf_counter() - t0

    def exact_rad(self, true_pose_rad: Mapping[str, float]) -> np.ndarray:
        n = self.real.turntable.R_rot_from_mount(dict(true_pose_rad)) @ self.real.face_normals_mount[self.face]
        return exact_reading_rad(self.R_rot_from_A, n / np.linalg.norm(n))

    def _fail(self, problem: str, pose: Mapping[str, float], ex: np.ndarray, flags: str = "") -> SearchError:
        h = self.half_range_rad * ARCSEC_PER_RAD
        return SearchError(
            f"face {self.face}: {problem} at the true turntable pose {_fmt_pose(pose)} (exact reading "
            f"({ex[0] * ARCSEC_PER_RAD:+.1f}″, {ex[1] * ARCSEC_PER_RAD:+.1f}″), usable range ±{h[0]:.0f}″ × "
            f"±{h[1]:.0f}″{'; truth flags: ' + flags if flags else ''}). Start the search nearer this face's "
            "null: set procedure.search_start_deg in the rig file")

    def __call__(self, true_pose_rad: Mapping[str, float]):
        k = self.calls
        self.calls += 1
        seed = _derived_seed(self.seed, k)
        pose = dict(true_pose_rad)
        ex = self.exact_rad(pose)
        info: dict = {"seed": seed}
        if not self.rendered:
            if np.any(np.abs(ex) > self.half_range_rad):
                raise self._fail("the return spot is off the detector", pose, ex)
            m = ex * ARCSEC_PER_RAD + np.random.default_rng(seed).normal(0.0, self.reading_sigma_arcsec, 2)
            return m, ex * ARCSEC_PER_RAD, info
        with warnings.catch_warnings(record=True) as wl:
            warnings.simplefilter("always")
            frame = self.renderer.render_frame(pose, seed=seed, noiseless=self.noiseless)
        m, _sig, sm = read_autocollimator(self.rig, frame.dn, self.optics, "face",  # the `rigsim autocollimator read` stage
                                          method="tcom" if self.spot_method == "tcom" else "model",
                                          construction="renderer" if self.spot_method == "model_renderer" else "optics")
        rm = measure_reticle(frame.dn, sm, self.roi_px)
        if rm is not None:  # the instrument projects a cross-hair: its centre from two line fits
            sm = rm
            m = self.optics.reading(rm.uv) * ARCSEC_PER_RAD if rm.ok else np.full(2, np.nan)
        info.update(_frame_info(frame, sm, wl))
        if self.on_frame is not None:
            self.on_frame("autocollimator", frame.dn, {"reading_deg": {a: math.degrees(v) for a, v in self.last_reading.items()},
                                                       "measured_arcsec": m.tolist(), "face": self.face})
        if not sm.ok:
            raise self._fail(sm.problem, pose, ex, ", ".join(info["truth_flags"]))
        if frame.sidecar["flags"].get("spot_exceeds_window"):
            # a limit of the simulator (its render window, derived from the geometric spot at the
            # reference pose), not of the instrument
            raise self._fail(f"the spot is larger than the {self.renderer.window_px} px render window (simulator limit)",
                             pose, ex, ", ".join(info["truth_flags"]))
        return m, ex * ARCSEC_PER_RAD, info


def autocollimator_face_search(rig: CubeMirrorRig, real: Realization, face_index: int, axis_rot,
                               encoder_error_rad: Mapping[str, float] | None, *, rendered: bool = True,
                               seed: int = 0, reading_sigma_arcsec: float = 0.0, spp: int | None = None,
                               noiseless: bool = False, axis_order: str | None = None,
                               progress: Callable[[int], None] | None = None, on_frame=None) -> TracedSearch:
    """Seed 001 step C for face ``rig.procedure.faces[face_index]``: null it on the
    autocollimator whose true axis is ``axis_rot`` by fine-tuning the middle (X′) and outer (Y′)
    axes (:func:`null_search`). Starts at ``procedure.search_start[face_index]`` (readings);
    threshold ``autocollimator.null_threshold_arcsec``; ``procedure.command_resolution_deg``
    and ``max_search_iterations``. Turntable: reading = true + ``real.encoder_bias_rad`` +
    ``encoder_error_rad`` (drawn once per face search by the caller) on X and Y; the other axes
    are set and read exactly. The result's ``final_reading_rad`` holds θ1, θ2 (θ3, θ4)."""
    proc = rig.procedure
    if not (0 <= face_index < len(proc.faces)):
        raise ValueError(f"face_index = {face_index!r}: must be in [0, {len(proc.faces) - 1}]")
    face = proc.faces[face_index]
    labels = {a.label for a in rig.turntable.axes}
    free = [lab for lab in ("X", "Y") if lab in labels]
    if len(free) != 2:
        raise ValueError(f"rig {rig.name!r}: step C adjusts the X′ and Y′ axes, the turntable has {sorted(labels)}")
    start = TurntableReading(pose_deg_to_rad(proc.search_start[face_index]))
    base = real.reading_to_true(dict(encoder_error_rad or {}), free)
    last: dict = {}

    def reading_to_true(r):
        last.clear()
        last.update(r)
        return base(r)

    measure = FaceReadingMeasurer(rig, real, face, axis_rot, rendered=rendered,
                                  reading_sigma_arcsec=reading_sigma_arcsec, seed=seed, spp=spp, noiseless=noiseless,
                                  on_frame=on_frame)
    model = reading_model(rig, face, start, axis_order)
    try:
        res = traced_search(measure, model, start, free, reading_to_true, face=face, unit="arcsec",
                            threshold=rig.autocollimator.null_threshold_arcsec,
                            command_resolution_rad=math.radians(proc.command_resolution_deg),
                            max_iterations=proc.max_search_iterations, progress=progress)
    except SearchError as e:
        raise SearchError(f"{e} [turntable reading {_fmt_pose(last)}]") from e
    return res
