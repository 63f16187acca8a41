"""A rendered twin of a real star camera, and how far it is from the real frames.

1. :func:`describe_camera`: what the real frames say about the camera and the night, measured on
   the frames with the calibration ``rigsim star calibrate`` wrote: the gain and the dark noise (the
   photon transfer of each frame's own sky), the lens's vignetting and each frame's sky level and
   glow (one fit to every frame's sky map: a common relative illumination, a level and a gradient
   per frame), the photometric zero point (identified stars' fluxes against their Hipparcos
   magnitudes, the vignetting divided out), and the PSF's width (bright stars' Gaussian σ).
2. :func:`twin_rig`: a star rig of that camera for one frame (the calibrated intrinsics, the
   measured detector, sky, glow and vignetting), which rigsim's renderer draws at the frame's
   solved attitude (:func:`render_twin`).
3. :func:`frame_stats` measures a frame (real or rendered) the same way: identified stars per
   magnitude bin, the PSF's FWHM across the field, the sky's level and its radial profile, the sky
   noise; :func:`compare` sets twin against real with the tolerances of :data:`TOLERANCES`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from rigsim.estimation.star_id import identify
from rigsim.imaging import Flag
from rigsim.imaging.star_field import extract_star_field, photon_transfer
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.sky import SkyCatalogue, star_photons

__all__ = ["MAG_BINS", "RHO_BINS", "TOLERANCES", "CameraDescription", "FrameStats", "compare", "describe_camera",
           "fit_faint_density", "frame_stats", "render_twin", "twin_rig"]

MAG_BINS = (3.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0)
RHO_BINS = tuple(np.round(np.linspace(0.0, 1.0, 6), 3))
TOLERANCES = {"stars per magnitude bin": 0.25, "detected stars": 0.25, "PSF FWHM": 0.10, "background profile": 0.10,
              "identification rate": 0.20, "centroid scatter": 0.20}
"""Relative agreement asked of the twin, per quantity."""
BAD = int(Flag.INVALID | Flag.SATURATED | Flag.EDGE | Flag.BLENDED)
PSF_STAR_SIGNIFICANCE = 20.0
EXPOSURE_S = 1.0
"""The twin's exposure: the real one is not known, and only its product with the zero point enters."""


@dataclass
class CameraDescription:
    """What the real frames say (units in the names; DN are the frames' own)."""

    gain_dn_per_e: float                 # frame DN per electron (photon transfer)
    gain_sigma: float
    dark_variance_dn2: float             # the photon transfer's intercept, read as dark noise (offset 0)
    rho2: float                          # vignetting: V = 1 − rho2 ρ² − rho4 ρ⁴
    rho4: float
    sky_level_dn: list                   # per frame: the sky on the axis (V = 1), DN
    glow_slope_per_deg: list             # per frame
    glow_direction_deg: list             # per frame
    sky_fit_rms_dn: float
    zero_point_log10_dn: float           # log10 of an Hp = 0 star's DN on the axis
    zero_point_scatter_dex: float
    psf_sigma_px: float
    psf_sigma_spread_px: float
    n_psf_stars: int
    notes: list = field(default_factory=list)
    faint_density_per_deg2_per_mag: float = 0.0  # stars beyond the catalogue (fitted by :func:`fit_faint_density`)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def _rho2(camera: PinholeBrown, u, v):
    half = math.hypot(camera.width / 2.0, camera.height / 2.0)
    return ((np.asarray(u, float) - camera.cx) ** 2 + (np.asarray(v, float) - camera.cy) ** 2) / half**2


def _field_deg(camera: PinholeBrown, u, v):
    """(du, dv) in degrees from the detector's centre (the renderer's glow reference)."""
    px_deg = math.degrees(1.0 / camera.fx)
    return ((np.asarray(u, float) - (camera.width - 1) / 2.0) * px_deg,
            (np.asarray(v, float) - (camera.height - 1) / 2.0) * px_deg)


