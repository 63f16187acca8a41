"""The twin's figures and tables: real | rendered | difference per frame, and the measured
quantities side by side (stars per magnitude bin, PSF FWHM across the field, the sky's radial
profile, the sky noise's histogram)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rigsim.procedures.star.twin import MAG_BINS, NOISE_EDGES, RHO_BINS

__all__ = ["frames_figure", "profiles_figure", "table_markdown"]


def _stretch(img, lo, hi):
    return np.clip((np.asarray(img, float) - lo) / max(hi - lo, 1e-9), 0, 1)


def frames_figure(path, names, reals, twins, *, crop=None) -> Path:
    """One row per frame: real, twin (same grey scale), and real − twin (±5σ of the sky noise).
    ``crop``: (v0, v1, u0, u1) to show a part of every frame at full resolution."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(reals)
    fig, axes = plt.subplots(n, 3, figsize=(13.5, 3.4 * n), squeeze=False)
    for k, (name, r, t) in enumerate(zip(names, reals, twins)):
        r, t = np.asarray(r, float), np.asarray(t, float)
        if crop is not None:
            v0, v1, u0, u1 = crop
            r, t = r[v0:v1, u0:u1], t[v0:v1, u0:u1]
        lo, hi = np.percentile(r, [1, 99.7])
        d = r - t
        s = 1.4826 * np.median(np.abs(d - np.median(d)))
        for ax, im, title, kw in ((axes[k, 0], _stretch(r, lo, hi), f"real: {name}", {"cmap": "gray"}),
                                  (axes[k, 1], _stretch(t, lo, hi), "rendered twin (same grey scale)", {"cmap": "gray"}),
                                  (axes[k, 2], d, f"real − twin (±5σ = ±{5 * s:.0f} DN)",
                                   {"cmap": "RdBu_r", "vmin": -5 * s, "vmax": 5 * s})):
            ax.imshow(im, interpolation="nearest", **kw)
            ax.set_title(title, fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def profiles_figure(path, real, twin) -> Path:
    """Four panels: identified stars per Hp bin, PSF FWHM against the field radius, the sky's radial
    profile of every frame, and the sky noise's histogram (pooled), real against twin."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 4, figsize=(17, 3.8))
    x = np.arange(len(MAG_BINS) - 1)
    R = np.sum([s.stars_per_mag_bin for s in real], axis=0)
    T = np.sum([s.stars_per_mag_bin for s in twin], axis=0)
    ax[0].bar(x - 0.2, R, 0.4, label="real")
    ax[0].bar(x + 0.2, T, 0.4, label="twin")
    ax[0].set_xticks(x, [f"{a:g}–{b:g}" for a, b in zip(MAG_BINS[:-1], MAG_BINS[1:])], fontsize=8)
    ax[0].set_xlabel("Hipparcos magnitude Hp")
    ax[0].set_ylabel("identified stars (all frames)")
    ax[0].legend()
    rc = 0.5 * (np.array(RHO_BINS[:-1]) + np.array(RHO_BINS[1:]))
    for stats, lab, mk in ((real, "real", "o-"), (twin, "twin", "s--")):
        f = [np.median([s.fwhm_px_by_rho[k] for s in stats if s.fwhm_px_by_rho[k] is not None] or [np.nan])
             for k in range(len(rc))]
        ax[1].plot(rc, f, mk, label=lab)
    ax[1].set_xlabel("field radius ρ (1 = corner)")
    ax[1].set_ylabel("PSF FWHM (px), bright stars")
    ax[1].legend()
    for k, (r, t) in enumerate(zip(real, twin)):
        line, = ax[2].plot(rc, r.level_profile_dn, "o-", label=f"frame {k} real")
        ax[2].plot(rc, t.level_profile_dn, "s--", color=line.get_color(), label=f"frame {k} twin")
    ax[2].set_xlabel("field radius ρ (1 = corner)")
    ax[2].set_ylabel("sky level (DN)")
    ax[2].legend(fontsize=7, ncol=2)
    c = 0.5 * (np.array(NOISE_EDGES[:-1]) + np.array(NOISE_EDGES[1:]))
    hr = np.sum([s.noise_hist for s in real], axis=0)
    ht = np.sum([s.noise_hist for s in twin], axis=0)
    ax[3].semilogy(c, hr / hr.sum(), "o-", label="real")
    ax[3].semilogy(c, ht / ht.sum(), "s--", label="twin")
    ax[3].semilogy(c, np.exp(-0.5 * c**2) / np.sqrt(2 * np.pi) * (c[1] - c[0]), "k:", label="unit Gaussian")
    ax[3].set_xlabel("(pixel − sky) / sky noise, star pixels left out")
    ax[3].set_ylabel("share of pixels")
    ax[3].legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def table_markdown(rows) -> str:
    """The comparison as a Markdown table."""
    out = ["| quantity | where | real | twin | difference | tolerance | within |", "|---|---|---:|---:|---:|---:|:---:|"]
    for r in rows:
        fmt = (lambda v: f"{v:.4g}" if isinstance(v, float) else str(v))
        out.append(f"| {r['quantity']} | {r['bin']} | {fmt(r['real'])} | {fmt(r['twin'])} | {100 * r['difference']:.1f} % "
                   f"| ±{100 * r['tolerance']:.0f} % | {'yes' if r['within'] else '**no**'} |")
    return "\n".join(out) + "\n"
