"""The detector signal chain: expected photons per pixel -> digital numbers (uint16)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rigsim.detector.config import DetectorConfig
from rigsim.detector.pattern import fixed_pattern, signal_maps
from rigsim.detector.poisson import poisson_inverse_cdf
from rigsim.detector.scratch import Scratch, thread_scratch

__all__ = ["DetectorFrame", "apply_detector", "fixed_pattern", "poisson_inverse_cdf"]

_CHUNK = 1 << 17  # pixels per block of the noisy chain (a multiple of _PAIR)
_PAIR = 1 << 15   # the read noise's Box–Muller pairs are formed within runs of this many pixels


@dataclass
class DetectorFrame:
    """One digitised frame.

    ``dn``: uint16 image (rows v, columns u). ``saturated``: bool mask of pixels clipped at the
    full well or at the ADC's top code. ``expected_dn``: the noise-free mean DN of every pixel
    (fixed patterns included unless ``noiseless``; full-well clip applied; not quantised) -- the
    reference for fidelity checks, float64, built when first read. ``meta``: seeds, config, counts.
    """

    dn: np.ndarray
    saturated: np.ndarray
    # float64 mean DN, or (noisy chain) the float32 gain x electrons to which ``offset_dn`` is added
    # in float64 on first read -- the same values, without writing 8 bytes per pixel per frame
    # that most callers never read
    _expected: np.ndarray = field(repr=False)
    meta: dict = field(default_factory=dict)
    _offset_dn: float = field(default=0.0, repr=False)

    @property
    def expected_dn(self) -> np.ndarray:
        if self._expected.dtype != np.float64:
            v = self._expected.astype(np.float64)
            v += self._offset_dn
            self._expected, self._offset_dn = v, 0.0
        return self._expected

    @property
    def saturated_pixels(self) -> int:
        return int(np.count_nonzero(self.saturated))


def _check_photons(ph: np.ndarray) -> float:
    """Raise unless ``ph`` is a 2-D image of finite values >= 0; return its largest value."""
    if ph.ndim != 2:
        raise ValueError(f"photons_per_px must be a 2-D image, got shape {ph.shape}")
    if not ph.size:
        return 0.0
    top = ph.max()
    if not (ph.min() >= 0 and top < np.inf):  # NaN fails both comparisons
        bad = int(np.sum(~np.isfinite(ph) | (ph < 0)))
        raise ValueError(f"photons_per_px must be finite and >= 0 ({bad} pixels are not)")
    return float(top)


def _add_normals_f32(rng: np.random.Generator, x: np.ndarray, sigma: float, work: Scratch | None = None) -> None:
    """Add N(0, sigma²) to float32 ``x`` in place: Box–Muller pairs from 24-bit uniforms (the
    tails end at 5.8 σ, a probability of 1e-8).

    The pixels are paired within consecutive runs of :data:`_PAIR` (the first half of a run with
    its second half, the last, shorter run likewise), whatever the block size of the caller."""
    n = x.size
    q = n // _PAIR
    if q:
        h = _PAIR // 2
        work = Scratch() if work is None else work
        uu = rng.random(dtype=np.float32, out=work.get("bm_u", q * _PAIR, np.float32)).reshape(q, 2, h)
        r = work.get("bm_r", q * h, np.float32).reshape(q, h)
        g = work.get("bm_g", q * h, np.float32).reshape(q, h)
        np.negative(uu[:, 0], out=r)
        np.log1p(r, out=r)                     # log(1 - u), 1 - u in (0, 1]
        r *= np.float32(-2.0 * sigma * sigma)
        np.sqrt(r, out=r)
        ang = uu[:, 1]
        ang *= np.float32(2.0 * np.pi)
        xx = x[: q * _PAIR].reshape(q, 2, h)
        np.cos(ang, out=g)
        g *= r
        xx[:, 0] += g
        np.sin(ang, out=g)
        g *= r
        xx[:, 1] += g
    if n > q * _PAIR:
        _add_normals_run(rng, x[q * _PAIR:], sigma)


def _add_normals_run(rng: np.random.Generator, x: np.ndarray, sigma: float) -> None:
    n = x.size
    m = (n + 1) // 2
    uu = rng.random(2 * m, dtype=np.float32)
    r = np.log1p(-uu[:m])  # log(1 - u), 1 - u in (0, 1]
    r *= np.float32(-2.0 * sigma * sigma)
    np.sqrt(r, out=r)
    ang = uu[m:]
    ang *= np.float32(2.0 * np.pi)
    g = np.cos(ang)
    g *= r
    x[:m] += g
    np.sin(ang[:n - m], out=g[:n - m])
    g[:n - m] *= r[:n - m]
    x[m:] += g[:n - m]


def _align_codes(dn: np.ndarray, top_code: np.ndarray, cfg: DetectorConfig) -> None:
    """Codes written MSB-aligned (``cfg.container_bits``), in place: code × code_step_dn, the top code as
    the container's all-ones word (as a camera that writes a 12-bit ADC into 16-bit words does)."""
    if cfg.container_bits is None:
        return
    np.left_shift(dn, cfg.container_bits - cfg.adc_bits, out=dn)
    np.putmask(dn, top_code, (1 << cfg.container_bits) - 1)


