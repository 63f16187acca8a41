"""The centroid stage on files: every spot of every frame (PNG, TIFF or FITS) into one table
(``rigsim centroid``). The detector's offset, gain, read noise and saturation come from a rig's
camera or from options; rigsim's own campaigns measure their frames with the same
:func:`rigsim.imaging.frame_spots.measure_frame`."""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from rigsim.errors import CliError
from rigsim.files import read_image, write_table
from rigsim.files.options import integer, number
from rigsim.files.outputs import declare
from rigsim.imaging import Flag
from rigsim.imaging.frame_spots import FRAME_METHODS, measure_frame

from rigsim.procedures.detector_settings import CAMERAS, DetectorSettings, detector_settings, frame_background

__all__ = ["CAMERAS", "DetectorSettings", "add_cli", "centroid_files", "detector_settings", "frame_background"]

def flag_names(flags: int) -> str:
    return "|".join(f.name for f in Flag if f.value & int(flags)) or ""


STAR_METHOD = "star"
"""``rigsim centroid --method star``: a star field (:func:`rigsim.imaging.star_field.extract_star_field`):
a position-dependent sky level and noise, a matched filter down to the noise floor, a Gaussian fit
of every star with the frame's PSF width."""
MODEL_METHOD = "model"
"""``rigsim centroid --method model``: the sun sensor's forward-model centroider
(:func:`rigsim.procedures.cube_mirror.spot_fit.model_frame_spots`; a cube-mirror ``--rig``; with
``--angles`` the sweep's two passes)."""
METHODS = (*FRAME_METHODS, STAR_METHOD, MODEL_METHOD)


def _star_spots(img: np.ndarray, settings: DetectorSettings, psf_sigma_px: float, threshold_sigma: float,
                gain_dn_per_e: float, psf_sigmas: list | None = None):
    from rigsim.imaging.result import CentroidBatch
    from rigsim.imaging.star_field import extract_star_field

    sat = settings.saturation_dn
    if sat is None and np.issubdtype(img.dtype, np.integer):
        sat = float(np.iinfo(img.dtype).max)
    sf = extract_star_field(img, psf_sigma_px=psf_sigma_px, threshold_sigma=threshold_sigma, saturation=sat,
                            gain_dn_per_e=gain_dn_per_e)
    if len(sf) and psf_sigmas is not None:
        psf_sigmas.append(float(np.median(sf.psf_sigma)))
    ok = np.isfinite(sf.u) & np.isfinite(sf.v)  # a detection no fit could place has no position to write
    return CentroidBatch(sf.u[ok], sf.v[ok], sf.sigma_u[ok], sf.sigma_v[ok], sf.flux[ok], sf.background[ok],
                         sf.flags[ok], STAR_METHOD)