def fit_sky(maps, camera: PinholeBrown):
    """One relative illumination for every frame and a level and gradient per frame, fitted to the
    sky maps' mesh levels (least squares in relative units). Returns (rho2, rho4, levels, slopes,
    directions, rms DN)."""
    pts = []
    for m in maps:
        ny, nx = m.mesh_level.shape
        cy = np.clip((np.arange(ny) + 0.5) * m.mesh_px, 0, camera.height - 1)
        cx = np.clip((np.arange(nx) + 0.5) * m.mesh_px, 0, camera.width - 1)
        vv, uu = np.meshgrid(cy, cx, indexing="ij")
        pts.append((uu.ravel(), vv.ravel(), m.mesh_level.ravel().astype(float)))
    n = len(pts)

    def model(x, k):
        u, v, _ = pts[k]
        r2 = _rho2(camera, u, v)
        du, dv = _field_deg(camera, u, v)
        V = 1.0 - x[0] * r2 - x[1] * r2**2
        return x[2 + 3 * k] * V * (1.0 + x[3 + 3 * k] * du + x[4 + 3 * k] * dv)

    def resid(x):
        return np.concatenate([(model(x, k) - pts[k][2]) / np.median(pts[k][2]) for k in range(n)])

    x0 = np.concatenate([[0.3, 0.0], *[[np.median(p[2]), 0.0, 0.0] for p in pts]])
    sol = least_squares(resid, x0, method="lm")
    x = sol.x
    levels = [float(x[2 + 3 * k]) for k in range(n)]
    gx = np.array([x[3 + 3 * k] for k in range(n)])
    gy = np.array([x[4 + 3 * k] for k in range(n)])
    rms = float(np.sqrt(np.mean(np.concatenate([model(x, k) - pts[k][2] for k in range(n)]) ** 2)))
    return float(x[0]), float(x[1]), levels, np.hypot(gx, gy).tolist(), np.degrees(np.arctan2(gy, gx)).tolist(), rms


@dataclass
class _Measured:
    sf: object
    ident: object
    mag: np.ndarray
    flux: np.ndarray
    rho2: np.ndarray


def _measure(img, camera: PinholeBrown, R, sky: SkyCatalogue, psf_sigma_px: float, gain: float,
             saturation: float, match_tolerance_px: float = 1.5) -> _Measured:
    sf = extract_star_field(img, psf_sigma_px=psf_sigma_px, gain_dn_per_e=gain, saturation=saturation, fit_psf="star")
    good = np.flatnonzero((sf.flags & BAD) == 0)
    ident = identify(sf.uv[good], sky, R, camera, search_radius_px=4 * match_tolerance_px,
                     match_tolerance_px=match_tolerance_px, min_matches=3)
    o = good[ident.obs_index] if ident.ok else np.zeros(0, int)
    mag = sky.hp_mag[ident.cat_index] if ident.ok else np.zeros(0)
    return _Measured(sf, ident, mag, sf.flux[o], _rho2(camera, sf.u[o], sf.v[o]))


def describe_camera(images, camera: PinholeBrown, attitudes, sky: SkyCatalogue, *, psf_sigma_px: float = 1.0,
                    saturation: float = 65535.0) -> CameraDescription:
    """The camera and the night as the real frames show them (see the module's docstring)."""
    notes = []
    pts = [photon_transfer(im, saturation=saturation) for im in images]
    pts = [p for p in pts if p is not None]
    if not pts:
        raise ValueError("no frame's sky spans enough levels to measure the gain")
    w = np.array([1.0 / p.gain_sigma**2 for p in pts])
    K = float(np.sum(w * [p.gain_dn_per_e for p in pts]) / w.sum())
    K_sig = float(1.0 / math.sqrt(w.sum()))
    dark = float(max(np.median([p.intercept_dn2 for p in pts]), 0.0))
    notes.append("offset taken as 0 DN: the photon transfer's intercept σ_dark² − K·offset is read as dark noise "
                 "(no dark frame to separate them)")
    meas = [_measure(im, camera, R, sky, psf_sigma_px, K, saturation) for im, R in zip(images, attitudes)]
    rho2, rho4, levels, slopes, dirs, rms = fit_sky([m.sf.sky for m in meas], camera)
    mag = np.concatenate([m.mag for m in meas])
    V = 1.0 - rho2 * np.concatenate([m.rho2 for m in meas]) - rho4 * np.concatenate([m.rho2 for m in meas]) ** 2
    flux = np.concatenate([m.flux for m in meas]) / V
    ok = (flux > 0) & np.isfinite(flux)
    y = np.log10(flux[ok]) + 0.4 * mag[ok]
    zp = float(np.median(y))
    zp_sc = float(1.4826 * np.median(np.abs(y - zp)))
    sig = []
    for m in meas:
        sel = (m.sf.significance >= PSF_STAR_SIGNIFICANCE) & ((m.sf.flags & BAD) == 0)
        sig += list(m.sf.psf_sigma[sel])
    sig = np.array(sig)
    return CameraDescription(K, K_sig, dark, rho2, rho4, levels, slopes, dirs, rms, zp, zp_sc,
                             float(np.median(sig)), float(1.4826 * np.median(np.abs(sig - np.median(sig)))),
                             int(sig.size), notes)


