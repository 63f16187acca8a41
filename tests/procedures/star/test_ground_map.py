"""The ground calibration of the lens's centroid shift (``[nominal] centroid_map = "traced_lens"``):
the bench measures a known shift, the pipeline subtracts the map, and on traced frames the corrected
centroids of the identified stars lie closer to the truth."""

from __future__ import annotations

import numpy as np
import pytest

from rigsim.errors import RigError
from rigsim.optics.star_centroid_map import CentroidMap
from rigsim.procedures.star.ground_map import bench_centroids, fill_missing, ground_centroid_map
from rigsim.procedures.star.pipeline import StarPipeline
from rigsim.procedures.star.run import compare, generate
from rigsim.rig.load import parse_model
from rigsim.rig.star import StarRig
from rigsim.truth.star import StarSky


def _with_map(rig, **upd):
    return rig.model_copy(update={"nominal": rig.nominal.model_copy(update={"centroid_map": "traced_lens", **upd})})


def _gaussian_bins(n, os_, R, sigma_px, du=0.0, dv=0.0):
    c = (np.arange(n) + 0.5) / os_ - R
    g = np.exp(-0.5 * ((c[None, :] - du) ** 2 + (c[:, None] - dv) ** 2) / sigma_px ** 2)
    return g / g.sum()


def test_the_bench_measures_a_known_shift(star_rig):
    """A Gaussian PSF displaced by (du, dv) in the table's layout: the bench's pipeline extraction finds
    exactly that shift (the Gaussian fit is unbiased on a Gaussian)."""
    nom = _with_map(star_rig).nominal_rig()
    os_, R = 4, 5
    n = 2 * R * os_
    shifts = [(0.0, 0.0), (0.25, -0.5), (-0.4, 0.3)]
    psfs = np.stack([_gaussian_bins(n, os_, R, nom.sensor.psf_sigma_px, du, dv) for du, dv in shifts])
    got = bench_centroids(psfs, os_, R, nom)
    np.testing.assert_allclose(got, shifts, atol=2e-3)


def test_lost_nodes_are_filled_from_their_neighbours():
    s = np.zeros((5, 5, 2))
    s[..., 0] = np.arange(5)[:, None]
    s[2, 2] = np.nan
    s[0, 0] = np.nan
    f = fill_missing(s)
    assert f[2, 2, 0] == pytest.approx(2.0) and f[0, 0, 0] == pytest.approx(2.0 / 3.0)
    assert np.all(np.isfinite(f))


def test_the_map_is_none_by_default_and_its_bad_values_are_named(star_rig):
    assert star_rig.nominal.centroid_map == "none" and star_rig.nominal_rig().sensor.centroid_map is None
    assert ground_centroid_map(star_rig.nominal_rig()) is None
    nom = {"focal_length_mm": 43.3, "principal_point_px": [511.5, 511.5]}
    with pytest.raises(RigError, match=r"nominal\.centroid_map` = 'bench'.*allowed: one of 'none', 'traced_lens'"):
        parse_model(StarRig, {"name": "x", "nominal": {**nom, "centroid_map": "bench"}}, "f.toml")
    with pytest.raises(RigError, match=r"nominal\.centroid_map_sigma_px` = -1.*≥ 0"):
        parse_model(StarRig, {"name": "x", "nominal": {**nom, "centroid_map_sigma_px": -1}}, "f.toml")


@pytest.fixture(scope="module")
def traced_run(star_rig, star_sky):
    """Three frames of the slew with the traced PSF, through the pipeline without and with the map, with the
    Gaussian fit (the centroider the map corrects; the forward model needs no map: docs/effects-star.md)."""
    rig = star_rig.model_copy(update={"effects": star_rig.effects.only(["traced_psf"]),
                                      "sequence": star_rig.sequence.model_copy(update={"n_frames": 3}),
                                      "calibration": star_rig.calibration.model_copy(update={"centroid_method": "gauss"})})
    sky = StarSky(rig, sky=star_sky.sky)
    held, truths = [], []
    for obs, truth, _fr in generate(rig, seed=0, sky=sky):
        held.append(obs)
        truths.append(truth)
    out = {}
    for name, r in (("off", rig), ("on", _with_map(rig))):
        p = StarPipeline(r.nominal_rig(), sky.sky)
        p.set_sequence_pattern(held)
        for o in held:
            p.add(o)
        out[name] = p
    return truths, out


def _errors(p, truths):
    """(measured − truth) of the identified stars, matched by HIP."""
    err = []
    for tr, usable, ident in zip(truths, p.usable, p.ident):
        pos = {int(h): i for i, h in enumerate(tr.hip)}
        for oi, h in zip(ident.obs_index, ident.hip):
            err.append(usable.uv[oi] - tr.uv[pos[int(h)]])
    return np.array(err)