def centroid_files(paths: Sequence, settings: DetectorSettings, *, method: str = "scurve",
                   threshold_dn: float | None = None, max_spots: int | None = None, progress=None,
                   warn=None, psf_sigma_px: float = 1.0, threshold_sigma: float = 5.0,
                   gain_dn_per_e: float | None = None, psf_sigmas: list | None = None, rig=None,
                   readings: dict | None = None) -> dict[str, list]:
    """Every spot of every frame file, brightest first per frame: the table's columns
    (frame, spot, u_px, v_px, sigma_u_px, sigma_v_px, flux_dn, flags, flag_names). ``warn(text)``
    hears of the first frame whose background disagrees with the detector model
    (:meth:`DetectorSettings.mismatch`). ``method`` ``star`` (:data:`STAR_METHOD`) measures its own sky
    map on each frame, with the PSF σ ``psf_sigma_px`` and the matched filter's ``threshold_sigma``; the
    stars' shot noise takes ``gain_dn_per_e`` (default the settings' gain); each frame's PSF σ (px, from
    its bright stars) is appended to ``psf_sigmas``. ``model`` (:data:`MODEL_METHOD`) needs the
    cube-mirror ``rig``, and takes the frames' turntable ``readings`` ({axis: (N,) rad}, in ``paths``'
    order) when there are some."""
    cols: dict[str, list] = {k: [] for k in ("frame", "spot", "u_px", "v_px", "sigma_u_px", "sigma_v_px", "flux_dn",
                                             "flags", "flag_names")}
    from rigsim.files.inputs import check_distinct

    check_distinct(paths, "FRAME")  # the table names each frame by its base name
    warned = False

    def measure(img, path, method=method):
        nonlocal warned
        if warn is not None and not warned:
            text = settings.mismatch(img, threshold_dn)
            if text is not None:
                warn(f"{path}: {text}")
                warned = True
        return measure_frame(img, settings.noise_for(img), method=method, threshold_dn=threshold_dn,
                             saturation_dn=settings.saturation_dn)

    modelled = None
    if method == MODEL_METHOD:
        from rigsim.procedures.cube_mirror.spot_fit import model_frame_spots

        if rig is None or not hasattr(rig, "sun_sensor"):
            raise CliError("--method model fits the sun sensor's spot model: give a cube-mirror --rig")
        modelled = iter(model_frame_spots(rig, paths, lambda img, path: measure(img, path, "scurve"), readings, progress,
                                          noise_of=settings.noise_for))
    for p in paths:
        if modelled is not None:
            spots = next(modelled)
        elif method == STAR_METHOD:
            img = read_image(p, shape=settings.shape)
            spots = _star_spots(img, settings, psf_sigma_px, threshold_sigma,
                                settings.noise.gain_dn_per_e if gain_dn_per_e is None else gain_dn_per_e, psf_sigmas)
        else:
            spots = measure(read_image(p, shape=settings.shape), p)
        n = len(spots) if max_spots is None else min(len(spots), max_spots)
        for k in range(n):
            for key, val in (("frame", Path(p).name), ("spot", k), ("u_px", spots.u[k]), ("v_px", spots.v[k]),
                             ("sigma_u_px", spots.sigma_u[k]), ("sigma_v_px", spots.sigma_v[k]),
                             ("flux_dn", spots.flux[k]), ("flags", int(spots.flags[k])),
                             ("flag_names", flag_names(spots.flags[k]))):
                cols[key].append(val)
        if progress is not None and modelled is None:
            progress(1)
    return cols


# ------------------------------------------------------------------------------ command

