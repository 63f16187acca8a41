"""``method="model"`` of the boresight ROI centroids (rigsim.procedures.boresight.model_spot): a pair
of ROI files with a known spot through the file stage, and a saturated ROI."""

import math

import numpy as np
from PIL import Image

from rigsim.imaging import Flag, NoiseModel
from rigsim.procedures.boresight.files import camera_geometry, centroid_roi_files
from rigsim.procedures.boresight.model_spot import roi_centroids
from rigsim.rig.load import load_boresight_rig


def disk(c, R, origin, W, ss=1024):
    x = origin[0] - 0.5 + (np.arange(W * ss) + 0.5) / ss - c[0]
    h = np.sqrt(np.maximum(R * R - x * x, 0.0))
    y0 = origin[1] - 0.5 + np.arange(W) - c[1]
    chord = np.clip(np.minimum(y0[:, None] + 1, h[None, :]) - np.maximum(y0[:, None], -h[None, :]), 0, None)
    return chord.reshape(W, W, ss).sum(axis=2) / ss / (math.pi * R * R)


def test_the_file_stage_with_the_model_finds_the_cores_centre(tmp_path):
    """Two ROI files of camera 0 (spots 0.4–0.9 px off the design reference): the model's centres are
    the true ones within 4σ (σ ≈ 0.0015 px). A ROI saturated over the disk: its saturated pixels do
    not count and the rim still gives the centre to 0.01 px."""
    rig = load_boresight_rig("dual_line_array_prism")
    det, W = rig.detector, rig.orbit.window_px
    cam = rig.cameras[0].name
    geom = camera_geometry(rig, cam)
    rng = np.random.default_rng(8)
    truth, paths = [], []
    for j in range(2):
        o = geom.roi_origin(j, W)
        c = np.asarray(geom.reference_uv[j]) + np.array([0.23, -0.37]) * (1 + j)
        mu = rig.laser.photons_per_frame * det.quantum_efficiency * disk(c, 2.5, o, W)
        dn = np.round(det.gain_dn_per_e * (rng.poisson(mu) + rng.normal(0.0, det.read_noise_e, mu.shape)) + det.offset_dn)
        p = tmp_path / f"m{j + 1}.png"
        Image.fromarray(np.clip(dn, 0, 4095).astype(np.uint16)).save(p)
        truth.append(c)
        paths.append(p)
    mod = centroid_roi_files(rig, cam, [paths[0]], [paths[1]], method="model")
    for j in range(2):
        k = f"m{j + 1}"
        e = np.array([mod[f"u_{k}_px"][0], mod[f"v_{k}_px"][0]]) - truth[j]
        s = np.array([mod[f"sigma_u_{k}_px"][0], mod[f"sigma_v_{k}_px"][0]])
        assert np.all(s < 0.003) and np.all(np.abs(e) < 4 * s), (e, s)
    # a saturated ROI: those pixels do not count, the fit still finds the centre
    o = geom.roi_origin(0, W)
    mu = 3 * rig.laser.photons_per_frame * det.quantum_efficiency * disk(truth[0], 2.5, o, W)
    dn = np.clip(np.round(det.gain_dn_per_e * mu + det.offset_dn), 0, 4095).astype(np.uint16)
    res = roi_centroids(rig, dn, [o], method="model", noise=NoiseModel.from_detector(det))
    assert res.valid[0] and not res.flags[0] & Flag.POOR_FIT
    assert np.abs(res.uv[0] - truth[0]).max() < 0.01