@pytest.mark.slow  # three traced frames through two pipelines (~10 s): the map corrects the Gaussian fit, no longer the default
def test_corrected_centroids_of_identified_stars_are_closer_to_the_truth(traced_run):
    """Measured on seed 0's three frames (91 identified stars, the same without and with the map):
    0.0988 px rms per axis without, 0.0914 px with (−7.5 %); the same stars in the same frames, so
    the difference is the map's alone, not noise. With the map's sign flipped: 0.133 px."""
    truths, pipes = traced_run
    off, on = _errors(pipes["off"], truths), _errors(pipes["on"], truths)
    assert len(off) == len(on) >= 80
    rms_off, rms_on = np.sqrt(np.mean(off ** 2)), np.sqrt(np.mean(on ** 2))
    assert rms_on < 0.95 * rms_off, (rms_off, rms_on)
    # the correction moved the centroids by the map's shift: with it flipped they land further away
    wrong = 2.0 * off - on                                      # measured + map instead of measured − map
    assert np.sqrt(np.mean(wrong ** 2)) > rms_off
    cmap = pipes["on"].centroid_map
    assert isinstance(cmap, CentroidMap) and np.abs(cmap.shift).max() > 0.2


@pytest.mark.slow
def test_the_map_removes_most_of_the_batch_focal_length_bias(star_rig, star_sky):
    """The whole 20-frame slew with the traced PSF (seed 0). The batch LSQ's f error: −1.62 px without the
    map (11 of its σ = 0.148 px), +0.04 px with it; the identified stars' centroid error 0.0997, 0.0946
    px rms → 0.0906, 0.0862 px. The test: the bias is beyond 5σ without the map and within 3σ with it. The batch σ
with the map is 0.148-0.166 px (it follows the centroider's σ), so the 3σ band is asked to be below 0.35 of the
bias it must resolve (3σ = 0.50 px against 1.63 px)."""
    rig = star_rig.model_copy(update={"effects": star_rig.effects.only(["traced_psf"]),  # the Gaussian fit's bias
                                      "calibration": star_rig.calibration.model_copy(update={"centroid_method": "gauss"})})
    sky = StarSky(rig, sky=star_sky.sky)
    held, truths = [], []
    for obs, truth, _fr in generate(rig, seed=0, sky=sky):
        held.append(obs)
        truths.append(truth)
    f_err, f_sig = {}, {}
    for name, r in (("off", rig), ("on", _with_map(rig))):
        p = StarPipeline(r.nominal_rig(), sky.sky)
        p.set_sequence_pattern(held)
        for o in held:
            p.add(o)
        out = p.calibrate()
        f_err[name] = float(out.batch.theta[0] - rig.sensor.f_px)
        f_sig[name] = float(out.batch.sigma[0])
        assert compare(out, truths, r, sky)[0]["wrong"] == 0
    assert f_err["off"] < -5.0 * f_sig["off"]
    assert abs(f_err["on"]) < 3.0 * f_sig["on"] < 0.35 * abs(f_err["off"])


def test_the_map_is_shared_through_the_cache_folder_and_measured_again_when_it_does_not_fit(star_rig, tmp_path,
                                                                                          monkeypatch):
    """Another process reads the measured map from the cache folder (every node as measured); a file that does not
    fit (a NaN shift, a shape that is not nodes × nodes × 2, tangents out of order) is measured again. The bench
    itself is replaced by a known map here: its measurement is the other tests' subject."""
    import json

    from rigsim.procedures.star import ground_map as gm

    monkeypatch.setenv("RIGSIM_CACHE_DIR", str(tmp_path))
    rng = np.random.default_rng(2)
    known = {"tan_x": np.linspace(-0.2, 0.2, 5).tolist(), "tan_y": np.linspace(-0.15, 0.15, 4).tolist(),
             "shift_px": (rng.normal(0.0, 0.3, (5, 4, 2)) / 7.0).tolist()}
    measured = []
    monkeypatch.setattr(gm, "_measured_map", lambda nominal: measured.append(1) or known)
    nominal = _with_map(star_rig).nominal_rig()

    def fresh():
        monkeypatch.setattr(gm, "_CACHE", {})
        return gm.ground_centroid_map(nominal)

    first = fresh()
    assert len(measured) == 1 and np.array_equal(first.shift, np.array(known["shift_px"]))
    again = fresh()
    assert len(measured) == 1                                                   # read, not measured
    assert np.array_equal(again.shift, first.shift) and np.array_equal(again.tan_x, first.tan_x)
    (f,) = (tmp_path / "star-ground-map").iterdir()
    doc = json.loads(f.read_text())
    bad_shift = np.array(known["shift_px"])
    bad_shift[2, 1, 0] = np.nan
    for spoil in ({"shift_px": bad_shift.tolist()}, {"shift_px": known["shift_px"][:-1]},
                  {"tan_x": known["tan_x"][::-1]}):
        f.write_text(json.dumps({**doc, "value": {**doc["value"], **spoil}}))
        n = len(measured)
        assert np.array_equal(fresh().shift, first.shift) and len(measured) == n + 1
