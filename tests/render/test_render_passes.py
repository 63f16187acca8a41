"""A render of more light paths than one Mitsuba pass holds (2^32 wavefront lanes; Mitsuba's own split fails
with the ldsampler) runs in equal passes with their own seeds, averaged: the same estimator."""

import numpy as np
import pytest

from rigsim.errors import CliError
from rigsim.render import scene as scene_mod
from rigsim.render.scene import PASS_SAMPLES, render_passes

pytestmark = pytest.mark.render


@pytest.mark.parametrize("spp,pixels,expect", [
    (1024, 1024 * 1024, (1, 1024)),                 # 2^30 paths: one pass
    (4096, 1024 * 1024, (4, 1024)),                 # powers of 4 stay powers of 4
    (65536, 2048 * 2048, (256, 256)),
    (8, 2**28, (2, 4)),                              # a power of 2 (independent sampler)
    (1, 2**31, None),                                # one path per pixel on 2^31 pixels: nothing to split
    (3, 2**29, (3, 1)),
    (6, 2**29, (3, 2)),
])
def test_render_passes(spp, pixels, expect):
    if expect is None:
        with pytest.raises(CliError, match="cannot be split"):
            render_passes(spp, pixels)
    else:
        passes, per = render_passes(spp, pixels)
        assert (passes, per) == expect and passes * per == spp and per * pixels <= PASS_SAMPLES


def test_a_render_in_passes_is_the_same_estimator(monkeypatch):
    """The chessboard target through the default sun sensor's camera at 16 spp in one pass and in 4 passes of
    4 spp: the mean flux agrees to the Monte-Carlo noise (thousands of lit pixels: < 0.1 %), and the images differ
    only by noise."""
    from rigsim.optics.targets import parse_target
    from rigsim.procedures.target_commands import spread_for_camera
    from rigsim.render.target import TargetScene
    from rigsim.rig.load import load_rig

    rig = load_rig("sun_sensor_2axis_diaphragm")
    t = parse_target("chessboard:8x6:10")
    pose = spread_for_camera(rig, t, 1, camera="sun-sensor", seed=1)
    ts = TargetScene(rig.sun_sensor.camera(), t, rig.sun_sensor.detector, spp=16)
    state = {"pose": (np.asarray(pose.rvec_deg[0], float), np.asarray(pose.tvec_mm[0], float)), "window_origin": (0, 0)}
    one = ts.scene.render(state, seed=3, spp=16)
    calls = []
    monkeypatch.setattr(scene_mod, "PASS_SAMPLES", 4 * one.size)
    many = ts.scene.render(state, seed=3, spp=16, progress=lambda k, n: calls.append((k, n)))
    assert calls[-1] == (4, 4)
    assert not np.array_equal(one, many)
    lit = one > 0.5 * one.max()
    assert abs(many[lit].mean() / one[lit].mean() - 1) < 0.01
