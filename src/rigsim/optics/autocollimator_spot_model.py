"""The autocollimator's return spot as a forward model: the image of its point reticle off a flat
mirror, through the objective, diffracted by the return pupil, pixel-integrated, as a function of
where the spot's ray centroid lies (the point the instrument's calibration reads).

The ray-optics image is the exact trace of :class:`rigsim.optics.autocollimator.AutocollimatorOptics`
(every reticle ray through the singlet, off the mirror, back through the stop and the lens: the
spherical aberration's ring, the mirror's outline clipping the pupil), histogrammed on a grid of
``step_px`` cells around its mean; it is convolved with the return pupil's Fraunhofer PSF times
the pixel's box (the renderer's diffraction, here sampled on the same fine grid, not per pixel), so
every cell holds the pixel-integrated image of a spot centred that far away. A cubic spline over
the grid gives any sub-pixel offset. The shape is computed once, for the mirror tilted to the
spot's first estimate: over the fraction of a pixel a fit moves it does not change.

The PSF is centrosymmetric, so the image's first moment is the rays' mean: the reference point of
the model is what :attr:`SpotTruth.mean_uv` is, and what the calibration's reading expects.
"""

from __future__ import annotations

import math

import numpy as np

from rigsim.optics.spot_grid import GridSpotModel, pixel_sums

__all__ = ["AutocollimatorSpotModel", "fine_diffraction_kernel"]


def fine_diffraction_kernel(optics, mirror, half_px: int, step_px: float) -> np.ndarray:
    """The return pupil's Fraunhofer PSF convolved with one pixel's box, sampled every ``step_px``
    (= 1/m) out to ±``half_px`` pixels: ``K[j, i]`` is the light a pixel centred (i·s − half_px,
    j·s − half_px) px from a point image collects. Normalised so that its samples on the integer-
    pixel sub-grid sum to 1 (the sum of all samples is m²). Same pupil as
    :meth:`AutocollimatorOptics.diffraction_kernel`, which samples the same function per pixel."""
    m = round(1.0 / step_px)
    s_min, _ = optics.kernel_sampling(half_px)
    if m < s_min:
        raise ValueError(f"step_px = {step_px!r}: the pupil needs at least {s_min} samples per pixel")
    from rigsim.optics.autocollimator import _fast_len

    n_fft = _fast_len(max(512, m * (3 * int(half_px) + 1)))
    lam = optics.objective.wavelength_nm * 1e-6
    dp = lam * optics.efl_mm * m / (n_fft * optics.pitch_mm)
    mask, c = optics.return_pupil(mirror, dp)
    if len(c) > n_fft // 2:
        raise ValueError("n_fft too small for the pupil at this sampling")
    P = np.zeros((n_fft, n_fft))
    k0 = n_fft // 2 - len(c) // 2
    P[k0:k0 + len(c), k0:k0 + len(c)] = mask
    psf = np.abs(np.fft.fft2(P)) ** 2
    nu = np.fft.fftfreq(n_fft, d=1.0 / m)  # cycles per pixel
    psf_pix = np.real(np.fft.ifft2(np.fft.fft2(psf) * np.sinc(nu)[:, None] * np.sinc(nu)[None, :]))
    idx = np.arange(-half_px * m, half_px * m + 1) % n_fft
    K = np.clip(psf_pix[np.ix_(idx, idx)], 0.0, None)
    K = 0.5 * (K + K[::-1, ::-1])
    return K * (m * m / K.sum())


class AutocollimatorSpotModel(GridSpotModel):
    """``model(u, v)``: the unit-flux pixel image, on the window of ``shape_hw`` pixels whose first
    pixel is at ``origin_uv``, of the autocollimator's return spot off ``mirror`` (a
    :class:`~rigsim.optics.autocollimator.MirrorTarget`: its outline, distance and tilt) whose ray
    centroid is at (u, v). ``optics``: the instrument (:class:`AutocollimatorOptics`, with its beam
    splitter if it has one). ``diffraction_half_px``: the PSF's half extent (None: no diffraction,
    a ray-optics image). ``n_rays``: the trace's rays; ``step_px``: the grid (1/m px).
    ``construction``: ``"optics"`` (the PSF applied to the continuous image, then the pixel's
    box) or ``"renderer"`` (as rigsim's renderer draws frames: the rays binned into pixels, then
    the per-pixel kernel; it aliases a sharp ring by up to 0.006 px). ``effects`` lists what the
    model holds."""

    def __init__(self, optics, mirror, origin_uv, shape_hw, *, diffraction_half_px: int | None = 32,
                 n_rays: int = 400_000, step_px: float = 0.125, construction: str = "optics"):
        if construction not in ("optics", "renderer"):
            raise ValueError(f"construction = {construction!r}: 'optics' or 'renderer'")
        m = round(1.0 / step_px)
        if m < 1 or abs(m * step_px - 1.0) > 1e-9:
            raise ValueError(f"step_px = {step_px!r}: must be 1/m for an integer m >= 1")
        self.origin = np.asarray(origin_uv, dtype=float).reshape(2)
        self.shape = (int(shape_hw[0]), int(shape_hw[1]))
        tr = optics.spot(mirror, n_rays=int(n_rays))
        if not tr.valid:
            raise ValueError("the mirror returns no light at this tilt: no spot model")
        self.mean_uv = np.asarray(tr.mean_uv, float)
        off = tr.bundle.uv - self.mean_uv
        w = tr.bundle.weight / tr.bundle.weight.sum()
        half_k = 0 if diffraction_half_px is None else int(diffraction_half_px)
        half = math.ceil(float(np.max(np.abs(off))) + half_k + max(self.shape) / 2.0 + 2.0)
        n = 2 * half * m + 1
        idx = np.floor(off / step_px + 0.5).astype(np.int64) + half * m
        img = np.bincount(idx[:, 1] * n + idx[:, 0], weights=w, minlength=n * n).reshape(n, n)  # [v, u]
        effects = ["reticle point image (exact trace: objective aberrations, mirror outline, stop)"]
        if optics.beam_splitter is not None:
            effects.append("beam splitter plate")
        if diffraction_half_px is None or construction == "renderer":
            # one pixel's sum: m cells (centres offset by (m-1)/2 cells)
            P = pixel_sums(img, m)
            first = ((m - 1) / 2.0 - half * m) * step_px
            if diffraction_half_px is not None:
                # rigsim's renderer: the rays binned into pixels, then that pixel image convolved with the
                # per-pixel kernel; at every sub-pixel phase that is P convolved with the kernel's samples
                # placed every m cells
                from scipy.signal import fftconvolve

                Kp = optics.diffraction_kernel(mirror, half_px=half_k)
                Ks = np.zeros((2 * half_k * m + 1, 2 * half_k * m + 1))
                Ks[::m, ::m] = Kp
                P = fftconvolve(P, Ks, mode="same")
                effects.append("return-pupil diffraction (as rigsim's renderer applies it: after pixel binning)")
        else:
            from scipy.signal import fftconvolve

            K = fine_diffraction_kernel(optics, mirror, half_k, step_px)
            P = fftconvolve(img, K, mode="same")
            first = -half * m * step_px
            effects.append("return-pupil diffraction")
        self._tabulate(P, first, step_px, origin_uv, shape_hw, effects)
