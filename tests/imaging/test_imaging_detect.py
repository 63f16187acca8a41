"""Detection, background estimation, ROI extraction and the end-to-end find_spots, against truth."""

import math

import numpy as np
import pytest

from rigsim.imaging import Flag, NoiseModel, detect, estimate_background, find_spots
from rigsim.imaging.synth import add_noise, gaussian_frame

NOISE = NoiseModel(0.5, 6.0)  # K = 0.5 DN/e-, read noise 6 e-
BG_DN = 40.0


def _frame(seed, u, v, flux, shape=(128, 160), sigma=1.3, bg=BG_DN):
    rng = np.random.default_rng(seed)
    return add_noise(gaussian_frame(shape, u, v, flux, sigma, background=bg), NOISE, rng)


def test_global_background_level_and_rms():
    img = _frame(1, [40.2, 90.7], [60.1, 30.3], [5e3, 8e3])
    b = estimate_background(img)
    true_sd = math.sqrt(NOISE.variance(np.array(BG_DN)))
    assert b.level == pytest.approx(BG_DN, abs=5 * true_sd / math.sqrt(img.size))
    assert b.rms == pytest.approx(true_sd, rel=0.05)


def test_mesh_background_follows_a_gradient():
    rng = np.random.default_rng(2)
    h, w = 128, 192
    expected = 30.0 + 0.2 * np.arange(w)[None, :] + np.zeros((h, 1))
    img = add_noise(expected, NOISE, rng)
    b = estimate_background(img, box_px=32)
    inner = (slice(16, -16), slice(16, -16))
    resid = (b.level - expected)[inner]
    assert np.max(np.abs(resid)) < 1.0  # DN; pixel noise is ~5 DN, each box has 1024 px
    gl = estimate_background(img)
    assert np.max(np.abs(gl.level - expected)) > 10.0  # the global level cannot follow it


def test_detect_finds_isolated_spots_and_nothing_else():
    u = np.array([20.3, 60.7, 100.2, 140.6, 80.1])
    v = np.array([30.1, 80.6, 50.5, 100.3, 20.8])
    flux = np.array([3e3, 8e3, 6e3, 2e3, 1.5e4])
    img = _frame(3, u, v, flux)
    d = detect(img)
    assert len(d) == len(u)
    order = np.argsort(d.u)
    t = np.argsort(u)
    assert np.allclose(d.u[order], u[t], atol=0.15) and np.allclose(d.v[order], v[t], atol=0.15)
    assert np.all(d.flags == 0) and d.frame_flags == Flag.OK
    # pure noise: no false detections at 5 sigma
    rng = np.random.default_rng(4)
    noise_only = add_noise(np.full((256, 256), BG_DN), NOISE, rng)
    assert len(detect(noise_only)) == 0


def test_deblending_of_close_pair():
    img = _frame(5, [50.0, 54.5], [40.0, 41.0], [2e4, 1.2e4])
    d = detect(img)
    assert len(d) == 2
    assert np.all(d.flags & Flag.BLENDED)
    assert sorted(np.round(d.peak_u)) == [50, 54] or sorted(np.round(d.peak_u)) == [50, 55]
    nd = detect(img, deblend=False)
    assert len(nd) == 1


def test_saturated_spot_detected_once_and_flagged():
    rng = np.random.default_rng(6)
    exp = gaussian_frame((64, 64), [30.4], [31.7], [4e5], 1.3, background=BG_DN)
    img = add_noise(exp, NOISE, rng, saturation_dn=20000.0)
    d = detect(img, saturation=20000.0)
    assert len(d) == 1 and d.flags[0] & Flag.SATURATED and d.frame_flags & Flag.SATURATED


def test_find_spots_against_truth():
    rng = np.random.default_rng(7)
    n = 25
    u = rng.uniform(10, 150, n)
    v = rng.uniform(10, 118, n)
    # keep them isolated
    keep = [0]
    for i in range(1, n):
        if all(math.hypot(u[i] - u[j], v[i] - v[j]) > 12 for j in keep):
            keep.append(i)
    u, v = u[keep], v[keep]
    flux = rng.uniform(3e3, 3e4, len(u))
    img = _frame(8, u, v, flux)
    res, det = find_spots(img, sigma_px=1.3, noise=NOISE)
    assert len(res) == len(u)
    # match by nearest neighbour
    for k in range(len(u)):
        j = int(np.argmin(np.hypot(res.u - u[k], res.v - v[k])))
        assert res.flags[j] == 0
        assert abs(res.u[j] - u[k]) < 4.5 * res.sigma_u[j]
        assert abs(res.v[j] - v[k]) < 4.5 * res.sigma_v[j]
    # the normalised errors have unit scatter (the sigmas are honest)
    zu = []
    for k in range(len(u)):
        j = int(np.argmin(np.hypot(res.u - u[k], res.v - v[k])))
        zu += [(res.u[j] - u[k]) / res.sigma_u[j], (res.v[j] - v[k]) / res.sigma_v[j]]
    assert 0.6 < np.std(zu) < 1.4