CATALOGUE_COMPLETE_MAG = 9.0
"""Hipparcos is complete to about this magnitude; the twin draws its stars from the catalogue to here
and the fainter ones as a random field with the sky's counts (``[effects.faint_stars]``)."""
FAINT_LIMIT_MAG = 11.0
"""The faintest star the twin draws: about a magnitude beyond what the frames detect; fainter stars are
part of the sky's level the frames already measure."""
FAINT_SLOPE_PER_MAG = 0.35
"""log10 growth of the star counts per magnitude near V ≈ 10 at mid galactic latitudes (Allen's
Astrophysical Quantities, star counts: ~0.3–0.45); the density at 9 mag is fitted to the frames."""


def twin_rig(base, desc: CameraDescription, camera: PinholeBrown, frame: int, *,
             magnitude_limit: float = CATALOGUE_COMPLETE_MAG):
    """The rig of the twin of frame ``frame``: ``base`` (a star rig of the camera: resolution, pitch,
    aperture, detector bits) with the calibrated intrinsics and what :func:`describe_camera` measured."""
    s = base.sensor
    det = s.detector
    step = getattr(det, "code_step_dn", 1)
    K_codes = desc.gain_dn_per_e / step  # the rig's gain is per ADC code
    qe, T = det.quantum_efficiency, s.optics_transmission
    area = math.pi * (s.aperture_diameter_mm / 20.0) ** 2
    # DN of an Hp = 0 star on the axis = K · QE · Φ0 · A · T · t
    phi0 = 10.0 ** desc.zero_point_log10_dn / (desc.gain_dn_per_e * qe * area * T * EXPOSURE_S)
    pix_arcsec = math.degrees(1.0 / camera.fx) * 3600.0
    sky_photons = desc.sky_level_dn[frame] / (desc.gain_dn_per_e * qe)
    mu = -2.5 * math.log10(sky_photons / (star_photons(0.0, zero_point_photons_per_s_cm2=phi0, aperture_area_cm2=area,
                                                      transmission=T, exposure_s=EXPOSURE_S) * pix_arcsec**2))
    read_e = math.sqrt(desc.dark_variance_dn2) / desc.gain_dn_per_e
    detector = det.model_copy(update={"gain_dn_per_e": K_codes, "read_noise_e": read_e, "offset_dn": 0.0,
                                      "exposure_s": EXPOSURE_S, "dark_current_e_per_s": 0.0, "dsnu_e": 0.0,
                                      "full_well_e": max(det.full_well_e, 1.05 * 2**det.adc_bits / K_codes)})
    sensor = s.model_copy(update={
        "focal_length_mm": camera.fx * s.pixel_pitch_um / 1000.0, "principal_point_px": [camera.cx, camera.cy],
        "k1": camera.k1, "k2": camera.k2, "p1": 0.0, "p2": 0.0,
        "psf": s.psf.model_copy(update={"sigma_px": desc.psf_sigma_px}), "detector": detector})
    eff = base.effects.only(["vignetting", "sky_glow"] + (["faint_stars"] if desc.faint_density_per_deg2_per_mag > 0 else []))
    eff = eff.model_copy(update={
        "faint_stars": eff.faint_stars.model_copy(update={
            "density_per_deg2_per_mag": desc.faint_density_per_deg2_per_mag, "slope_per_mag": FAINT_SLOPE_PER_MAG,
            "faint_limit_mag": FAINT_LIMIT_MAG}),
        "vignetting": eff.vignetting.model_copy(update={"rho2": desc.rho2, "rho4": desc.rho4}),
        "sky_glow": eff.sky_glow.model_copy(update={"slope_per_deg": float(np.clip(desc.glow_slope_per_deg[frame], -0.2, 0.2)),
                                                    "direction_deg": float(desc.glow_direction_deg[frame])})})
    sky = base.sky.model_copy(update={"magnitude_limit": magnitude_limit, "zero_point_photons_per_s_cm2": phi0,
                                      "background_mag_per_arcsec2": float(np.clip(mu, 5.0, 30.0))})
    return base.model_copy(update={"sensor": sensor, "sky": sky, "effects": eff})


