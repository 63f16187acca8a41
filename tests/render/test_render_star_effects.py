"""The star sensor's [effects] in rendered frames: each one adds exactly what its model says, where
it says, and nothing else (the detector noise of the other pixels is unchanged)."""

from __future__ import annotations

import numpy as np
import pytest

from rigsim.detector.defects import deposit_cosmic_rays, hot_pixel_rates
from rigsim.errors import RigError
from rigsim.optics.stray_light import stray_light_mag_map
from rigsim.render.star import render_frame
from rigsim.rig.load import parse_model
from rigsim.rig.star import StarRig
from rigsim.truth.star import StarSky


def _frames(star_rig, star_sky, names, noiseless, **values):
    eff = star_rig.effects.only(names)
    for name, upd in values.items():
        eff = eff.model_copy(update={name: getattr(eff, name).model_copy(update=upd)})
    sky = StarSky(star_rig.model_copy(update={"effects": eff}), sky=star_sky.sky)
    R = np.eye(3)
    ideal = render_frame(star_sky, R, seed=5, noiseless=noiseless, fits_header=False)
    with_fx = render_frame(sky, R, seed=5, noiseless=noiseless, fits_header=False)
    return ideal, with_fx, sky


def _linear(fr):
    """Pixels where neither frame clips (expected DN is linear in electrons there)."""
    return ~fr.detector.saturated


def test_effects_are_off_by_default(star_rig):
    assert star_rig.effects.enabled == ()


def test_stray_light_adds_the_gradient_photons_through_the_quantum_efficiency(star_rig, star_sky):
    ideal, fx, sky = _frames(star_rig, star_sky, ["stray_light"], True)
    d = star_rig.sensor.detector
    st = sky.rig.effects.stray_light
    mag = stray_light_mag_map(sky.shape_hw, sky.pixel_arcsec / 3600.0, direction_deg=st.direction_deg,
                              edge_mag_per_arcsec2=st.edge_mag_per_arcsec2, falloff_mag_per_deg=st.falloff_mag_per_deg)
    want = d.gain_dn_per_e * d.quantum_efficiency * sky.photons(mag) * sky.pixel_arcsec**2
    ok = _linear(fx) & _linear(ideal)
    np.testing.assert_allclose((fx.detector.expected_dn - ideal.detector.expected_dn)[ok], want[ok], rtol=1e-9)
    assert want[:, -1].mean() > 30 * want[:, 0].mean()                     # 6 mag across the field
    assert fx.sidecar["truth"]["effects"]["stray_light"]["photons_per_px_max"] == pytest.approx(want.max() / 0.06)


def test_hot_pixels_add_their_dark_current_and_leave_every_other_pixel_alone(star_rig, star_sky):
    H, W = star_sky.shape_hw
    hp = star_rig.effects.hot_pixels
    rates = hot_pixel_rates(star_rig.sensor.detector.sensor_seed, W, (0, H), (0, W), fraction=hp.fraction,
                            threshold_e_per_s=hp.threshold_e_per_s, mean_excess_e_per_s=hp.mean_excess_e_per_s)
    hot = rates > 0
    d = star_rig.sensor.detector
    ideal, fx, _ = _frames(star_rig, star_sky, ["hot_pixels"], True)
    ok = _linear(fx)
    np.testing.assert_allclose((fx.detector.expected_dn - ideal.detector.expected_dn)[ok],
                               (d.gain_dn_per_e * rates * d.exposure_s)[ok], rtol=1e-6, atol=1e-9)
    ideal, fx, _ = _frames(star_rig, star_sky, ["hot_pixels"], False)
    np.testing.assert_array_equal(fx.dn[~hot], ideal.dn[~hot])              # the noise stream is unchanged
    excess = (fx.dn.astype(float) - ideal.dn)[hot & _linear(fx)]
    mean_e = rates[hot & _linear(fx)] * d.exposure_s
    # Poisson(rate·t) electrons: mean and spread against the model (5 standard errors)
    assert abs(excess.mean() - d.gain_dn_per_e * mean_e.mean()) < 5 * d.gain_dn_per_e * np.sqrt(mean_e.mean() / excess.size) + 0.1
    assert fx.sidecar["truth"]["effects"]["hot_pixels"]["n"] == int(hot.sum())


def test_cosmic_rays_deposit_their_charge_where_their_tracks_are(star_rig, star_sky):
    ideal, fx, sky = _frames(star_rig, star_sky, ["cosmic_rays"], False, cosmic_rays={"flux_per_cm2_s": 200.0})
    t = fx.sidecar["truth"]["effects"]["cosmic_rays"]
    assert t["n"] > 20                                                      # 200 /cm²/s × 2.36 cm² × 0.1 s ≈ 47
    from rigsim.detector.defects import CosmicRayHits

    hits = CosmicRayHits(np.array(t["start_uv_px"]), np.array(t["end_uv_px"]), np.array(t["charge_e"]))
    H, W = sky.shape_hw
    dep = deposit_cosmic_rays(hits, (0, H), (0, W))
    d = star_rig.sensor.detector
    ok = _linear(fx) & _linear(ideal)
    # the sidecar's rounded tracks move charge between neighbours at most: compare sums over the frame
    diff = fx.detector.expected_dn - ideal.detector.expected_dn
    assert diff[ok].sum() == pytest.approx(d.gain_dn_per_e * dep[ok].sum(), rel=2e-3)
    np.testing.assert_array_equal(fx.dn[dep == 0], ideal.dn[dep == 0])


