"""The detector's output at low counts has the distribution of its physics, not only its moments.

A flat field of N pixels (no fixed pattern, so every pixel has the same λ = QE·photons + dark current·t) through
``apply_detector`` against the exact law of the chain, computed here with scipy and nothing of rigsim:

    DN = clip(floor(K·(n + σ·z) + offset + ½), 0, 2^bits − 1),   n ~ Poisson(λ),  z ~ N(0, 1)

i.e. P(DN = d) = Σ_n Poisson(n; λ)·[Φ((e_{d+1} − n)/σ) − Φ((e_d − n)/σ)] with e_d = (d − ½ − offset)/K: Poisson
convolved with the read noise, quantised. Pearson's χ² over the DN values (the tails pooled until every bin
expects ≥ 20 pixels) at a false-alarm rate α = 10⁻³.

Power: the alternative that moments cannot tell apart — the shot noise replaced by a rounded Gaussian of the
same mean and variance, n = round(λ + √λ·z) — shifts each bin's probability by a known amount; the χ²
statistic then follows a noncentral χ² whose noncentrality N·Σ(p₁ − p₀)²/p₀ gives the probability of
rejecting it. Each case's λ and N are chosen so that this power is ≥ 0.99 (the table in docs/testing.md, and
the rejection rates over 200 seeds measured by ``python tests/detector/test_detector_distribution.py``). The
detectors are the rig files' own: the star sensor's and the sun sensor's (read noise 10 and 8 e⁻, where the
skewness of a faint spot's pixels is all that tells the laws apart), the boresight camera's (3 e⁻), and a
photon-counting one (0.25 e⁻, 2 DN/e⁻) where every electron is its own DN step.
"""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy import special, stats

from rigsim.detector import DetectorConfig, apply_detector

ALPHA = 1e-3
MIN_EXPECTED = 20
SCENES = Path(__file__).resolve().parents[2] / "scenes"


def rig_detector(rig_file: str, *table: str) -> dict:
    """A rig file's detector table, read from the TOML text (not through the rig schema)."""
    d = tomllib.loads((SCENES / f"{rig_file}.toml").read_text())
    for key in table:
        d = d[key]
    return d


# (name, detector table, λ in electrons, pixels): λ includes the dark current's electrons
CASES = [
    ("star sensor, faint star pixel (walk)", ("star_sensor", "sensor", "detector"), 29.0, 1 << 20),
    ("star sensor, Cornish-Fisher regime", ("star_sensor", "sensor", "detector"), 200.0, 1 << 20),
    ("sun sensor, spot wing", ("sun_sensor_2axis_diaphragm", "sun_sensor", "detector"), 20.0, 1 << 20),
    ("boresight camera", ("dual_line_array_prism", "detector"), 5.0, 1 << 17),
    ("photon counting", None, 3.0, 1 << 14),
]
PHOTON_COUNTING = dict(quantum_efficiency=0.8, exposure_s=0.01, full_well_e=10000.0, read_noise_e=0.25,
                       dark_current_e_per_s=0.0, dsnu_e=0.0, prnu_frac=0.0, gain_dn_per_e=2.0, adc_bits=12,
                       offset_dn=64.0, sensor_seed=1)


def config(table) -> DetectorConfig:
    d = dict(PHOTON_COUNTING) if table is None else dict(rig_detector(*table))
    d.update(prnu_frac=0.0, dsnu_e=0.0)  # one λ for every pixel
    return DetectorConfig(**d)


def dn_pmf(cfg: DetectorConfig, lam: float, shot: str = "poisson") -> tuple[int, np.ndarray]:
    """(d0, p): p[i] = P(DN = d0 + i) of the chain above over the DN values within 12 σ of the mean, the first
    and last holding the tails below and above; ``shot="rounded gaussian"``: n = round(N(λ, λ))."""
    half = 12.0 * np.sqrt(lam) + 20.0
    if shot == "poisson":
        n = np.arange(0, int(lam + half))
        p = stats.poisson.pmf(n, lam)
    else:
        n = np.arange(int(lam - half), int(lam + half))
        p = stats.norm.cdf(n + 0.5, lam, np.sqrt(lam)) - stats.norm.cdf(n - 0.5, lam, np.sqrt(lam))
    K, spread = cfg.gain_dn_per_e, 12.0 * np.sqrt(lam + cfg.read_noise_e**2) + 20.0
    d0 = int(max(0, np.floor(cfg.offset_dn + K * (lam - spread))))
    d1 = int(min(cfg.max_dn, np.ceil(cfg.offset_dn + K * (lam + spread))))
    d = np.arange(d0, d1 + 1)
    edges = (np.concatenate([[-np.inf], d[1:] - 0.5, [np.inf]]) - cfg.offset_dn) / K
    cdf = stats.norm.cdf((edges[None, :] - n[:, None]) / cfg.read_noise_e)
    return d0, p @ np.diff(cdf, axis=1)