def render_twin(rig, R_cam_from_icrs, *, seed: int, catalogue=None) -> np.ndarray:
    """One twin frame (frame DN) at the solved attitude, by rigsim's star renderer."""
    from rigsim.render.star import render_frame
    from rigsim.truth.star import StarSky

    sky = StarSky(rig, catalogue)
    return render_frame(sky, R_cam_from_icrs, seed=seed, fits_header=False).dn


@dataclass
class FrameStats:
    """One frame measured as :func:`frame_stats` does (real or twin)."""

    n_detected: int
    n_identified: int
    stars_per_mag_bin: list
    fwhm_px_by_rho: list          # median FWHM of bright stars per RHO_BINS interval (None where none)
    level_profile_dn: list        # median sky level per RHO_BINS interval
    noise_rms_dn: float           # sky noise at the field's centre (the map's rms)
    noise_hist: list              # counts of (pixel − sky) / rms in NOISE_EDGES, star pixels left out
    centroid_scatter_px: float    # rms residual of the identified stars about the calibrated camera (attitude refitted)


NOISE_EDGES = tuple(np.linspace(-5.0, 5.0, 41))


def frame_stats(img, camera: PinholeBrown, R, sky: SkyCatalogue, *, psf_sigma_px: float, gain: float,
                saturation: float = 65535.0) -> FrameStats:
    m = _measure(img, camera, R, sky, psf_sigma_px, gain, saturation)
    sf = m.sf
    hist = np.histogram(m.mag, bins=MAG_BINS)[0].tolist()
    rho = np.sqrt(_rho2(camera, sf.u, sf.v))
    bright = (sf.significance >= PSF_STAR_SIGNIFICANCE) & ((sf.flags & BAD) == 0)
    fwhm = []
    for a, b in zip(RHO_BINS[:-1], RHO_BINS[1:]):
        sel = bright & (rho >= a) & (rho < b)
        fwhm.append(float(2.3548 * np.median(sf.psf_sigma[sel])) if sel.sum() >= 2 else None)
    H, W = np.shape(img)
    vv, uu = np.mgrid[0:H, 0:W]
    rr = np.sqrt(_rho2(camera, uu, vv))
    lev = sf.sky.level
    prof = [float(np.median(lev[(rr >= a) & (rr < b)])) for a, b in zip(RHO_BINS[:-1], RHO_BINS[1:])]
    prof = [p if np.isfinite(p) else None for p in prof]
    mask = np.zeros((H, W), bool)
    iu, iv = np.rint(sf.u[np.isfinite(sf.u)]).astype(int), np.rint(sf.v[np.isfinite(sf.v)]).astype(int)
    for du in range(-4, 5):
        for dv in range(-4, 5):
            mask[np.clip(iv + dv, 0, H - 1), np.clip(iu + du, 0, W - 1)] = True
    a = np.asarray(img, float)
    z = ((a - lev) / sf.sky.rms)[~mask & (a < saturation)]
    noise_hist = np.histogram(z, bins=NOISE_EDGES)[0].tolist()
    centre = (rr < 0.2)
    scatter = float("nan")
    if m.ident.ok and len(m.ident) >= 3:
        from scipy.spatial.transform import Rotation

        good = np.flatnonzero((sf.flags & BAD) == 0)[m.ident.obs_index]
        uv = sf.uv[good]
        rot, _ = Rotation.align_vectors(camera.unproject(uv), m.ident.dirs_icrs)
        res = uv - camera.project(m.ident.dirs_icrs @ rot.as_matrix().T)
        scatter = float(np.sqrt(np.mean(res**2)))
    return FrameStats(int(len(sf)), int(len(m.ident)) if m.ident.ok else 0, hist, fwhm, prof,
                      float(np.median(sf.sky.rms[centre])), noise_hist, scatter)


