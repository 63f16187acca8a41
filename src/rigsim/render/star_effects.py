"""The star sensor's ``[effects]`` on one frame: the photons and electrons they add, and their truth.

Stray light adds photons (it passes through the optics and the detector's quantum efficiency
like the sky); hot pixels and cosmic rays add electrons after the photon shot noise. Each
effect draws from its own stream of the frame's seed, so switching one on changes neither the
detector noise nor another effect's draw.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from rigsim.detector.defects import deposit_cosmic_rays, draw_cosmic_rays, hot_pixel_electrons, hot_pixel_rates
from rigsim.optics.stray_light import stray_light_mag_map, surface_brightness_photons

__all__ = ["FrameEffects", "draw_faint_stars", "effects_rng", "star_frame_effects", "traced_psf_table",
           "traced_star_psfs"]

_STREAMS = {"hot_pixels": 0x407, "cosmic_rays": 0xC05, "faint_stars": 0xFA1}


def effects_rng(seed: int, name: str) -> np.random.Generator:
    """The random stream of effect ``name`` in the frame with detector seed ``seed``."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), 0xEFFEC7, _STREAMS[name]]))


@dataclass
class FrameEffects:
    photons: np.ndarray | None = None      # added to the expected photons per pixel
    electrons: np.ndarray | None = None    # added to the signal after the shot noise
    illumination: np.ndarray | None = None  # multiplies the expected photons (stars, sky and added light)
    stars_uv: np.ndarray | None = None      # (M, 2) px: stars the catalogue does not hold, drawn with the PSF
    stars_photons: np.ndarray | None = None  # (M,)
    truth: dict = field(default_factory=dict)


def _static_maps(sky) -> dict:
    """The maps that do not change from frame to frame (the stray light, the hot pixels' rates),
    computed once per sky and effects table."""
    eff, s = sky.rig.effects, sky.rig.sensor
    key = (eff.model_dump_json(), s.detector.sensor_seed)
    cached = getattr(sky, "_effects_maps", None)
    if cached is not None and cached[0] == key:
        return cached[1]
    H, W = sky.shape_hw
    maps = {}
    if eff.stray_light.enabled:
        st = eff.stray_light
        mag = stray_light_mag_map((H, W), sky.pixel_arcsec / 3600.0, direction_deg=st.direction_deg,
                                  edge_mag_per_arcsec2=st.edge_mag_per_arcsec2, falloff_mag_per_deg=st.falloff_mag_per_deg)
        maps["stray_photons"] = surface_brightness_photons(mag, sky.photons, sky.pixel_arcsec)
    if eff.sky_glow.enabled:
        g = eff.sky_glow
        c, sn = math.cos(math.radians(g.direction_deg)), math.sin(math.radians(g.direction_deg))
        v, u = np.mgrid[0:H, 0:W].astype(np.float64)
        d_deg = ((u - (W - 1) / 2.0) * c + (v - (H - 1) / 2.0) * sn) * sky.pixel_arcsec / 3600.0
        maps["glow_photons"] = sky.background_photons_per_px * g.slope_per_deg * d_deg
        if float(maps["glow_photons"].min()) < -sky.background_photons_per_px:
            raise ValueError(f"effects.sky_glow: slope {g.slope_per_deg}/° darkens the sky below zero inside the field")
    if eff.vignetting.enabled:
        vg = eff.vignetting
        cam = sky.camera
        v, u = np.mgrid[0:H, 0:W].astype(np.float64)
        half_diag = math.hypot(W / 2.0, H / 2.0)
        rho2 = ((u - cam.cx) ** 2 + (v - cam.cy) ** 2) / half_diag**2
        maps["illumination"] = np.clip(1.0 - vg.rho2 * rho2 - vg.rho4 * rho2**2, 0.0, None)
    if eff.hot_pixels.enabled:
        hp = eff.hot_pixels
        maps["hot_rates"] = hot_pixel_rates(s.detector.sensor_seed, W, (0, H), (0, W), fraction=hp.fraction,
                                            threshold_e_per_s=hp.threshold_e_per_s,
                                            mean_excess_e_per_s=hp.mean_excess_e_per_s)
    sky._effects_maps = (key, maps)
    return maps


