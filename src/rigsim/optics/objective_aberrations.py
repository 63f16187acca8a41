"""The camera objective's third-order (Seidel) aberrations at one field point, as a wavefront over
its pupil, and the geometric PSF they give the laser loop's spot.

A Seidel wavefront at relative field H (here the CMOS's field point, H = 1), in normalised pupil
coordinates (x along the sagittal direction, y along the tangential one, pupil radius a):

    W(x, y) = W131·y·(x² + y²)   (coma)   +   W222·y²   (astigmatism)

(lengths in mm). A ray crossing the pupil at (x, y) lands displaced from the chief ray by the
transverse ray aberration ε = −(F/a)·∇W (geometric optics). The loop crosses the objective twice
(out to the prism facet, normal to the beam, and back along the same rays: autocollimation), so
its wavefront error is twice the objective's: the renderer applies W_loop = 2W on the return
crossing. Closed forms for a uniformly filled pupil of relative radius ``fill`` (⟨x²⟩ = ⟨y²⟩ = fill²/4):

* coma moves the spot's centroid along the tangential direction by −(F/a)·2·W131·fill²
  (⟨∂W/∂y⟩ = W131·⟨x² + 3y²⟩ = W131·fill², doubled), and not at all sagittally;
* astigmatism adds the variance (F/a)²·16·W222²·⟨y²⟩ = 4(F/a)²W222²·fill² tangentially and none
  sagittally (the sagittal and tangential foci split by 8(F/a)²·W222 along the axis, doubled in the loop).
"""

from __future__ import annotations

import numpy as np

__all__ = ["centroid_shift_mm", "loop_transverse_aberration_mm", "sample_pupil", "tangential_variance_mm2"]


def loop_transverse_aberration_mm(x, y, *, coma_mm: float, astig_mm: float, f_over_a: float) -> tuple[np.ndarray, np.ndarray]:
    """Transverse aberration (sagittal, tangential) in mm on the focal plane of the loop (2W) for rays
    through the normalised pupil point (x, y)."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    dwx = coma_mm * 2.0 * x * y
    dwy = coma_mm * (x**2 + 3.0 * y**2) + astig_mm * 2.0 * y
    return -f_over_a * 2.0 * dwx, -f_over_a * 2.0 * dwy


def centroid_shift_mm(*, coma_mm: float, f_over_a: float, fill: float) -> float:
    """Tangential centroid shift of the loop's spot (uniform pupil of relative radius ``fill``)."""
    return -f_over_a * 2.0 * coma_mm * fill**2


def tangential_variance_mm2(*, astig_mm: float, f_over_a: float, fill: float) -> float:
    """Variance astigmatism alone adds to the loop's spot along the tangential direction."""
    return 4.0 * f_over_a**2 * astig_mm**2 * fill**2


def sample_pupil(rng: np.random.Generator, n: int, fill: float) -> tuple[np.ndarray, np.ndarray]:
    """n points uniform on the pupil disk of relative radius ``fill`` (the renderer's sampling)."""
    r = fill * np.sqrt(rng.random(n))
    t = 2.0 * np.pi * rng.random(n)
    return r * np.cos(t), r * np.sin(t)
