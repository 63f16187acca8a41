"""The one render loop (rigsim.render.scene) and the one frame type (rigsim.render.frame.Frame)."""

import numpy as np
import pytest

from rigsim.detector import DetectorConfig
from rigsim.optics.camera import PinholeBrown
from rigsim.render.frame import OBSERVABLE_FLAGS, Frame, Observation, digitise

pytestmark = pytest.mark.render

CAM = PinholeBrown(fx=200.0, fy=200.0, cx=31.5, cy=23.5, width=64, height=48)


def _disk(to_world):
    import mitsuba as mi

    return {"type": "disk", "to_world": mi.ScalarTransform4f(to_world),
            "emitter": {"type": "area", "radiance": {"type": "uniform", "value": 1.0}}}


def _disk_matrix(c, r=2.0):
    M = np.diag([r, r, 1.0, 1.0])
    M[2, 2] = -1.0  # facing the camera (−z)
    M[0, 0] = -r
    M[:3, 3] = c
    return M


def test_elements_update_only_what_the_state_names():
    from rigsim.render.backend import ensure_variant

    ensure_variant()
    import mitsuba as mi

    from rigsim.render.scene import Element, PinholeSensor, Scene

    calls = []

    def move(state):
        calls.append(dict(state))
        return {"disk.to_world": mi.Transform4f(_disk_matrix(state["centre"]))} if "centre" in state else {}

    sc = Scene({"type": "path", "max_depth": 1},
               [PinholeSensor(CAM, width=64, height=48, spp=16, sampler="independent", response="radiance"),
                Element("disk", _disk(_disk_matrix([0.0, 0.0, 100.0])), move)])
    a = sc.render(seed=1)
    b = sc.render({"centre": [10.0, 0.0, 100.0]}, seed=1)
    # the disk moved by f·10/100 = 20 px to the right (+u), the image moved with it
    ca, cb = (np.array([(im * np.arange(64)).sum() / im.sum(), 0.0]) for im in (a, b))
    assert cb[0] - ca[0] == pytest.approx(20.0, abs=0.3)
    c = sc.render({"window_origin": (0, 0)}, seed=1)  # no 'centre': the disk stays where it was
    np.testing.assert_allclose(c, b)
    with pytest.raises(ValueError, match="emitted twice"):
        Scene({"type": "path"}, [Element("disk", _disk(np.eye(4))), Element("disk", _disk(np.eye(4)))])
    with pytest.raises(ValueError, match="not in the scene"):
        Scene.from_dict({"type": "scene", "integrator": {"type": "path"}}, {"disk": move})


def test_a_frame_splits_into_observation_and_truth():
    cfg = DetectorConfig()
    photons = np.full((8, 8), 100.0)
    photons[3, 3] = 1e7  # saturates
    fr = digitise(photons, cfg, seed=3, truth={"spot_uv": [3.0, 3.0]}, geometry_flags={"spot_off_detector": False},
                  render={"spp": 16}, pose={"X": 1.0})
    assert isinstance(fr, Frame)
    obs, truth = fr
    assert isinstance(obs, Observation)
    assert truth == {"spot_uv": [3.0, 3.0]}
    assert "truth" not in obs.meta and "pose" not in obs.meta
    assert set(obs.meta["flags"]) <= set(OBSERVABLE_FLAGS) and obs.meta["flags"]["saturated"]
    assert obs.meta["render"] == {"spp": 16} and np.array_equal(obs.dn, fr.dn) and fr.dn.dtype == np.uint16
    assert fr.sidecar["flags"]["spot_off_detector"] is False and fr.sidecar["seed"] == 3
