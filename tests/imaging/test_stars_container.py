"""Star extraction on a frame whose 12-bit codes are written MSB-aligned into 16-bit words: the same stars,
positions and σ as on the codes themselves (the frames differ by the factor 16 exactly, so the noise
model, threshold and saturation level must scale with it), each within 5σ of the true position, and the
saturated star (written 65535) flagged."""

from __future__ import annotations

import numpy as np

from rigsim.detector import DetectorConfig, apply_detector
from rigsim.imaging import Flag
from rigsim.imaging.stars import extract_stars
from rigsim.imaging.synth import gaussian_frame

SIGMA_PX = 1.1


def _frames():
    rng = np.random.default_rng(8)
    gu, gv = np.meshgrid(np.arange(4) * 56.0 + 30.0, np.arange(3) * 56.0 + 40.0)   # 12 stars 56 px apart
    u, v = gu.ravel() + rng.uniform(-0.5, 0.5, 12), gv.ravel() + rng.uniform(-0.5, 0.5, 12)
    flux = rng.uniform(4e3, 4e4, 12)
    flux[0] = 3e6                                         # saturates the ADC
    photons = gaussian_frame((192, 256), u, v, flux, SIGMA_PX, background=200.0)
    base = dict(quantum_efficiency=0.6, exposure_s=0.2, full_well_e=1e5, read_noise_e=5.0, dark_current_e_per_s=10.0,
                dsnu_e=0.0, prnu_frac=0.0, gain_dn_per_e=0.05, adc_bits=12, offset_dn=80.0, sensor_seed=1)
    codes_cfg, words_cfg = DetectorConfig(**base), DetectorConfig(**base, container_bits=16)
    codes = apply_detector(photons, codes_cfg, seed=21).dn
    words = apply_detector(photons, words_cfg, seed=21).dn
    return (u, v), (codes, codes_cfg), (words, words_cfg)


def test_the_same_stars_on_codes_and_on_16_bit_words():
    (u, v), (codes, ccfg), (words, wcfg) = _frames()
    top = codes == 4095
    assert top.any() and np.array_equal(words[top], np.full(top.sum(), 65535))
    assert np.array_equal(words[~top], 16 * codes[~top].astype(np.uint16))
    a, b = extract_stars(codes, ccfg, SIGMA_PX), extract_stars(words, wcfg, SIGMA_PX)
    assert len(a) == len(b) == len(u)
    ia, ib = np.lexsort(a.uv.T), np.lexsort(b.uv.T)
    np.testing.assert_allclose(b.uv[ib], a.uv[ia], atol=1e-6)
    np.testing.assert_allclose(b.sigma_uv[ib], a.sigma_uv[ia], rtol=1e-5)
    np.testing.assert_array_equal(b.flags[ib], a.flags[ia])
    # against the truth: every usable star within 5σ, the saturated one flagged
    d = np.hypot(b.uv[:, None, 0] - u[None], b.uv[:, None, 1] - v[None])
    j = d.argmin(axis=1)
    assert len(set(j)) == len(u)
    sat = (b.flags & int(Flag.SATURATED)) != 0
    assert set(j[sat]) == {0}
    ok = b.usable
    err = b.uv[ok] - np.column_stack([u[j[ok]], v[j[ok]]])
    assert ok.sum() == len(u) - 1 and np.all(np.abs(err) < 5 * b.sigma_uv[ok])