def fit_faint_density(unidentified: callable, real_unidentified: int, *, trial: float = 1.0, rounds: int = 3) -> float:
    """The density (stars per deg² per magnitude at the catalogue's completeness) for which the twin's
    frames have as many detections without a catalogue star as the real ones: ``unidentified(ρ)``
    renders and counts them. Secant steps from ρ = 0 and ``trial`` (the count is nearly linear in ρ)."""
    x0, x1 = 0.0, float(trial)
    u0, u1 = unidentified(x0), unidentified(x1)
    for _ in range(rounds):
        if u1 == u0:
            break
        x2 = max(0.0, x1 + (real_unidentified - u1) * (x1 - x0) / (u1 - u0))
        x0, u0, x1 = x1, u1, x2
        u1 = unidentified(x1)
    return x1


def _rel(a, b):
    return abs(a - b) / abs(b) if b else float("inf")


def compare(real: list[FrameStats], twin: list[FrameStats], *, ident_real: float, ident_twin: float,
            scatter_real: float, scatter_twin: float) -> list[dict]:
    """Rows of the comparison: quantity, real, twin, relative difference, tolerance, within it.
    Stars per magnitude bin and FWHM are pooled over the frames; the background profile is compared
    per frame and bin (the worst difference reported)."""
    rows = []
    R = np.sum([r.stars_per_mag_bin for r in real], axis=0)
    T = np.sum([t.stars_per_mag_bin for t in twin], axis=0)
    for k, (a, b) in enumerate(zip(MAG_BINS[:-1], MAG_BINS[1:])):
        if R[k] >= 10:  # too few stars for a ±25 % statement otherwise
            rows.append({"quantity": "stars per magnitude bin", "bin": f"Hp {a:g}–{b:g}", "real": int(R[k]),
                         "twin": int(T[k]), "difference": _rel(T[k], R[k])})
    nd_r, nd_t = sum(r.n_detected for r in real), sum(t.n_detected for t in twin)
    rows.append({"quantity": "detected stars", "bin": "all frames, identified or not", "real": nd_r, "twin": nd_t,
                 "difference": _rel(nd_t, nd_r)})
    for k, (a, b) in enumerate(zip(RHO_BINS[:-1], RHO_BINS[1:])):
        fr = [r.fwhm_px_by_rho[k] for r in real if r.fwhm_px_by_rho[k] is not None]
        ft = [t.fwhm_px_by_rho[k] for t in twin if t.fwhm_px_by_rho[k] is not None]
        if fr and ft:
            rows.append({"quantity": "PSF FWHM", "bin": f"ρ {a:g}–{b:g}", "real": float(np.median(fr)),
                         "twin": float(np.median(ft)), "difference": _rel(np.median(ft), np.median(fr))})
    worst = max(((_rel(t, r), k, i) for i, (rf, tf) in enumerate(zip(real, twin))
                 for k, (r, t) in enumerate(zip(rf.level_profile_dn, tf.level_profile_dn)) if r and t), default=None)
    if worst is not None:
        d, k, i = worst
        rows.append({"quantity": "background profile", "bin": f"worst: frame {i}, ρ {RHO_BINS[k]:g}–{RHO_BINS[k + 1]:g}",
                     "real": real[i].level_profile_dn[k], "twin": twin[i].level_profile_dn[k], "difference": d})
    nr = float(np.median([r.noise_rms_dn for r in real]))
    nt = float(np.median([t.noise_rms_dn for t in twin]))
    rows.append({"quantity": "background profile", "bin": "sky noise at the centre (rms)", "real": nr, "twin": nt,
                 "difference": _rel(nt, nr)})
    rows.append({"quantity": "identification rate", "bin": "frames identified", "real": ident_real, "twin": ident_twin,
                 "difference": _rel(ident_twin, ident_real)})
    rows.append({"quantity": "centroid scatter", "bin": "joint fit's residual rms (px)", "real": scatter_real,
                 "twin": scatter_twin, "difference": _rel(scatter_twin, scatter_real)})
    for r in rows:
        r["tolerance"] = TOLERANCES[r["quantity"]]
        r["within"] = bool(r["difference"] <= r["tolerance"])
    return rows
