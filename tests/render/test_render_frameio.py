"""Frame files: 16-bit PNG + JSON sidecar round trip, flags, and a full sun-sensor frame."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from rigsim.detector import DetectorConfig, apply_detector
from rigsim.optics.camera import PinholeBrown
from rigsim.render.frame import FLAG_KEYS, build_sidecar, read_frame, write_frame


def test_round_trip_is_lossless(tmp_path):
    rng = np.random.default_rng(0)
    dn = rng.integers(0, 65536, size=(37, 53), dtype=np.uint16)
    side = build_sidecar(truth={"center_uv": np.array([1.5, 2.25])}, render={"spp": 64},
                         seed=7, pose={"R": np.eye(3)})
    png, js = write_frame(tmp_path / "a" / "frame_0001", dn, side)
    assert png.name == "frame_0001.png" and js.name == "frame_0001.json"
    back, side2 = read_frame(tmp_path / "a" / "frame_0001.png")
    assert back.dtype == np.uint16
    np.testing.assert_array_equal(back, dn)
    assert side2["truth"]["center_uv"] == [1.5, 2.25]
    assert side2["pose"]["R"] == np.eye(3).tolist()
    assert side2["seed"] == 7 and side2["render"]["spp"] == 64
    assert side2["image"]["width"] == 53 and side2["image"]["height"] == 37
    for k in FLAG_KEYS:
        assert side2["flags"][k] is False


def test_saturation_and_geometry_become_flags(tmp_path):
    cfg = DetectorConfig(full_well_e=1000.0, gain_dn_per_e=1.0, adc_bits=12, offset_dn=10.0)
    ph = np.zeros((16, 16))
    ph[4:6, 4:7] = 1e5
    det = apply_detector(ph, cfg, seed=3)
    side = build_sidecar(detector_frame=det, geometry_flags={"spot_cut_by_edge": True}, seed=3)
    write_frame(tmp_path / "s", det.dn, side)
    _, s2 = read_frame(tmp_path / "s")
    assert s2["flags"]["saturated"] is True and s2["flags"]["saturated_pixels"] == 6
    assert s2["flags"]["spot_cut_by_edge"] is True and s2["flags"]["spot_off_detector"] is False
    assert s2["detector"]["full_well_e"] == 1000.0
    assert s2["detector_frame"]["seed"] == 3


def test_bad_inputs_rejected(tmp_path):
    with pytest.raises(ValueError, match="uint16"):
        write_frame(tmp_path / "x", np.zeros((4, 4), dtype=np.float32), {})
    with pytest.raises(ValueError, match="uint16"):
        write_frame(tmp_path / "x", np.zeros((4, 4, 3), dtype=np.uint16), {})
    write_frame(tmp_path / "ok", np.zeros((4, 4), dtype=np.uint16), build_sidecar())
    (tmp_path / "ok.json").unlink()
    with pytest.raises(FileNotFoundError, match="sidecar"):
        read_frame(tmp_path / "ok")
    # NaN truth is written as null, never as invalid JSON
    write_frame(tmp_path / "n", np.zeros((2, 2), dtype=np.uint16),
                build_sidecar(truth={"x": float("nan")}))
    assert json.loads((tmp_path / "n.json").read_text())["truth"]["x"] is None


def test_sun_sensor_frame_end_to_end(tmp_path):
    """Render -> detector -> PNG -> read -> centroid: the truth in the sidecar is what the frame
    shows, to within the photon noise predicted for this spot."""
    from rigsim.optics.sun_disk import SUN_FULL_ANGLE_RAD
    from rigsim.render.cube_mirror.sun_sensor import SunSpotRenderer

    cam = PinholeBrown(fx=700.0, fy=700.0, cx=255.5, cy=255.5, width=512, height=512, k1=-0.08,
                        k2=0.01)
    photons = 2.0e6
    r = SunSpotRenderer(cam, full_angle_rad=SUN_FULL_ANGLE_RAD, window_px=32, spp=1024,
                        spot_photons=photons)
    s = np.array([0.2, -0.15, 1.0])
    s /= np.linalg.norm(s)
    frame, win = r.render_frame(s, seed=11)
    cfg = DetectorConfig(quantum_efficiency=0.5, full_well_e=60000.0, read_noise_e=8.0,
                         dark_current_e_per_s=50.0, dsnu_e=2.0, prnu_frac=0.005,
                         gain_dn_per_e=0.06, adc_bits=12, offset_dn=100.0, exposure_s=0.01)
    det = apply_detector(frame, cfg, seed=12)
    truth = r.truth(s, n=1_000_000)
    side = build_sidecar(truth=truth, render=r.settings(), detector_frame=det,
                         geometry_flags=win.flags, seed=11, pose={"sun_dir_cam": s})
    write_frame(tmp_path / "sun", det.dn, side)
    dn, side2 = read_frame(tmp_path / "sun")
    assert side2["flags"]["saturated"] is False and side2["render"]["spp"] == 1024
    assert side2["render"]["variant"] == r.variant
    # centroid over the window after removing the mean dark level
    u0, v0 = win.origin_uv
    sub = dn[v0:v0 + 32, u0:u0 + 32].astype(float) - float(np.median(dn))
    v, u = np.indices(sub.shape)
    c = np.array([(sub * u).sum(), (sub * v).sum()]) / sub.sum() + [u0, v0]
    # photon-noise centroid sd ~ spot rms radius / sqrt(N_e) (+ read/dark noise over 1024 px)
    n_e = photons * cfg.quantum_efficiency * truth["relative_flux"]
    r_rms = 700.0 * SUN_FULL_ANGLE_RAD / 4
    noise_px = 16 * math.sqrt(1024 * (cfg.read_noise_e ** 2 + 0.5 + cfg.dsnu_e ** 2)) / n_e
    sd = math.hypot(r_rms / math.sqrt(n_e), noise_px)
    np.testing.assert_allclose(c, side2["truth"]["pixel_centroid_uv"], atol=5 * sd + 0.01)
