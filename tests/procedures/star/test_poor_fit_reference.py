"""Poor PSF fits judged against the frame (``[calibration] poor_fit_reference = "frame"``).

A traced lens's stars (defocus rings on axis, coma in the corners) are not Gaussians: against the
noise model alone a third of the usable stars of a frame fail the fit test, although nothing is wrong
with them. Judged against their frame's other stars, none fails; a particle track laid across a star
still does. On Gaussian frames the two references agree."""

from __future__ import annotations

import numpy as np
import pytest

from rigsim.imaging import Flag
from rigsim.imaging.stars import MIN_FRAME_STARS, extract_stars, frame_poor_fits
from rigsim.render.star import render_frame
from rigsim.truth.star import StarSky

POOR = int(Flag.POOR_FIT)


@pytest.fixture(scope="module")
def traced(star_rig, star_sky):
    rig = star_rig.model_copy(update={"effects": star_rig.effects.only(["traced_psf"])})
    return StarSky(rig, sky=star_sky.sky)


def _extract(dn, rig, reference):
    s = rig.sensor
    return extract_stars(dn, s.detector, s.psf_sigma_px, repair_single_pixels=True, poor_fit=reference)


def _poor_usable(o) -> int:
    return int((o.usable & ((o.flags & POOR) != 0)).sum())


def test_traced_stars_are_poor_against_the_model_and_fine_against_their_frame(star_rig, traced):
    fr = render_frame(traced, np.eye(3), seed=0, fits_header=False)
    dn = fr.dn.astype(float)
    model, frame = _extract(dn, star_rig, "model"), _extract(dn, star_rig, "frame")
    np.testing.assert_array_equal(model.uv, frame.uv)       # the reference changes flags only
    assert model.usable.sum() >= 20
    assert _poor_usable(model) >= 0.25 * model.usable.sum()  # measured: 13 of 29
    assert _poor_usable(frame) == 0


def test_a_particle_track_across_a_star_is_still_a_poor_fit(star_rig, traced):
    fr = render_frame(traced, np.eye(3), seed=0, fits_header=False)
    dn = fr.dn.astype(float)
    clean = _extract(dn, star_rig, "frame")
    idx = np.flatnonzero(clean.usable)
    # three bright stars well apart; a 3-pixel track 2 px beside each core, as bright as the star's peak
    # (a minimum-ionising particle leaves ~1e3–1e4 e⁻ in a few pixels)
    order = idx[np.argsort(-clean.flux[idx])]
    hit: list[int] = []
    for i in order:
        if all(np.hypot(*(clean.uv[i] - clean.uv[j])) > 30 for j in hit):
            hit.append(int(i))
        if len(hit) == 3:
            break
    for i in hit:
        u, v = np.floor(clean.uv[i] + 0.5).astype(int)
        peak = dn[v - 1:v + 2, u - 1:u + 2].max() - star_rig.sensor.detector.offset_dn
        dn[v + 2, u - 1:u + 2] += peak
    hitobs = _extract(dn, star_rig, "frame")
    for i in hit:
        k = int(np.argmin(np.hypot(*(hitobs.uv - clean.uv[i]).T)))
        moved = float(np.hypot(*(hitobs.uv[k] - clean.uv[i])))
        assert moved > 0.1                                 # the track pulls the centroid: it must go
        assert hitobs.flags[k] & POOR or not hitobs.usable[k], (i, moved, hitobs.flags[k])
    assert _poor_usable(hitobs) <= len(hit)


def test_on_gaussian_frames_the_references_agree(star_rig, star_sky):
    fr = render_frame(star_sky, np.eye(3), seed=0, fits_header=False)
    dn = fr.dn.astype(float)
    model, frame = _extract(dn, star_rig, "model"), _extract(dn, star_rig, "frame")
    np.testing.assert_array_equal(model.flags, frame.flags)


def test_the_frame_test_needs_a_population():
    chi2 = np.array([1.0, 1.1, 50.0])
    snr = np.array([10.0, 20.0, 10.0])
    assert frame_poor_fits(chi2, snr, np.ones(3, bool)).all()      # too few: the model test decides
    n = MIN_FRAME_STARS + 4
    snr = np.linspace(20, 200, n)
    chi2 = 1.0 + 0.02 * snr ** 2          # the same unexplained share for every star
    chi2[3] += 400.0                       # one star with residual of its own
    out = frame_poor_fits(chi2, snr, np.ones(n, bool))
    assert out.tolist() == [k == 3 for k in range(n)]
    judged = np.ones(n, bool)
    judged[3] = False                      # a star not judged (flagged otherwise) is not an outlier's reference
    assert frame_poor_fits(chi2, snr, judged)[3]


def test_bad_reference_is_refused(star_rig):
    with pytest.raises(ValueError, match="poor_fit = 'chi2'"):
        _extract(np.zeros((64, 64)), star_rig, "chi2")
