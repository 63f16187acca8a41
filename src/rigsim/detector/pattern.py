"""Fixed patterns (PRNU, DSNU) drawn only for the pixels asked for, from a counter-based generator.

Every detector pixel owns one 64-bit hash of (``sensor_seed``, pixel index ``v * W + u``) —
splitmix64, a bijective integer mixer — whose two 24-bit halves are the uniforms of one
Box–Muller pair: the PRNU and the DSNU normal of that pixel. A pixel's pattern therefore depends
on the seed and its position only, never on the region drawn: a crop window sees exactly the
values of the same pixels in a full frame, and a window costs what its pixels cost.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["fixed_pattern", "pattern_normals"]

_GOLDEN = np.uint64(0x9E37_79B9_7F4A_7C15)
_M1 = np.uint64(0xBF58_476D_1CE4_E5B9)
_M2 = np.uint64(0x94D0_49BB_1331_11EB)
_PATTERN_STREAM = 0x9D7F_11E5  # separates this stream from any other use of the seed


def _mix64(z: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser, in place on a uint64 array."""
    z ^= z >> np.uint64(30)
    z *= _M1
    z ^= z >> np.uint64(27)
    z *= _M2
    z ^= z >> np.uint64(31)
    return z


def _seed_key(sensor_seed: int) -> np.uint64:
    k = np.array([(int(sensor_seed) ^ (_PATTERN_STREAM << 32)) & 0xFFFF_FFFF_FFFF_FFFF], dtype=np.uint64)
    return _mix64(k * _GOLDEN + _GOLDEN)[0]


def pattern_normals(sensor_seed: int, detector_width: int, rows: tuple[int, int],
                    cols: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Two independent standard-normal float32 maps (PRNU's, DSNU's) of detector rows
    ``rows[0]:rows[1]`` and columns ``cols[0]:cols[1]`` (inside a detector ``detector_width`` wide)."""
    (b0, b1), (a0, a1) = rows, cols
    h, w = b1 - b0, a1 - a0
    z1 = np.empty((h, w), np.float32)
    z2 = np.empty((h, w), np.float32)
    if h <= 0 or w <= 0:
        return z1, z2
    key = _seed_key(sensor_seed)
    col = np.arange(a0, a1, dtype=np.uint64)
    two_pi = np.float32(2.0 * np.pi)
    scale = np.float32(2.0 ** -24)
    step = max(1, (1 << 16) // w)  # rows per block: cache-sized temporaries
    with np.errstate(over="ignore"):
        for r0 in range(0, h, step):
            r1 = min(h, r0 + step)
            idx = (np.arange(b0 + r0, b0 + r1, dtype=np.uint64)[:, None] * np.uint64(detector_width) + col)
            z = _mix64((idx + key) * _GOLDEN)
            # u1 in (0, 1] (no log of 0), u2 in [0, 1): 24 bits each, exact in float32
            u1 = ((z >> np.uint64(40)).astype(np.float32) + np.float32(1.0)) * scale
            u2 = ((z >> np.uint64(16)) & np.uint64(0xFF_FFFF)).astype(np.float32) * scale
            r = np.sqrt(np.float32(-2.0) * np.log(u1))
            ang = two_pi * u2
            np.multiply(r, np.cos(ang), out=z1[r0:r1])
            np.multiply(r, np.sin(ang), out=z2[r0:r1])
    return z1, z2


def _window(detector_shape, origin_uv, shape):
    H, W = int(detector_shape[0]), int(detector_shape[1])
    h, w = int(shape[0]), int(shape[1])
    u0, v0 = int(origin_uv[0]), int(origin_uv[1])
    a0, b0, a1, b1 = max(0, u0), max(0, v0), min(W, u0 + w), min(H, v0 + h)
    return W, (u0, v0), (a0, b0, a1, b1)


def fixed_pattern(cfg, detector_shape: tuple[int, int], origin_uv: tuple[int, int] = (0, 0),
                  shape: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """PRNU gain map (1 + prnu_frac z) and DSNU offset map (dsnu_e z, electrons) of a region.

    The region of ``shape`` (default: the whole detector) has its pixel (0, 0) at detector pixel
    ``origin_uv``; pixels off the detector get gain 1 and no DSNU. Drawn from ``cfg.sensor_seed``
    and the pixel positions only: a crop window sees exactly the pattern of the same pixels in a
    full frame.
    """
    shape = tuple(detector_shape) if shape is None else tuple(shape)
    W, (u0, v0), (a0, b0, a1, b1) = _window(detector_shape, origin_uv, shape)
    gain = np.ones((int(shape[0]), int(shape[1])))
    dsnu = np.zeros_like(gain)
    if a1 > a0 and b1 > b0:
        z_prnu, z_dsnu = pattern_normals(cfg.sensor_seed, W, (b0, b1), (a0, a1))
        gain[b0 - v0:b1 - v0, a0 - u0:a1 - u0] += cfg.prnu_frac * z_prnu.astype(np.float64)
        dsnu[b0 - v0:b1 - v0, a0 - u0:a1 - u0] = cfg.dsnu_e * z_dsnu.astype(np.float64)
    return np.maximum(gain, 0.0), dsnu


@lru_cache(maxsize=2)
def signal_maps(sensor_seed: int, prnu_frac: float, dsnu_e: float, eta: float, dark_mean_e: float,
                detector_shape: tuple[int, int], origin_uv: tuple[int, int],
                shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The per-pixel maps the signal chain needs, float32 and read-only: electrons per photon
    (QE x PRNU gain) and the mean dark electrons (dark signal + DSNU, >= 0). Kept for the last
    two regions (a dataset renders the same region frame after frame)."""
    W, (u0, v0), (a0, b0, a1, b1) = _window(detector_shape, origin_uv, shape)
    eg = np.full(shape, np.float32(eta), np.float32)
    dark = np.full(shape, np.float32(max(dark_mean_e, 0.0)), np.float32)
    if a1 > a0 and b1 > b0:
        z_prnu, z_dsnu = pattern_normals(sensor_seed, W, (b0, b1), (a0, a1))
        win = (slice(b0 - v0, b1 - v0), slice(a0 - u0, a1 - u0))
        g = z_prnu
        g *= np.float32(prnu_frac)
        g += np.float32(1.0)
        np.maximum(g, np.float32(0.0), out=g)
        g *= np.float32(eta)
        eg[win] = g
        d = z_dsnu
        d *= np.float32(dsnu_e)
        d += np.float32(dark_mean_e)
        np.maximum(d, np.float32(0.0), out=d)
        dark[win] = d
    eg.setflags(write=False)
    dark.setflags(write=False)
    return eg, dark