def _noisy_block(ph, eg, dark, rng_shot, cfg, rng_read, dn, saturated, mean_kdn, added=None, clamp=True,
                 work: Scratch | None = None):
    """The noisy chain over one block of pixels (flat views); writes the outputs in place and
    returns the counts of full-well and ADC-clipped pixels. ``added``: electrons added after the
    shot noise (or None). ``clamp=False``: no value of photons × QE × PRNU reaches 1e15 (the clamp
    would change nothing)."""
    size = ph.size
    w = Scratch() if work is None else work
    u = rng_shot.random(dtype=np.float32, out=w.get("u", size, np.float32))
    e, t, n = (w.get(k, size, np.float32) for k in ("e", "t", "n"))
    well, adc = w.get("well", size, bool), w.get("adc", size, bool)
    np.minimum(ph, 1e30, out=e, casting="unsafe")
    e *= eg
    if clamp:
        np.minimum(e, np.float32(1e15), out=e)
    e += dark                                  # λ: photo-electrons and dark electrons are Poisson
    fw = np.float32(cfg.full_well_e)
    K = cfg.gain_dn_per_e
    if added is None:
        np.minimum(e, fw, out=t)
    else:
        np.add(e, added, out=t)
        np.minimum(t, fw, out=t)
    np.multiply(t, np.float32(K * cfg.code_step_dn), out=mean_kdn)  # float32 K·electrons (frame DN): the offset is added on reading
    poisson_inverse_cdf(e, u, out=n, work=w)
    if added is not None:
        n += added
    np.greater_equal(n, fw, out=well)
    np.minimum(n, fw, out=n)
    if cfg.read_noise_e > 0:
        _add_normals_f32(rng_read, n, cfg.read_noise_e, w)
    n *= np.float32(K)
    n += np.float32(cfg.offset_dn + 0.5)       # round half up: truncation of y + 0.5 once clipped to >= 0
    top = np.float32(cfg.max_dn)
    np.greater_equal(n, top, out=adc)
    np.clip(n, np.float32(0.0), top, out=n)
    dn[:] = n
    _align_codes(dn, adc, cfg)
    np.logical_or(well, adc, out=saturated)
    return int(np.count_nonzero(well)), int(np.count_nonzero(adc))


