"""A star-sensor rig file from what a user knows of the camera: detector size and pixel pitch, the
lens's focal length (or the field of view), f-number and the detector's bit depth (``rigsim rig new
star-sensor``). Everything else gets a default scaled to the field of view, and the file says which
values were given, which were derived and which are defaults to review.

[sensor] and [nominal] are both the design (principal point at the detector's centre, no distortion):
the instrument as far as the user knows it, and the same belief with the σ a lens tolerance and an
unmeasured mounting warrant. docs/custom-rig.md walks through it."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

from rigsim.optics.sky import load_hipparcos, star_photons
from rigsim.rig.star import PSF, psf_sigma_px

__all__ = ["StarDesign", "design_values", "star_rig_text"]

F_SIGMA_FRACTION = 0.02     # [nominal] focal_length_sigma_px: 2 % of f (a lens's focal-length tolerance, typically 1–3 %)
PP_SIGMA_FRACTION = 0.02    # [nominal] principal_point_sigma_px: 2 % of the detector's width (lens centring + mounting)
PSF_SIGMA_PX = 0.8          # defocus chosen for a star σ ≈ 0.8 px (~3×3 px: sub-pixel centroids need a few pixels)
LIMIT_SNR = 10.0            # [sky] magnitude_limit: the magnitude a star reaches this SNR at (every rendered star detectable)
SMEAR_STEP_PX = 0.05        # motion smear sampled every 0.05 px (the packaged rig: 0.36 px in 8 sub-steps)
VOTE_TOLERANCE_PX = 5.0     # rigsim.estimation.star_id's offset vote: the roll error must move the corner by less
SKY_DEG2 = 41252.96


@dataclass
class StarDesign:
    """The values a user gives; None: the default (see :func:`design_values`)."""

    resolution_px: tuple[int, int]
    pixel_pitch_um: float
    focal_length_mm: float | None = None
    fov_deg: float | None = None
    f_number: float | None = None
    adc_bits: int | None = None
    container_bits: int | None = None
    offset_dn: float | None = None
    gain_dn_per_e: float | None = None
    full_well_e: float | None = None
    read_noise_e: float | None = None
    exposure_s: float | None = None
    magnitude_limit: float | None = None
    name: str | None = None
    given: list[str] = field(default_factory=list)


def _g(x: float, digits: int = 6) -> float:
    """``x`` to ``digits`` significant digits (what a rig file shows)."""
    return float(f"{x:.{digits}g}")


def stars_per_frame(magnitude_limit: float, fov_u_deg: float, fov_v_deg: float) -> float:
    """Hipparcos stars brighter than the limit in a field of fov_u × fov_v (a rectangle on the sky: its
    solid angle 4·asin(sin(a/2)·sin(b/2))), on average over the sky."""
    cat = load_hipparcos()
    n = int((cat.hp_mag <= magnitude_limit).sum())
    omega_sr = 4.0 * math.asin(math.sin(math.radians(fov_u_deg) / 2) * math.sin(math.radians(fov_v_deg) / 2))
    return n * math.degrees(1.0) ** 2 * omega_sr / SKY_DEG2


def design_values(d: StarDesign) -> dict:
    """Every value of the new rig file, as ``{table: {key: (value, note)}}``; note is "given", "derived: …"
    or "default: …". Raises ValueError (one sentence) for a combination that cannot make a rig."""
    W, H = d.resolution_px
    pitch = d.pixel_pitch_um
    if (d.focal_length_mm is None) == (d.fov_deg is None):
        raise ValueError("give either --focal-length-mm or --fov-deg")
    if d.focal_length_mm is not None:
        f_mm, f_note = d.focal_length_mm, "given"
        f_px = f_mm * 1000.0 / pitch
    else:
        f_px = (W / 2.0) / math.tan(math.radians(d.fov_deg) / 2.0)
        f_mm = f_px * pitch / 1000.0
        f_note = f"derived: {d.fov_deg:g}° across {W} px, f = {W / 2:g} px / tan({d.fov_deg:g}°/2) = {f_px:.2f} px"
        f_px = f_mm * 1000.0 / pitch
    if not 1.0 < f_mm <= 5000.0:
        raise ValueError(f"focal length {f_mm:.4g} mm: allowed > 1 to 5000 mm")
    fov_u = 2 * math.degrees(math.atan(W / 2 / f_px))
    fov_v = 2 * math.degrees(math.atan(H / 2 / f_px))
    N = d.f_number if d.f_number is not None else 2.0
    aperture = f_mm / N
    bits = d.adc_bits if d.adc_bits is not None else 12
    if d.container_bits is not None and d.container_bits < bits:
        raise ValueError(f"--container-bits {d.container_bits} is narrower than the ADC's {bits} bits")
    offset = d.offset_dn if d.offset_dn is not None else float(2 ** bits // 64)
    if offset >= 2 ** bits - 1:
        raise ValueError(f"--offset-dn {offset:g} leaves no room in a {bits}-bit ADC (top code {2 ** bits - 1})")
    full_well = d.full_well_e if d.full_well_e is not None else 40000.0
    gain = d.gain_dn_per_e if d.gain_dn_per_e is not None else _g((2 ** bits - 1 - offset) / full_well, 4)
    read = d.read_noise_e if d.read_noise_e is not None else 10.0
    exposure = d.exposure_s if d.exposure_s is not None else 0.1
    qe, dark, transmission = 0.6, 50.0, 0.7
    # the defocus that gives σ ≈ PSF_SIGMA_PX: blur radius / 2 in quadrature with the Airy core's 0.42 λN
    wl = 600.0
    s_def_um = math.sqrt(max((PSF_SIGMA_PX * pitch) ** 2 - (0.42 * wl * 1e-3 * N) ** 2, 0.0))
    defocus = round(4.0 * N * s_def_um, 1)
    sigma_psf = psf_sigma_px(PSF(defocus_um=defocus, wavelength_nm=wl), N, pitch)
    # the faintest star rendered: SNR = F / √(F + 4πσ²·(b + dark + R²)) reaches LIMIT_SNR
    phot = dict(zero_point_photons_per_s_cm2=1.5e6, aperture_area_cm2=math.pi * (aperture / 20.0) ** 2,
                transmission=transmission, exposure_s=exposure)
    pix_arcsec = pitch * 1e-3 / f_mm * 206264.806
    sky_e = qe * float(star_photons(21.0, **phot)) * pix_arcsec ** 2
    floor = 4 * math.pi * sigma_psf ** 2 * (sky_e + dark * exposure + read ** 2)
    F = LIMIT_SNR ** 2 / 2 + math.sqrt(LIMIT_SNR ** 4 / 4 + LIMIT_SNR ** 2 * floor)   # electrons at the limit
    m_snr = -2.5 * math.log10(F / (qe * float(star_photons(0.0, **phot))))
    if d.magnitude_limit is not None:
        mag, mag_note = d.magnitude_limit, "given"
    else:
        mag = round(min(max(m_snr, 2.0), 10.0), 1)
        mag_note = f"derived: a star of this magnitude reaches SNR {LIMIT_SNR:g} in one {exposure:g} s exposure"
    n_stars = stars_per_frame(mag, fov_u, fov_v)
    # identification: the prior's roll error must move the corner by less than the offset vote's tolerance
    half_diag = math.hypot(W, H) / 2
    att = round(min(0.3, math.degrees(0.75 * VOTE_TOLERANCE_PX / half_diag)), 2)
    search = max(20.0, 5.0 * math.ceil(4.0 * f_px * math.tan(math.radians(att)) / 5.0))
    rate = 0.06
    smear_px = math.radians(rate * exposure) * f_px
    substeps = int(min(64, max(1, math.ceil(smear_px / SMEAR_STEP_PX))))
    g = set(d.given)

    def note(key, default_note):
        return "given" if key in g else default_note

    name = d.name or f"star-sensor-{W}x{H}-f{_g(f_mm, 4):g}mm"
    det = {
        "quantum_efficiency": (qe, "default: put your detector's values (its EMVA 1288 datasheet) in this table"),
        "exposure_s": (exposure, note("exposure_s", "default")),
        "full_well_e": (full_well, note("full_well_e", "default")),
        "read_noise_e": (read, note("read_noise_e", "default")),
        "dark_current_e_per_s": (dark, "default"),
        "dsnu_e": (2.0, "default"),
        "prnu_frac": (0.005, "default"),
        "gain_dn_per_e": (gain, note("gain_dn_per_e", f"derived: the ADC's top code at the full well, "
                                                      f"({2 ** bits - 1} − {offset:g}) / {full_well:g} e⁻")),
        "adc_bits": (bits, note("adc_bits", "default")),
        "offset_dn": (offset, note("offset_dn", f"default: 1/64 of the ADC's range; in ADC codes")),
    }
    if d.container_bits is not None:
        step = 2 ** (d.container_bits - bits)
        det["container_bits"] = (d.container_bits, f"given: frames hold code × {step}, the offset {offset:g} codes is "
                                                   f"{offset * step:g} DN, a saturated pixel {2 ** d.container_bits - 1}")
    det["sensor_seed"] = (0, "default: the fixed patterns' instance")
    return {
        "": {"name": (name, note("name", "default")), "seed_document": ("004", ""),
             "description": (f"{W}×{H} px of {pitch:g} µm, f = {f_mm:.4g} mm (f/{N:g}), FOV {fov_u:.2f}° × {fov_v:.2f}° "
                             "(rigsim rig new star-sensor)", "")},
        "sensor": {
            "resolution_px": ([W, H], "given"),
            "pixel_pitch_um": (pitch, "given"),
            "focal_length_mm": (round(f_mm, 9), f_note + ("; " if d.fov_deg is not None else f"; {f_px:.2f} px, ")
                                + f"FOV {fov_u:.3f}° × {fov_v:.3f}°"),
            "principal_point_px": ([(W - 1) / 2.0, (H - 1) / 2.0], "default: the detector's centre, the design"),
            "k1": (0.0, "default: no distortion known; after a calibration: rigsim rig import-camera"),
            "k2": (0.0, ""), "p1": (0.0, ""), "p2": (0.0, ""),
            "aperture_diameter_mm": (round(aperture, 6), ("derived" if d.f_number is not None else "default f/2: derived")
                                     + f": f / N = {f_mm:.4g} / {N:g}"),
            "optics_transmission": (transmission, "default"),
        },
        "sensor.psf": {
            "model": ("gaussian", ""),
            "defocus_um": (defocus, f"default: a star σ ≈ {sigma_psf:.2f} px, about 3×3 px; measure yours and change it"),
            "wavelength_nm": (wl, "default"),
        },
        "sensor.detector": det,
        "nominal": {
            "focal_length_mm": (round(f_mm, 9), "the design, as [sensor]"),
            "focal_length_sigma_px": (_g(F_SIGMA_FRACTION * f_px, 3), f"default: {F_SIGMA_FRACTION:.0%} of f, a lens's "
                                                                       "focal-length tolerance"),
            "principal_point_px": ([(W - 1) / 2.0, (H - 1) / 2.0], "the detector's centre"),
            "principal_point_sigma_px": (_g(PP_SIGMA_FRACTION * W, 3), f"default: {PP_SIGMA_FRACTION:.0%} of the width, "
                                                                        "lens centring and mounting"),
            "k1": (0.0, "no distortion assumed"), "k2": (0.0, ""), "p1": (0.0, ""), "p2": (0.0, ""),
        },
        "sky": {
            "catalogue": ("hipparcos2", ""),
            "epoch_year": (2025.0, "default"),
            "magnitude_limit": (mag, mag_note + f"; ≈ {n_stars:.0f} stars per frame on average"),
            "zero_point_photons_per_s_cm2": (1.5e6, "default: Hp = 0 in a ~150 nm silicon band"),
            "background_mag_per_arcsec2": (21.0, "default: a dark sky in orbit; a night sky from the ground: 18–21"),
        },
        "sequence": {
            "kind": ("slew", "default: inertial | slew | random"),
            "n_frames": (20, "default"),
            "frame_interval_s": (10.0, "default"),
            "start_ra_deg": (80.0, "default"), "start_dec_deg": (20.0, ""), "start_roll_deg": (0.0, ""),
            "slew_rate_deg_per_s": (rate, "default: the LEO orbital rate"),
            "slew_direction_deg": (30.0, "default"),
            "roll_rate_deg_per_s": (0.01, "default"),
            "jitter_arcsec": (5.0, "default"),
            "smear_substeps": (substeps, f"derived: {smear_px:.2f} px of smear per exposure, every "
                                         f"{SMEAR_STEP_PX:g} px"),
        },
        "identification": {
            "attitude_error_deg": (att, "default: the a-priori attitude's error, your attitude source's; at most "
                                        f"what the offset vote takes at the corner, {half_diag:.0f} px out"),
            "search_radius_px": (search, f"derived: 4× that error in px, 4 × {f_px * math.tan(math.radians(att)):.1f} px"),
            "match_tolerance_px": (2.0, "default"),
            "min_matches": (4, "default"),
        },
        "calibration": {
            "max_stars_per_frame": (20, "default"),
            "weighting": ("propagated", "default"),
            "ads_variant": ("exact", "default"),
            "process_noise_px": (0.0, "default"),
            "centroid_method": ("gauss", "default"),
            "background": ("map", "default: the sky's level and noise mapped across each frame (glow, vignetting)"),
            "distortion_terms": ("auto", "default: k1, and k2 when the data support it"),
            "single_pixel_filter": (True, "default: repair hot pixels and particle hits before extraction"),
            "fixed_pattern": ("none", "default: 'sequence' subtracts the per-pixel median of a slew"),
            "reject_poor_fits": (True, "default"),
            "poor_fit_reference": ("frame", "default: a real PSF is no Gaussian: poor only next to the frame's other stars"),
        },
        "study": {"trials": (200, "default"), "seed": (4, "default")},
        "_summary": {"f_px": f_px, "fov_deg": (fov_u, fov_v), "stars_per_frame": n_stars, "psf_sigma_px": sigma_psf,
                     "magnitude_limit": mag},
    }


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # JSON's string escapes are TOML's basic-string escapes
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, float):
        return repr(v)
    return str(v)


HEADER = """\
# A star-sensor rig written by `rigsim rig new star-sensor` from the values given on its command line:
#   {args}
# Every value says where it comes from: given, derived (and how), or default (change it to your
# camera's). [sensor] is the instrument rigsim renders; [nominal] is what the estimators start from
# (the design, with the σ you are sure of it to). Check it: rigsim rig check <this file>.
"""

FOOTER = """
# [effects.*] (what a real sensor shows beyond the ideal frame: hot pixels, cosmic rays, stray light, ...)
# are all off here; the packaged rig lists every one with its source: rigsim rig copy star_sensor s.toml
"""


def star_rig_text(values: dict, args_text: str) -> str:
    """The rig file's text for :func:`design_values`'s values, with one comment per value."""
    lines = [HEADER.format(args=args_text)]
    for table, entries in values.items():
        if table.startswith("_"):
            continue
        if table:
            lines.append(f"\n[{table}]")
        rows = [(f"{k} = {_toml(v)}", n) for k, (v, n) in entries.items()]
        w = max((len(r) for r, n in rows if n), default=0)
        for r, n in rows:
            lines.append(f"{r:{w}s}  # {n}" if n else r)
    return "\n".join(lines) + "\n" + FOOTER
