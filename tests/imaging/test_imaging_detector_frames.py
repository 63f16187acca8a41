"""Centroiding frames made by rigsim's own detector model (offset, gain K, quantisation):
NoiseModel.from_detector gives honest uncertainties and unbiased positions."""

import math

import numpy as np

from rigsim.detector import DetectorConfig, apply_detector
from rigsim.imaging import Flag, NoiseModel, centroid_gauss, extract_rois
from rigsim.imaging.synth import gaussian_spots


def test_gauss_fit_on_detector_frames():
    cfg = DetectorConfig(quantum_efficiency=0.6, exposure_s=0.01, full_well_e=20000, read_noise_e=5.0,
                         dark_current_e_per_s=2000.0, dsnu_e=0.0, prnu_frac=0.0, gain_dn_per_e=0.2,
                         adc_bits=12, offset_dn=64.0, sensor_seed=1)
    rng = np.random.default_rng(4)
    n, tile, sigma = 400, 11, 1.3
    side = 20
    du = rng.uniform(-0.5, 0.5, n)
    dv = rng.uniform(-0.5, 0.5, n)
    photons = gaussian_spots((tile, tile), 5 + du, 5 + dv, 2.0e4, sigma)  # 12000 e- per spot
    mosaic = photons.reshape(side, side, tile, tile).transpose(0, 2, 1, 3).reshape(side * tile, side * tile)
    frame = apply_detector(mosaic, cfg, seed=7)
    assert not frame.saturated.any()
    k = np.arange(n)
    cu = (k % side) * tile + 5.0
    cv = (k // side) * tile + 5.0
    rois = extract_rois(frame.dn, cu, cv, tile)
    nm = NoiseModel.from_detector(cfg)
    r = centroid_gauss(rois.stack, sigma_px=sigma, noise=nm, origin_uv=rois.origin_uv,
                       saturation=cfg.max_dn)
    assert np.all(r.flags == Flag.OK)
    z = np.concatenate([(r.u - cu - du) / r.sigma_u, (r.v - cv - dv) / r.sigma_v])
    assert abs(np.mean(z)) < 4 / math.sqrt(z.size)
    assert 0.9 < np.std(z) < 1.1  # 800 samples: the std is known to 2.5 %
    # the background is the offset plus the dark signal, in DN
    assert abs(np.median(r.background) - (cfg.offset_dn + cfg.gain_dn_per_e * cfg.dark_mean_e)) < 0.1
    # and the flux is 12000 e- in DN
    assert abs(np.median(r.flux) / (0.6 * 2.0e4 * cfg.gain_dn_per_e) - 1) < 0.01
