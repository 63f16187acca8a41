"""One frame of every kind a cube-mirror rig makes, rendered and measured by the file stages against the
renderer's truth (the random-rig render tests and the documented custom rig's)."""

import math
import warnings

import numpy as np

AC_SPP = 64
# The render's Monte-Carlo noise on the spot's centroid, per axis: 0.035 px at 64 spp (measured over seeds on
# two random rigs of 5.7 and 10.4 px rms radius: 0.02-0.04 px typical, one seed 0.125 px; 0.02 px at 256 spp).
# It hardly depends on the spot's size: the samples grow with its area as its spread does. Radially, 4.3 σ is
# exceeded with a 1e-4 chance per rig. The 0.5 % of the rms radius allows for the thresholded centroid's bias
# on an aberrated spot's faint, asymmetric halo.
AC_TOLERANCE_PX = 4.3 * 0.035 * math.sqrt(64 / AC_SPP)
# The instrument's factory calibration (six traced tilts) only turns a spot into a reading, and no reading is
# checked here: 40 000 rays per tilt instead of the default 400 000 run the same code over the same tilts (the
# failure modes these rigs once found: no light back at a tilt) for a tenth of the trace, which was a third of
# an autocollimator rig's time.
AC_CALIBRATION_RAYS = 40_000


def render_every_kind(rig) -> dict:
    """One frame of every kind the rig makes, each measured by its file stage against its truth."""
    from rigsim.imaging.frame_spots import measure_frame, single_spot
    from rigsim.optics.targets import parse_target, project_target
    from rigsim.procedures.centroid import detector_settings
    from rigsim.procedures.target_commands import spread_for_camera
    from rigsim.render.cube_mirror.sun_sensor import SunSensorScene
    from rigsim.render.target import TargetScene
    from rigsim.truth.cube_mirror.realization import realization_from_rig

    real = realization_from_rig(rig)
    out = {}
    # sun sensor: the sweep's centre pose (on the detector by construction of the sweep)
    fr = SunSensorScene(rig, real, spp=4).render({a.label: 0.0 for a in rig.turntable.axes}, seed=1, truth_points=20_000)
    spot = fr.sidecar["truth"]["spot"]
    det = detector_settings(rig, "sun-sensor")
    sp = measure_frame(fr.dn, det.noise, saturation_dn=det.saturation_dn)
    k = single_spot(sp)
    assert k is not None, fr.sidecar["flags"]
    out["sun-sensor"] = float(np.hypot(sp.u[k] - spot["center_uv"][0], sp.v[k] - spot["center_uv"][1]))
    # a chessboard through the sun sensor's true camera
    t = parse_target("chessboard:8x6:10")
    pose = spread_for_camera(rig, t, 1, camera="sun-sensor", seed=1)
    cam = rig.sun_sensor.camera()
    tf = TargetScene(cam, t, rig.sun_sensor.detector, spp=1).render(pose.rvec_deg[0], pose.tvec_mm[0], seed=1)
    _, vis = project_target(cam, t.points_mm, pose.rvec_deg[0], pose.tvec_mm[0])
    out["target"] = int(vis.sum())
    assert tf.dn.shape == (cam.height, cam.width) and vis.sum() > 0 and tf.dn.max() > tf.dn.min()
    if rig.procedure.method == "diaphragm":
        from rigsim.optics.screen_return import visible_return_centre_mm
        from rigsim.procedures.cube_mirror.null_files import measure_concentricity
        from rigsim.render.cube_mirror.aiming import ConcentricityRenderer
        from rigsim.truth.cube_mirror.placement import diaphragm_layout

        p = dict(diaphragm_layout(rig, real, 0).null_pose_rad)
        first = next(iter(p))
        p[first] += math.radians(10.0 / 3600.0)
        renderer = ConcentricityRenderer(rig, real, 0, spp=1)
        af = renderer.render(p, seed=1, warn=False)
        m = measure_concentricity(rig, af.hole.dn, af.spot.dn)
        # the light lost into the hole pulls the measured centre away from it: by 3 % of the offset on the
        # default rig, by 90 % when the divergence blur is no larger than the hole (a short screen distance)
        op = rig.aiming_camera.object_pixel_mm
        ex = visible_return_centre_mm(af.truth.offset_mm, renderer.geometry.hole_radius_mm, renderer.R_div_mm) / op
        out["aiming-camera"] = float(np.hypot(*(m["offset_px"] - ex)))
        assert out["aiming-camera"] < 0.5 + 0.02 * np.hypot(*ex), (m["offset_px"], ex)
    else:
        from rigsim.procedures.cube_mirror.null_files import read_autocollimator
        from rigsim.render.cube_mirror.autocollimator import AutocollimatorRenderer

        r = AutocollimatorRenderer(rig, real, "face", rig.procedure.faces[0], spp=AC_SPP, truth_rays=20_000)
        r.optics.calibration(n_rays=AC_CALIBRATION_RAYS)  # cached: the frame's truth and the reading use it
        p = dict(r.layout.reference_pose_rad)
        first = next(iter(p))
        p[first] += math.radians(20.0 / 3600.0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            af = r.render_frame(p, seed=1)
        m, _s, sm = read_autocollimator(rig, af.dn, r.optics)  # the same instrument: its calibration is reused
        tr, flags = af.sidecar["truth"], af.sidecar["flags"]
        if any(flags.get(k) for k in ("return_vignetted", "beam_partly_misses_face", "beam_misses_face")):
            # the truth warns that the beam is cut (a fast or small objective, a small face): the spot is not
            # the instrument's calibrated one, only "no traceback" is asked of the stage
            out["autocollimator"] = float("nan")
        else:
            assert sm.ok, sm.problem
            tol = AC_TOLERANCE_PX + 0.005 * tr["spot_rms_radius_px"]
            out["autocollimator"] = float(np.hypot(*(sm.uv - np.asarray(tr["spot_pixel_centroid_uv"]))))
            assert out["autocollimator"] < tol, (sm.uv, tr["spot_pixel_centroid_uv"], tol)
    assert out["sun-sensor"] < 0.5, out
    return out


def share(d: dict, parts: int) -> int:
    """Which of ``parts`` shares the rig dictionary ``d`` falls in (stable across processes and runs)."""
    import hashlib

    return int(hashlib.sha256(repr(d).encode()).hexdigest(), 16) % parts


def rendered_rig_tests(method: str, draws: int, distinct: int, parts: int = 1, part: int = 0):
    """The two slow tests of one file: ``draws`` hypothesis rigs of ``method`` (derandomized: the same rigs in
    every run, every worker and every file — tests/conftest.py), of which this file renders the ``part``-th
    share of ``parts`` in every kind, then a check that at least ``distinct`` of those were different
    (derandomized hypothesis repeats a few draws). A rig's share is a hash of its dictionary, so the rig a
    failure reports is the one hypothesis replays. Files go to different workers of the parallel runner: a
    slow method is spread over several."""
    import pytest
    from hypothesis import given
    from random_rigs import build, draw, rig_dicts

    seen: set[str] = set()

    @pytest.mark.slow  # 216 rigs: ~15 min on 2 workers (docs/testing.md)
    @draw(draws)
    @given(rig_dicts(method))
    def renders_a_frame_of_every_kind(d):
        if share(d, parts) != part:
            return
        seen.add(repr(d))
        render_every_kind(build(d))

    @pytest.mark.slow
    def enough_different_rigs_were_rendered():
        assert len(seen) >= distinct

    return renders_a_frame_of_every_kind, enough_different_rigs_were_rendered