@pytest.mark.parametrize("method", ["tcom", "wcom", "gauss"])
def test_find_spots_edge_and_blend_flags(method):
    u = [1.2, 60.0, 64.5, 120.0]
    v = [40.0, 60.0, 61.0, 126.6]
    img = _frame(9, u, v, [1e4, 1.5e4, 1e4, 1e4])
    res, _ = find_spots(img, sigma_px=1.3, noise=NOISE, method=method)
    assert len(res) == 4
    near = lambda uu, vv: int(np.argmin(np.hypot(res.u - uu, res.v - vv)))  # noqa: E731
    assert res.flags[near(1.2, 40.0)] & Flag.EDGE
    assert res.flags[near(120.0, 126.6)] & Flag.EDGE
    assert res.flags[near(60.0, 60.0)] & Flag.BLENDED
    assert res.flags[near(64.5, 61.0)] & Flag.BLENDED
    # NaN fill outside the frame is not reported as a NaN defect
    assert not np.any(res.flags & Flag.NAN)


def test_blended_pair_joint_fit_against_truth():
    """Two spots 3.2 px apart: the joint fit recovers both within 4 sigma, and its sigmas match
    the Monte-Carlo scatter (30 frames)."""
    from rigsim.imaging import centroid_gauss_multi

    rng = np.random.default_rng(12)
    truth = np.array([[10.3, 10.6], [13.4, 11.4]])
    z = []
    for _ in range(30):
        exp = gaussian_frame((22, 24), truth[:, 0], truth[:, 1], [8e3, 5e3], 1.2, background=BG_DN)
        img = add_noise(exp, NOISE, rng)
        m = centroid_gauss_multi(img, [[10.0, 11.0], [13.0, 11.0]], sigma_px=1.2, noise=NOISE)
        assert np.all(m.flags == Flag.BLENDED)
        z += list((m.u - truth[:, 0]) / m.sigma_u) + list((m.v - truth[:, 1]) / m.sigma_v)
    z = np.array(z)
    assert np.all(np.abs(z) < 4.5)
    assert 0.75 < np.std(z) < 1.25  # 120 samples: std known to ~7 %


def test_find_spots_refits_blends_jointly():
    u = [60.0, 63.4]
    v = [60.0, 61.2]
    img = _frame(10, u, v, [1.5e4, 1e4])
    res, _ = find_spots(img, sigma_px=1.3, noise=NOISE)
    assert len(res) == 2 and np.all(res.flags & Flag.BLENDED)
    for k in range(2):
        j = int(np.argmin(np.hypot(res.u - u[k], res.v - v[k])))
        assert abs(res.u[j] - u[k]) < 4 * res.sigma_u[j] and abs(res.v[j] - v[k]) < 4 * res.sigma_v[j]
    # without the joint refit the single-spot fits are pulled towards each other (biased)
    single, _ = find_spots(img, sigma_px=1.3, noise=NOISE, deblend_fit=False)
    err_single = max(np.min(np.hypot(single.u - u[k], single.v - v[k])) for k in range(2))
    err_joint = max(np.min(np.hypot(res.u - u[k], res.v - v[k])) for k in range(2))
    assert err_joint < err_single


def _clipped_stats_by_definition(v, nsigma, max_iter):
    """The sigma clip written out with numpy's median on the values themselves (the definition)."""
    med = rms = np.nan
    for _ in range(max_iter):
        if v.size == 0:
            break
        med = float(np.median(v))
        rms = float(1.482602218505602 * np.median(np.abs(v - med)))
        if rms == 0:
            rms = float(np.std(v))
            if rms == 0:
                break
        keep = np.abs(v - med) <= nsigma * rms
        if keep.all():
            break
        v = v[keep]
    return med, rms


def test_clipped_background_of_whole_numbered_frames_is_the_definitions_bit_for_bit():
    """Frames of codes are clipped on their histogram: the median, the MAD and every clip must be those of
    numpy's median on the values, to the last bit, whatever the values (odd and even counts, half-integer
    medians, negative codes, outliers, most pixels equal, a clip that keeps nothing)."""
    from rigsim.imaging._common import MAD_TO_SD
    from rigsim.imaging.detect import _HISTOGRAM_MIN_SIZE, _clipped_stats

    assert MAD_TO_SD == 1.482602218505602
    rng = np.random.default_rng(5)
    cases = [
        rng.poisson(40.0, 200_000),                                            # sky codes
        rng.poisson(3.0, 50_001) - 7,                                         # negative, odd count
        np.concatenate([rng.normal(1000, 12, 80_000).round(), rng.integers(1200, 65535, 3000)]),  # stars, hot pixels
        np.concatenate([np.full(30_000, 100.0), rng.integers(0, 4000, 20_000)]),  # most pixels one value: MAD 0
        np.full(_HISTOGRAM_MIN_SIZE, 7.0),                                    # flat: rms 0
        rng.integers(0, 2, 10_000) * 2 + 1.0,                                 # two values: half-integer median
        np.repeat([0.0, 1.0, 9.0], [2048, 2049, 3]),                         # the middle value just past a value's last copy
        np.repeat([0.0, 5.0], [2048, 2048]),                                 # even count split between two values: 2.5
        np.repeat([-3.0, 0.0, 1.0, 2.0], [1500, 1000, 1000, 1596]),          # a MAD that ends on a value's last copy
    ]
    for v in cases:
        v = np.asarray(v, dtype=float)
        rng.shuffle(v)
        for nsigma, it in ((3.0, 5), (2.0, 9), (0.1, 5), (5.0, 1)):
            got, want = _clipped_stats(v, nsigma, it), _clipped_stats_by_definition(v, nsigma, it)
            assert np.array_equal(got, want, equal_nan=True), (v[:5], nsigma, it, got, want)
    # not whole-numbered, or too few values: the array path (the same definition)
    v = rng.normal(10.0, 1.0, 20_000)
    assert _clipped_stats(v, 3.0, 5) == _clipped_stats_by_definition(v, 3.0, 5)