def apply_detector(photons_per_px: np.ndarray, cfg: DetectorConfig, seed: int | None = None, *,
                   noiseless: bool = False, origin_uv: tuple[int, int] = (0, 0),
                   detector_shape: tuple[int, int] | None = None, added_e: np.ndarray | None = None) -> DetectorFrame:
    """Digitise an image of expected photon counts per pixel (over the exposure).

    Chain: photons x QE x PRNU -> Poisson; dark: Poisson(dark_current x t + DSNU); sum clipped at
    the full well; + N(0, read_noise); x gain + offset; round half up; clip to [0, 2^bits - 1]; with
    ``cfg.container_bits``, the codes written MSB-aligned (× ``code_step_dn``, the top code as all ones).
    ``dn`` and ``expected_dn`` are in frame DN.

    ``seed`` drives the temporal noise of this frame (required unless ``noiseless``): the same
    seed and input give an identical frame. The fixed patterns come from ``cfg.sensor_seed``.
    ``noiseless=True`` drops every random term (shot, dark shot, read noise, DSNU, PRNU) and keeps
    QE, mean dark signal, full well, gain, offset, quantisation and ADC clipping.
    For a crop window pass its ``origin_uv`` and the full ``detector_shape`` (rows, cols) so the
    fixed pattern matches the full frame's. ``added_e``: electrons (same shape as the photons) added
    to the signal after the shot noise and before the full well — charge the optics did not deliver
    (hot pixels, cosmic-ray hits: rigsim.detector.defects).

    The noisy chain runs in float32 over blocks of pixels (counts stay exact integers up to the
    largest full well, 1e7 < 2^24); ``expected_dn`` is float64 (computed when first read).
    """
    ph = np.asarray(photons_per_px)
    if ph.dtype.kind not in "fiub":
        ph = ph.astype(np.float64)
    ph_max = _check_photons(ph)
    if not noiseless and seed is None:
        raise ValueError("apply_detector needs an explicit seed (or noiseless=True)")
    det_shape = tuple(ph.shape) if detector_shape is None else tuple(int(x) for x in detector_shape)
    added = None
    if added_e is not None:
        added = np.asarray(added_e, dtype=np.float64)
        if added.shape != ph.shape:
            raise ValueError(f"added_e has shape {added.shape}, the photons {ph.shape}")
        _check_photons(added)

    eta = cfg.quantum_efficiency
    dark_mean = cfg.dark_mean_e
    K = cfg.gain_dn_per_e
    if noiseless:
        ph = ph.astype(np.float64, copy=False)
        e_mean = eta * ph + dark_mean
        if added is not None:
            e_mean = e_mean + added
        electrons = np.minimum(e_mean, cfg.full_well_e)
        well_clip = e_mean >= cfg.full_well_e
        codes = K * electrons + cfg.offset_dn
        q = np.floor(codes + 0.5)
        top = cfg.max_dn
        adc_clip = q >= top
        dn = np.clip(q, 0, top).astype(np.uint16)
        _align_codes(dn, adc_clip, cfg)
        expected_dn = codes * cfg.code_step_dn if cfg.container_bits is not None else codes
        saturated = well_clip | adc_clip
        n_well, n_adc = int(well_clip.sum()), int(adc_clip.sum())
    else:
        eg, dark = signal_maps(int(cfg.sensor_seed), float(cfg.prnu_frac), float(cfg.dsnu_e), float(eta),
                               float(dark_mean), det_shape, (int(origin_uv[0]), int(origin_uv[1])),
                               tuple(int(x) for x in ph.shape))
        # Exactly one uniform per pixel for the shot noise, and a separate stream for the read
        # noise: the draws of one pixel never depend on another pixel's value. Renderers that add
        # samples with atomic float adds (ptracer) reproduce photon images only to ~1e-7; with
        # numpy's Poisson sampler (a value-dependent number of draws per pixel) that would
        # reshuffle the noise of every later pixel, with an inverse CDF it changes nothing.
        # the PRNU gain is 1 + prnu_frac·z with |z| <= 5.8 (24-bit Box–Muller uniforms)
        clamp = not ph_max * eta * (1.0 + 6.0 * float(cfg.prnu_frac)) < 1e14
        ss_shot, ss_read = np.random.SeedSequence([int(seed), 0x7E4D_0A11]).spawn(2)
        rng_shot, rng_read = np.random.default_rng(ss_shot), np.random.default_rng(ss_read)
        dn = np.empty(ph.shape, np.uint16)
        saturated = np.empty(ph.shape, bool)
        expected_dn = np.empty(ph.shape, np.float32)  # the mean's K·electrons (see DetectorFrame)
        flat = [a.reshape(-1) for a in (np.ascontiguousarray(ph), eg, dark, dn, saturated, expected_dn)]
        flat_added = None if added is None else added.astype(np.float32).reshape(-1)
        n_well = n_adc = 0
        work = thread_scratch()
        for i in range(0, ph.size, _CHUNK):
            s = slice(i, min(ph.size, i + _CHUNK))
            w, a = _noisy_block(*(f[s] for f in flat[:3]), rng_shot, cfg, rng_read, *(f[s] for f in flat[3:]),
                                None if flat_added is None else flat_added[s], clamp=clamp, work=work)
            n_well += w
            n_adc += a
    meta = {
        "seed": None if seed is None else int(seed),
        "sensor_seed": cfg.sensor_seed,
        "noiseless": bool(noiseless),
        "origin_uv": [int(origin_uv[0]), int(origin_uv[1])],
        "detector_shape": [int(det_shape[0]), int(det_shape[1])],
        "saturated_pixels": int(np.count_nonzero(saturated)),
        "full_well_pixels": n_well,
        "adc_clipped_pixels": n_adc,
        "config": cfg.model_dump(exclude={"container_bits"} if cfg.container_bits is None else None),
    }
    return DetectorFrame(dn, saturated, expected_dn, meta, 0.0 if noiseless else float(cfg.offset_dn) * cfg.code_step_dn)