def pooled(p0: np.ndarray, n: int, *others) -> list[np.ndarray]:
    """Bins of ``p0`` expecting ≥ MIN_EXPECTED of ``n``, the tails pooled into the first and last; ``others``
    (a pmf or counts over the same values) pooled alike."""
    keep = np.flatnonzero(n * p0 >= MIN_EXPECTED)
    lo, hi = keep[0], keep[-1]
    return [np.concatenate([[a[:lo + 1].sum()], a[lo + 1:hi], [a[hi:].sum()]]) for a in (p0, *others)]


def chi2_pvalue(dn: np.ndarray, law: tuple[int, np.ndarray]) -> float:
    d0, p0 = law
    counts = np.bincount(np.clip(dn.ravel().astype(np.int64) - d0, 0, p0.size - 1), minlength=p0.size).astype(float)
    q0, c = pooled(p0, dn.size, counts)
    e = dn.size * q0
    return float(stats.chi2.sf(np.sum((c - e) ** 2 / e), q0.size - 1))


def power_against_rounded_gaussian(cfg: DetectorConfig, lam: float, n: int) -> float:
    (d0, p0), (d1, p1) = dn_pmf(cfg, lam), dn_pmf(cfg, lam, "rounded gaussian")
    assert d0 == d1
    q0, q1 = pooled(p0, n, p1)
    df = q0.size - 1
    return float(stats.ncx2.sf(stats.chi2.isf(ALPHA, df), df, n * np.sum((q1 - q0) ** 2 / q0)))


def flat_field(cfg: DetectorConfig, lam: float, n: int, seed: int) -> np.ndarray:
    photons = (lam - cfg.dark_current_e_per_s * cfg.exposure_s) / cfg.quantum_efficiency
    assert photons >= 0
    return apply_detector(np.full((n // 1024 if n >= 1024 else 1, min(n, 1024)), photons), cfg, seed=seed).dn


def rounded_gaussian_shot(lam, u, small=30.0, *, out=None, work=None):
    """The mutant: a rounded Gaussian with the Poisson law's mean and variance, one uniform per pixel."""
    lam64 = np.asarray(lam, np.float64)
    z = special.ndtri(np.clip(np.asarray(u, np.float64), 1e-12, 1 - 1e-12))
    k = np.floor(lam64 + np.sqrt(lam64) * z + 0.5)
    if out is None:
        return k.astype(np.asarray(lam).dtype)
    np.copyto(out, k, casting="unsafe")
    return out


@pytest.mark.parametrize("name, table, lam, n", CASES, ids=[c[0] for c in CASES])
def test_low_count_frames_follow_poisson_convolved_with_the_read_noise(name, table, lam, n):
    cfg = config(table)
    p0 = dn_pmf(cfg, lam)
    assert abs(p0[1].sum() - 1.0) < 1e-9
    assert power_against_rounded_gaussian(cfg, lam, n) >= 0.99
    assert chi2_pvalue(flat_field(cfg, lam, n, seed=2024), p0) > ALPHA


@pytest.mark.parametrize("name, table, lam, n", CASES, ids=[c[0] for c in CASES])
def test_the_same_frames_with_rounded_gaussian_shot_noise_are_rejected(monkeypatch, name, table, lam, n):
    """The χ² sees the mutant that passes every moment test: same seeds, the shot noise's law changed."""
    import rigsim.detector.model as model

    cfg = config(table)
    monkeypatch.setattr(model, "poisson_inverse_cdf", rounded_gaussian_shot)
    assert chi2_pvalue(flat_field(cfg, lam, n, seed=2024), dn_pmf(cfg, lam)) < ALPHA


def measured_rates(seeds: int = 200) -> None:  # pragma: no cover - the documented power measurement
    """Rejection rates over ``seeds`` seeds of the true chain (≈ α) and of the mutant (≈ the power)."""
    import rigsim.detector.model as model

    real = model.poisson_inverse_cdf
    print(f"{'case':40s} {'λ e⁻':>6s} {'pixels':>8s} {'power':>7s} {'true: rejected':>15s} {'mutant: rejected':>17s}")
    for name, table, lam, n in CASES:
        cfg = config(table)
        p0 = dn_pmf(cfg, lam)
        rates = []
        for shot in (real, rounded_gaussian_shot):
            model.poisson_inverse_cdf = shot
            rates.append(np.mean([chi2_pvalue(flat_field(cfg, lam, n, seed=s), p0) < ALPHA for s in range(seeds)]))
        model.poisson_inverse_cdf = real
        print(f"{name:40s} {lam:6.0f} {n:8d} {power_against_rounded_gaussian(cfg, lam, n):7.4f} "
              f"{rates[0]:15.3f} {rates[1]:17.3f}")


if __name__ == "__main__":  # pragma: no cover
    measured_rates(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