def test_a_bad_effects_value_is_named(star_rig):
    data = star_rig.model_dump()
    data["effects"]["hot_pixels"]["fraction"] = 2.0
    with pytest.raises(RigError, match=r"effects\.hot_pixels\.fraction.*2\.0"):
        parse_model(StarRig, data, "star.toml")
    data["effects"]["hot_pixels"]["fraction"] = 0.01
    data["effects"]["cosmic_rays"]["enabled"] = "yes"
    with pytest.raises(RigError, match=r"effects\.cosmic_rays\.enabled"):
        parse_model(StarRig, data, "star.toml")


def _dark(star_rig):
    d = star_rig.sensor.detector
    return d.gain_dn_per_e * d.dark_mean_e + d.offset_dn


def test_vignetting_dims_the_stars_and_the_sky_by_the_relative_illumination(star_rig, star_sky):
    ideal, fx, sky = _frames(star_rig, star_sky, ["vignetting"], True, vignetting={"rho2": 0.25, "rho4": 0.1})
    H, W = sky.shape_hw
    cx, cy = star_rig.sensor.principal_point_px
    v, u = np.mgrid[0:H, 0:W]
    rho2 = ((u - cx) ** 2 + (v - cy) ** 2) / ((W / 2) ** 2 + (H / 2) ** 2)
    want = 1 - 0.25 * rho2 - 0.1 * rho2**2  # relative illumination, computed here
    ok = _linear(fx) & _linear(ideal)
    dark = _dark(star_rig)  # dark signal and offset are not light: they are not dimmed
    ratio = (fx.detector.expected_dn - dark)[ok] / (ideal.detector.expected_dn - dark)[ok]
    np.testing.assert_allclose(ratio, want[ok], rtol=1e-6)
    assert want.min() == pytest.approx(0.65, abs=0.01)  # at the corner: 1 − 0.25 − 0.1


def test_sky_glow_raises_the_sky_along_its_direction(star_rig, star_sky):
    ideal, fx, sky = _frames(star_rig, star_sky, ["sky_glow"], True, sky_glow={"slope_per_deg": 0.05, "direction_deg": 0})
    H, W = sky.shape_hw
    d = star_rig.sensor.detector
    k = d.gain_dn_per_e * d.quantum_efficiency
    deg = (np.arange(W) - (W - 1) / 2) * sky.pixel_arcsec / 3600.0
    want = k * sky.background_photons_per_px * 0.05 * deg  # added sky per column, from +u's side
    diff = fx.detector.expected_dn - ideal.detector.expected_dn
    ok = _linear(fx) & _linear(ideal)
    for col in (0, W // 4, W - 1):
        np.testing.assert_allclose(diff[ok[:, col], col], want[col], rtol=1e-9, atol=1e-12)
    assert want[-1] == pytest.approx(-want[0])


def test_a_vignetting_that_leaves_the_corner_dark_is_refused(star_rig):
    with pytest.raises(RigError, match="corner"):
        parse_model(StarRig, {"name": "x", "effects": {"vignetting": {"rho2": 0.9, "rho4": 0.5}}}, "f.toml")


def test_faint_stars_follow_the_counts_law_and_add_their_light(star_rig, star_sky):
    from scipy import stats

    from rigsim.render.star_effects import draw_faint_stars, effects_rng

    ideal, fx, sky = _frames(star_rig, star_sky, ["faint_stars"], True,
                             faint_stars={"density_per_deg2_per_mag": 3.0, "slope_per_mag": 0.4, "faint_limit_mag": 9.5})
    H, W = sky.shape_hw
    m0, m1, s = star_rig.sky.magnitude_limit, 9.5, 0.4
    area = H * W * (sky.pixel_arcsec / 3600) ** 2
    want_n = 3.0 * area * (10 ** (s * (m1 - m0)) - 1) / (s * np.log(10))  # ∫ ρ0 10^(s(m−m0)) dm over the field
    mags = np.concatenate([draw_faint_stars(sky, effects_rng(k, "faint_stars"))[1] for k in range(20)])
    assert abs(mags.size / 20 - want_n) < 4 * np.sqrt(want_n / 20)
    cdf = lambda m: (10 ** (s * (np.asarray(m) - m0)) - 1) / (10 ** (s * (m1 - m0)) - 1)  # noqa: E731
    assert stats.kstest(mags, cdf).pvalue > 1e-3
    added = (fx.detector.expected_dn - ideal.detector.expected_dn).sum()
    d = star_rig.sensor.detector
    truth = fx.sidecar["truth"]["effects"]["faint_stars"]
    light = d.gain_dn_per_e * d.quantum_efficiency * sky.photons(np.array(truth["mag"])).sum()
    assert added == pytest.approx(light, rel=0.02)  # (stars at the edge lose a little of their light)