def add_cli(groups: dict) -> None:
    c = groups["top"].add_parser(
        "centroid", help="every spot of every frame (PNG/TIFF/FITS) into a CSV/Parquet table",
        description="Detect and centroid every spot of every frame. Positions are detector pixels with pixel "
                    "(0,0)'s centre at (0,0) (OpenCV's convention); the detector's offset, gain, read noise and "
                    "saturation come from --rig (its --camera) or from the options.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    c.add_argument("frames", nargs="+", metavar="FRAME", help="frame files (8/16-bit PNG or TIFF, FITS)")
    c.add_argument("--out", required=True, metavar="FILE", help="the table (.csv or .parquet)")
    c.add_argument("--method", default=None, choices=METHODS,
                   help="scurve: S-curve corrected first moment (sun disk); tcom, wcom, gauss: rigsim.imaging's; star: a "
                        "star field (sky level and noise mapped across the frame, matched-filter detection to the noise "
                        "floor, Gaussian fit with the frame's PSF width); model: the sun sensor's spot as the rig's optics "
                        "draw it, fitted by maximum likelihood (a cube-mirror --rig; with --angles, the sweep's two passes). "
                        "Default: star with a star-sensor --rig, the rig's procedure.sweep_centroider with a cube-mirror "
                        "--rig's sun sensor, else scurve")
    c.add_argument("--angles", default=None, metavar="FILE",
                   help="--method model: the sweep's angle log (frame, x_deg, y_deg[, z_deg]; every frame in it): a first "
                        "calibration on the moment centroids shapes every spot (the lens's distortion) and gives the "
                        "simulator's gradient direction at each pose; without it the design camera shapes them")
    c.add_argument("--psf-sigma-px", type=number(0.2, 20), default=None,
                   help="--method star: the PSF's σ for the matched filter (default the rig's, else 1 px; each frame's "
                        "width is then measured on its bright stars)")
    c.add_argument("--threshold-sigma", type=number(2, 1000), default=5.0,
                   help="--method star: detection threshold, in σ of the matched filter's noise")
    c.add_argument("--rig", default=None, help="rig file or default rig name: the camera's detector")
    c.add_argument("--camera", default=None, choices=sorted(CAMERAS), help="which camera of the rig (default its main one)")
    c.add_argument("--background", default=None, choices=("model", "frame"),
                   help="model: the offset and read noise of --rig or the options; frame: measured on each frame "
                        "(sigma-clipped median and rms of its pixels; gain from --rig or --gain-dn-per-e). Default: model with "
                        "--rig or --offset-dn, else frame")
    c.add_argument("--offset-dn", type=number(0, 1e6), default=None, help="black level (default the rig's, else 0)")
    c.add_argument("--gain-dn-per-e", type=number(1e-6, 1e3), default=None, help="system gain (default the rig's, else 1)")
    c.add_argument("--read-noise-e", type=number(0, 1e5), default=None, help="read noise (default the rig's, else 0)")
    c.add_argument("--saturation-dn", type=number(1, 1e9), default=None, help="raw DN of a saturated pixel (default the rig's: its ADC's top code, in the frame's DN)")
    c.add_argument("--threshold-dn", type=number(1e-3, 1e6), default=None, help="detection threshold above the offset (default 5σ read noise, ≥ 3 DN)")
    c.add_argument("--max-spots", type=integer(1, 1_000_000), default=None, help="keep the N brightest spots per frame")
    c.add_argument("--quiet", action="store_true", help="no progress bar")
    c.set_defaults(func=cmd_centroid)
    declare(c, "out", suffixes=(".csv", ".parquet"))


def _check_options(args) -> None:
    for name in ("offset_dn", "read_noise_e", "threshold_dn"):
        v = getattr(args, name)
        if v is not None and not (np.isfinite(v) and 0.0 <= v <= 65535.0):
            raise CliError(f"--{name.replace('_', '-')} = {v}: allowed 0 to 65535")
    if args.gain_dn_per_e is not None and not (np.isfinite(args.gain_dn_per_e) and 0.0 < args.gain_dn_per_e <= 100.0):
        raise CliError(f"--gain-dn-per-e = {args.gain_dn_per_e}: allowed > 0 to 100")
    if args.saturation_dn is not None and not (np.isfinite(args.saturation_dn) and 0.0 < args.saturation_dn <= 65535.0):
        raise CliError(f"--saturation-dn = {args.saturation_dn}: allowed > 0 to 65535")
    if args.max_spots is not None and not 1 <= args.max_spots <= 1_000_000:
        raise CliError(f"--max-spots = {args.max_spots}: allowed 1 to 1000000")
    if Path(args.out).suffix.lower() not in (".csv", ".parquet"):
        raise CliError(f"--out = {args.out}: expected a .csv or .parquet file name")


def _readings_of(frames, angles_path, rig) -> dict:
    """The turntable readings {axis: (N,) rad} of ``frames`` (in their order) from the angle log."""
    from rigsim.errors import InputError
    from rigsim.procedures.cube_mirror.files import read_angle_log

    names, reading, _ = read_angle_log(angles_path, rig)
    row = {n: i for i, n in enumerate(names)}
    missing = [Path(f).name for f in frames if Path(f).name not in row]
    if missing:
        raise InputError(f"{angles_path}: column frame: no row for {missing[0]!r}"
                         + (f" (and {len(missing) - 1} other frames)" if len(missing) > 1 else "")
                         + "; --angles must give every frame's turntable reading")
    idx = [row[Path(f).name] for f in frames]
    return {k: np.asarray(v, float)[idx] for k, v in reading.items()}


def cmd_centroid(args) -> int:
    from tqdm import tqdm

    from rigsim.rig.load import load_any_rig

    _check_options(args)
    rig = load_any_rig(args.rig) if args.rig else None
    if args.camera and rig is None:
        raise CliError("--camera needs --rig")
    star_rig = rig is not None and hasattr(rig, "sensor") and (args.camera in (None, "star-sensor"))
    sun_rig = rig is not None and hasattr(rig, "sun_sensor") and args.camera in (None, "sun-sensor")
    method = args.method or (STAR_METHOD if star_rig else rig.procedure.sweep_centroider if sun_rig else "scurve")
    if method == MODEL_METHOD and not sun_rig:
        raise CliError("--method model fits the sun sensor's spot model: give a cube-mirror --rig (its sun-sensor camera)")
    if args.angles is not None and method != MODEL_METHOD:
        raise CliError("--angles is for --method model")
    readings = _readings_of(args.frames, args.angles, rig) if args.angles is not None else None
    if method != STAR_METHOD and args.psf_sigma_px is not None:
        raise CliError("--psf-sigma-px is for --method star")
    psf = args.psf_sigma_px if args.psf_sigma_px is not None else (rig.sensor.psf_sigma_px if star_rig else 1.0)
    st = detector_settings(rig, args.camera, offset_dn=args.offset_dn, gain_dn_per_e=args.gain_dn_per_e,
                           read_noise_e=args.read_noise_e, saturation_dn=args.saturation_dn)
    if args.background is not None:
        if args.background == "frame" and (args.offset_dn is not None or args.read_noise_e is not None):
            raise CliError("--background frame measures the offset and the noise on each frame: "
                           "leave out --offset-dn and --read-noise-e")
        st = replace(st, estimate_background=args.background == "frame")
    t0 = time.perf_counter()
    psf_sigmas: list[float] = []
    gain, gain_note = st.noise.gain_dn_per_e, "gain"
    if method == STAR_METHOD and rig is None and args.gain_dn_per_e is None:  # nobody stated it: the sky's own noise
        from rigsim.imaging.star_field import photon_transfer

        first = read_image(args.frames[0], shape=st.shape)
        sat = st.saturation_dn if st.saturation_dn is not None else (
            float(np.iinfo(first.dtype).max) if np.issubdtype(first.dtype, np.integer) else None)
        pt = photon_transfer(first, saturation=sat)
        if pt is not None:
            gain, gain_note = pt.gain_dn_per_e, f"gain (photon transfer of {Path(args.frames[0]).name}'s sky)"
        else:
            gain_note = "gain (not measurable: the sky is too uniform; give --gain-dn-per-e)"
    warnings: list[str] = []
    with tqdm(total=len(args.frames), desc="centroid", unit="frame", disable=True if args.quiet else None) as pb:
        cols = centroid_files(args.frames, st, method=method, threshold_dn=args.threshold_dn,
                              max_spots=args.max_spots, progress=pb.update, warn=warnings.append, psf_sigma_px=psf,
                              threshold_sigma=args.threshold_sigma, gain_dn_per_e=gain, psf_sigmas=psf_sigmas, rig=rig,
                              readings=readings)
    for w in warnings:
        print(f"warning: {w}. Use --background frame, or describe the camera that took the frames "
              "(--rig/--camera, --offset-dn, --read-noise-e)", file=sys.stderr)
    write_table(args.out, cols)
    n_frames_with = len(set(cols["frame"]))
    how = (f"star: sky mapped on each frame, matched filter ≥ {args.threshold_sigma:g}σ, {gain_note} {gain:.4g} DN/e-"
           + (f", PSF σ {np.median(psf_sigmas):.3f} px (median of the frames' bright stars)" if psf_sigmas else "")
           if method == STAR_METHOD else f"{method}; {st.describe()}")
    print(f"{len(cols['frame'])} spots in {n_frames_with} of {len(args.frames)} frames ({how}) "
          f"→ {args.out} [{time.perf_counter() - t0:.2f} s]")
    return 0