def star_frame_effects(sky, *, seed: int, noiseless: bool = False) -> FrameEffects:
    """What the rig's enabled effects add to one full frame of ``sky`` (a
    :class:`rigsim.truth.star.StarSky`) rendered with detector seed ``seed``."""
    rig = sky.rig
    eff = rig.effects
    out = FrameEffects()
    if not eff.enabled:
        return out
    s = rig.sensor
    H, W = sky.shape_hw
    static = _static_maps(sky)
    if eff.stray_light.enabled:
        out.photons = static["stray_photons"]
        out.truth["stray_light"] = {"photons_per_px_min": float(out.photons.min()),
                                    "photons_per_px_max": float(out.photons.max())}
    if eff.sky_glow.enabled:
        out.photons = static["glow_photons"] if out.photons is None else out.photons + static["glow_photons"]
        out.truth["sky_glow"] = {"photons_per_px_min": float(static["glow_photons"].min()),
                                 "photons_per_px_max": float(static["glow_photons"].max())}
    if eff.vignetting.enabled:
        out.illumination = static["illumination"]
        out.truth["vignetting"] = {"illumination_min": float(out.illumination.min())}
    if eff.faint_stars.enabled:
        out.stars_uv, mags = draw_faint_stars(sky, effects_rng(seed, "faint_stars"))
        out.stars_photons = sky.photons(mags)
        out.truth["faint_stars"] = {"n": int(mags.size), "uv": out.stars_uv.tolist(), "mag": mags.tolist()}
    electrons = np.zeros((H, W), dtype=np.float64)
    if eff.hot_pixels.enabled:
        rates = static["hot_rates"]
        electrons += hot_pixel_electrons(rates, s.detector.exposure_s, effects_rng(seed, "hot_pixels"), noiseless)
        out.truth["hot_pixels"] = {"n": int(np.count_nonzero(rates))}
    if eff.cosmic_rays.enabled:
        cr = eff.cosmic_rays
        hits = draw_cosmic_rays(effects_rng(seed, "cosmic_rays"), (H, W), pixel_pitch_um=s.pixel_pitch_um,
                                exposure_s=s.detector.exposure_s, flux_per_cm2_s=cr.flux_per_cm2_s, depth_um=cr.depth_um,
                                charge_e_per_um=cr.charge_e_per_um, landau_width=cr.landau_width)
        electrons += deposit_cosmic_rays(hits, (0, H), (0, W))
        out.truth["cosmic_rays"] = hits.as_dict()
    if eff.hot_pixels.enabled or eff.cosmic_rays.enabled:
        out.electrons = electrons
    return out


def draw_faint_stars(sky, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Positions (px) and magnitudes of the stars fainter than the catalogue on one frame of ``sky``:
    a Poisson number over the detector's solid angle, uniform in position, magnitudes from
    dN/dm = ρ0 · 10^(s (m − m_lim)) per deg² (inverse transform sampling)."""
    fs = sky.rig.effects.faint_stars
    H, W = sky.shape_hw
    m0, m1, s_ = float(sky.rig.sky.magnitude_limit), float(fs.faint_limit_mag), float(fs.slope_per_mag)
    if m1 <= m0 or fs.density_per_deg2_per_mag <= 0:
        return np.zeros((0, 2)), np.zeros(0)
    area_deg2 = H * W * (sky.pixel_arcsec / 3600.0) ** 2
    per_mag = (10.0 ** (s_ * (m1 - m0)) - 1.0) / (s_ * math.log(10.0)) if s_ > 0 else (m1 - m0)
    n = int(rng.poisson(fs.density_per_deg2_per_mag * area_deg2 * per_mag))
    uv = np.stack([rng.uniform(-0.5, W - 0.5, n), rng.uniform(-0.5, H - 0.5, n)], axis=1)
    x = rng.uniform(0.0, 1.0, n)
    if s_ > 0:
        mag = m0 + np.log10(1.0 + x * (10.0 ** (s_ * (m1 - m0)) - 1.0)) / s_
    else:
        mag = m0 + x * (m1 - m0)
    return uv, mag


@functools.lru_cache(maxsize=4)
def _table(key: tuple):
    from rigsim.optics.star_lens import StarLens
    from rigsim.optics.star_psf import psf_table

    f_mm, epd_mm, ref_nm, defocus_um, pitch_um, tx, ty, lo, hi, nl, nodes, rays, os_ = key
    # the detector sits defocus_um before best focus (towards the lens): on that side the lens's spherical
    # aberration leaves a filled blur disk; behind it the rays cross in a caustic core (docs/effects-star.md)
    lens = StarLens(focal_length_mm=f_mm, epd_mm=epd_mm, ref_nm=ref_nm, defocus_mm=-defocus_um * 1e-3)
    return psf_table(lens, tan_max_x=tx, tan_max_y=ty, wavelengths_nm=np.linspace(lo, hi, nl), pixel_pitch_um=pitch_um,
                     nodes=nodes, pupil_rays=rays, oversample=os_)


def traced_psf_table(rig):
    """The :class:`rigsim.optics.star_psf.PSFTable` of the rig's traced lens over its field (cached per
    lens, detector and ``[effects.traced_psf]`` values: the robustness trials share it)."""
    from rigsim.optics.star_psf import field_tangents

    s, tp = rig.sensor, rig.effects.traced_psf
    t = field_tangents(s.camera(), s.resolution_px)   # 2 % wider than the detector (off-detector wings)
    key = (float(s.focal_length_mm), float(s.aperture_diameter_mm), float(s.psf.wavelength_nm), float(s.psf.defocus_um),
           float(s.pixel_pitch_um), round(float(t[0]), 6), round(float(t[1]), 6), float(tp.band_min_nm),
           float(tp.band_max_nm), int(tp.wavelengths), int(tp.field_nodes), int(tp.pupil_rays), int(tp.oversample))
    return _table(key)


def traced_star_psfs(rig, truth):
    """Each star's traced PSF (N, n, n), its shift from the truth position (N, 2) px, and the table: the
    PSF of the star's direction and colour (B−V → blackbody temperature → photons per wavelength)."""
    from rigsim.optics.star_psf import bv_temperature_k, photon_spectrum_weights

    table = traced_psf_table(rig)
    bv = np.where(np.isfinite(truth.bv), truth.bv, 0.65) if truth.bv is not None else np.full(len(truth), 0.65)
    w = photon_spectrum_weights(bv_temperature_k(bv), table.wavelengths_nm)
    psfs, shift = table.star_psfs(truth.dirs_cam, w)
    return psfs, shift, table


def traced_margin_px(rig) -> int:
    """How far off the detector a star's traced PSF still reaches (px)."""
    return math.ceil(traced_psf_table(rig).radius_px)
