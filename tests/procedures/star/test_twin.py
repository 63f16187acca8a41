"""The twin's description of a camera: rendered frames with a known vignetting, glow, gain, PSF and
zero point go in, and :func:`describe_camera` must give those numbers back (its truth is the rig the
frames were rendered from, not the code that measures them)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rigsim.optics.sky import SkyCatalogue
from rigsim.procedures.star.twin import compare, describe_camera, frame_stats, twin_rig
from rigsim.render.star import render_frame
from rigsim.truth.star import StarSky

RHO2, RHO4 = 0.35, -0.05
SLOPES = (0.03, 0.0, 0.05)
DIRS = (90.0, 0.0, 200.0)


@pytest.fixture(scope="module")
def night(star_rig):
    s = star_rig.sensor
    det = s.detector.model_copy(update={"gain_dn_per_e": 0.5, "read_noise_e": 4.0, "offset_dn": 0.0, "dsnu_e": 0.0,
                                        "dark_current_e_per_s": 0.0, "exposure_s": 0.5, "full_well_e": 1e5})
    sensor = s.model_copy(update={"resolution_px": [512, 384], "pixel_pitch_um": 13.8, "focal_length_mm": 35.0,
                                  "principal_point_px": [258.0, 195.0], "k1": 0.1, "k2": 0.0,
                                  "psf": s.psf.model_copy(update={"sigma_px": 0.7}), "detector": det})
    sky = star_rig.sky.model_copy(update={"magnitude_limit": 9.5, "epoch_year": 2019.6,
                                          "background_mag_per_arcsec2": 19.0})
    rig = star_rig.model_copy(update={"sensor": sensor, "sky": sky})
    cat = SkyCatalogue.load(10.0, 2019.6)
    frames, Rs = [], []
    rng = np.random.default_rng(2)
    for k, (slope, direction) in enumerate(zip(SLOPES, DIRS)):
        eff = rig.effects.only(["vignetting", "sky_glow"])
        eff = eff.model_copy(update={"vignetting": eff.vignetting.model_copy(update={"rho2": RHO2, "rho4": RHO4}),
                                     "sky_glow": eff.sky_glow.model_copy(update={"slope_per_deg": slope,
                                                                                 "direction_deg": direction})})
        rk = rig.model_copy(update={"effects": eff})
        while True:  # a field with enough stars for photometry
            R = Rotation.random(random_state=rng).as_matrix()
            if len(StarSky(rk, sky=SkyCatalogue.load(9.5, 2019.6)).field(R)) >= 40:
                break
        frames.append(render_frame(StarSky(rk, sky=SkyCatalogue.load(9.5, 2019.6)), R, seed=10 + k, fits_header=False).dn)
        Rs.append(R)
    return rig, cat, frames, Rs


def test_the_description_gives_back_the_rendered_camera(night):
    rig, cat, frames, Rs = night
    s, d = rig.sensor, rig.sensor.detector
    cam = s.camera()
    desc = describe_camera(frames, cam, Rs, cat, psf_sigma_px=0.8, saturation=float(d.max_dn))
    assert abs(desc.gain_dn_per_e - d.gain_dn_per_e) < max(4 * desc.gain_sigma, 0.03)
    V = lambda r2: 1 - desc.rho2 * r2 - desc.rho4 * r2**2  # noqa: E731
    for r2 in (0.25, 0.6, 1.0):  # the relative illumination across the field, not each coefficient
        assert abs(V(r2) - (1 - RHO2 * r2 - RHO4 * r2**2)) < 0.02
    sky = StarSky(rig, sky=cat)
    want_level = d.gain_dn_per_e * d.quantum_efficiency * sky.background_photons_per_px
    for lev in desc.sky_level_dn:
        assert abs(lev / want_level - 1) < 0.03
    for slope, direction, got_s, got_d in zip(SLOPES, DIRS, desc.glow_slope_per_deg, desc.glow_direction_deg):
        assert abs(got_s - slope) < 0.006
        if slope > 0:
            assert abs((got_d - direction + 180) % 360 - 180) < 10
    assert abs(desc.psf_sigma_px - 0.7) < 0.035
    # log10 of an Hp = 0 star's DN on the axis, from the rig's radiometry
    zp = math.log10(d.gain_dn_per_e * d.quantum_efficiency * float(sky.photons(0.0)))
    assert abs(desc.zero_point_log10_dn - zp) < 0.02, (desc.zero_point_log10_dn, zp)


def test_the_twin_of_rendered_frames_agrees_with_them(night):
    rig, cat, frames, Rs = night
    cam = rig.sensor.camera()
    desc = describe_camera(frames, cam, Rs, cat, psf_sigma_px=0.8, saturation=float(rig.sensor.detector.max_dn))
    kw = {"psf_sigma_px": desc.psf_sigma_px, "gain": desc.gain_dn_per_e, "saturation": float(rig.sensor.detector.max_dn)}
    twins = [render_frame(StarSky(twin_rig(rig, desc, cam, k, magnitude_limit=9.5), sky=SkyCatalogue.load(9.5, 2019.6)),
                          R, seed=99 + k, fits_header=False).dn for k, R in enumerate(Rs)]
    real = [frame_stats(im, cam, R, cat, **kw) for im, R in zip(frames, Rs)]
    twin = [frame_stats(im, cam, R, cat, **kw) for im, R in zip(twins, Rs)]
    rows = compare(real, twin, ident_real=1.0, ident_twin=1.0, scatter_real=0.1, scatter_twin=0.1)
    bad = [r for r in rows if not r["within"]]
    assert not bad, bad
