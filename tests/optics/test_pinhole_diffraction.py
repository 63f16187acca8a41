"""The pinhole's diffraction PSF (rigsim.optics.pinhole_diffraction) against closed forms: the Airy
pattern of a circular aperture (first zero, peak, encircled energy), the Fresnel on-axis intensity,
Parseval, centrosymmetry, and the 1/cos²θ elongation of an oblique pinhole's pattern."""

import math

import numpy as np
import pytest
from scipy.special import j0, j1

from rigsim.optics.pinhole_diffraction import PinholePSF, band_weights, kernel_moments

F, D, LAM = 3.0, 0.1, 550.0  # the rig's sun sensor: f 3 mm, pinhole 0.1 mm; 550 nm
FX = F / 0.011  # 11 µm pixels
R0 = 1.22 * LAM * 1e-6 * F / D / 0.011  # the Airy first zero on axis, px (1.83)


def mono(propagation="fraunhofer", thickness=0.0, samples=96):
    return PinholePSF(D, thickness, F, (LAM,), (1.0,), propagation, samples)


def test_on_axis_fraunhofer_is_the_airy_pattern():
    """Peak πa²/(λf)² per mm²; zero at 1.22 λ f / D (1.22 λ/D in angle); 83.8 % inside it
    (1 − J0²(x) − J1²(x) at x = 3.8317); the Fresnel PSF (N = 1.5) fails every one of these."""
    step = R0 / 20
    K = mono().kernel([0, 0, 1], FX, FX, 3 * R0, step)
    c = K.shape[0] // 2
    area = (0.011 * step) ** 2
    peak = math.pi * (D / 2) ** 2 / (LAM * 1e-6 * F) ** 2 * area
    assert K[c, c] == pytest.approx(peak, rel=2e-3)
    assert K[c, c + 20] < 2e-4 * K[c, c] and K[c + 20, c] < 2e-4 * K[c, c]  # the first dark ring
    assert K[c, c + 15] > 0.05 * K[c, c]
    off = (np.arange(K.shape[0]) - c) * step
    U, V = np.meshgrid(off, off)
    ee = K[np.hypot(U, V) < R0].sum()
    x = 3.8317
    assert 1 - j0(x) ** 2 - j1(x) ** 2 == pytest.approx(0.838, abs=1e-3)
    assert ee == pytest.approx(1 - j0(x) ** 2 - j1(x) ** 2, abs=4e-3)
    Kf = mono("fresnel").kernel([0, 0, 1], FX, FX, 3 * R0, step)
    assert Kf[c, c] < 0.2 * peak  # 0.081 of it at N = 1.52


def test_fresnel_on_axis_intensity_is_the_closed_form():
    """On axis the aperture's Fresnel integral is λf (e^{iπN} − 1)/i: I(0) = 4 sin²(πN/2)/(πa²) of the
    light through it, N = a²/(λf) = 1.52; Fraunhofer gives πa²/(λf)², 12× more."""
    a, lam = D / 2, LAM * 1e-6
    N = a * a / (lam * F)
    assert mono("fresnel").fresnel_number(LAM) == pytest.approx(N)
    K = mono("fresnel").kernel([0, 0, 1], FX, FX, 1.0, 0.5)
    area = (0.011 * 0.5) ** 2
    assert K[2, 2] == pytest.approx(4 * math.sin(math.pi * N / 2) ** 2 / (math.pi * a * a) * area, rel=1e-2)
    assert K[2, 2] < 0.1 * math.pi * a * a / (lam * F) ** 2 * area


def test_the_band_psf_is_normalised_centrosymmetric_and_the_window_keeps_most():
    """Parseval: the PSF holds all the light through the opening (sum → 1 over a wide window, never
    more); the opening is centrosymmetric so its intensity pattern is too (the continuous centroid
    of a spot does not move); a thick mask off axis included."""
    psf = PinholePSF(D, 0.025, F)
    s = np.array([math.sin(math.radians(40)) * 0.6, math.sin(math.radians(40)) * 0.8, math.cos(math.radians(40))])
    K = psf.kernel(s, FX, FX * 1.0004, 48, 0.5)
    assert 0.975 < K.sum() <= 1.0 + 1e-3  # the tails (∝ 1/r³) hold 1.5 % beyond 48 px
    assert np.abs(K - K[::-1, ::-1]).max() < 1e-12 * K.max() * 1e3
    mom = kernel_moments(K, 0.5)
    assert np.abs(mom["centroid_px"]).max() < 1e-9
    w = band_weights((450, 550, 650, 750, 850))
    assert w.sum() == pytest.approx(1.0) and int(np.argmax(w)) in (1, 2)  # 5800 K × silicon peaks at 550–650 nm


def test_off_axis_pattern_is_stretched_along_the_field_by_one_over_cos_squared():
    """At θ = 50° the opening seen along the chief ray is D cos θ wide along the field, the distance
    f / cos θ, and the detector is oblique by θ: the first zero lies at 1.22 λ f / (D cos³θ) along
    the field and 1.22 λ f / (D cos θ) across (ratio 1/cos²θ = 2.42); the on-axis zero is not one."""
    th = math.radians(50.0)
    s = np.array([math.sin(th), 0.0, math.cos(th)])  # field direction: +u
    along, across = R0 / math.cos(th) ** 3, R0 / math.cos(th)
    step = across / 20
    K = mono(samples=128).kernel(s, FX, FX, 1.2 * along, step)
    c = K.shape[0] // 2
    ia = round(along / step)
    assert abs(ia * step - along) < 0.5 * step
    assert K[c + 20, c] < 5e-4 * K[c, c] and K[c - 20, c] < 5e-4 * K[c, c]  # across (rows: v)
    near = K[c, c + ia - 1:c + ia + 2].min()  # the zero along the field, within a sample
    assert near < 5e-3 * K[c, c]
    assert K[c, c + 20] > 0.3 * K[c, c]  # across's zero is bright along the field
    assert K[c, c + round(R0 / step)] > 0.5 * K[c, c]  # and so is the on-axis zero
