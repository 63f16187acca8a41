"""The null measurements of seeds 000/001 on a user's frames, the same functions the campaign's
measurers call: the hole/spot offset of two aiming-camera frames with the turntable step that
nulls it (``rigsim concentricity``), and the autocollimator's reading of one frame with its σ
(``rigsim autocollimator read``). Nominal rig only."""

from __future__ import annotations

import argparse
import functools
import json
import math
from collections.abc import Mapping

import numpy as np

from rigsim.errors import CliError, InputError
from rigsim.estimation.fit_quality import FitQuality, not_judged
from rigsim.estimation.null_search import numerical_jacobian, offset_model
from rigsim.files.outputs import declare
from rigsim.frames import ARCSEC_PER_RAD
from rigsim.imaging.screen import apply_flat, flat_field, hole_spot_offset
from rigsim.imaging.spot import THRESHOLD_SIGMA, SpotMeasurement, measure_spot
from rigsim.optics.aiming import nominal_screen_homography
from rigsim.procedures.fit_verdict import add_accept_option, judge
from rigsim.rig.cube_mirror import Autocollimator, CubeMirrorRig
from rigsim.rig.load import DEFAULT_RIG

__all__ = ["measure_concentricity", "null_step", "parse_reading", "read_autocollimator", "autocollimator_optics",
           "autocollimator_roi_px", "autocollimator_targets", "add_cli"]

FREE_AXES = ("X", "Y")


def measure_concentricity(rig: CubeMirrorRig, hole_dn: np.ndarray, spot_dn: np.ndarray, *,
                          method: str = "moments", flat_dn: np.ndarray | None = None) -> dict:
    """Hole and spot centres on the screen (mm) and their offset (mm and aiming-camera px, spot −
    hole) from a hole frame (the spot blocked) and a spot frame, with the nominal screen homography
    and the aiming camera's ``hole_background`` fit. ``method="model"``: the spot's centre from the
    forward-model fit of the spot frame (:func:`rigsim.procedures.cube_mirror.model_spots.fit_screen_spot`,
    starting from the moments'; keys ``spot_sigma_mm``, ``spot_chi2_dof`` and ``spot_problem`` added;
    the spot is NaN when the fit is refused). ``flat_dn``: the mean of frames of the screen lit
    evenly by a lamp; their flat field against the hole frame (:func:`rigsim.imaging.screen.flat_field`)
    divides the spot before either fit (docs/effects-screen.md)."""
    if method not in ("moments", "model"):
        raise ValueError(f"method = {method!r}: 'moments' or 'model'")
    ac = rig.aiming_camera
    if rig.procedure.method != "diaphragm" or ac is None:
        raise InputError(f"rig {rig.name!r} has no diaphragm screen and aiming camera (seed 000's method)")
    if flat_dn is not None:
        spot_dn = apply_flat(hole_dn, spot_dn, flat_field([flat_dn], hole_dn))
    m = hole_spot_offset(hole_dn, spot_dn, nominal_screen_homography(ac), object_pixel_mm=ac.object_pixel_mm,
                         offset_dn=ac.detector.offset_dn * ac.detector.code_step_dn, background=ac.hole_background)
    if method == "model":
        from rigsim.procedures.cube_mirror.model_spots import fit_screen_spot

        r, _ = fit_screen_spot(rig, hole_dn, spot_dn, hole_mm=m["hole_mm"], start_mm=m["spot_mm"])
        sc = r["spot_mm"] if r["problem"] is None else np.full(2, np.nan)
        m.update(spot_mm=sc, offset_mm=sc - m["hole_mm"], offset_px=(sc - m["hole_mm"]) / ac.object_pixel_mm,
                 spot_sigma_mm=r["sigma_mm"], spot_chi2_dof=r["chi2_dof"], spot_problem=r["problem"])
    return m


def null_step(rig: CubeMirrorRig, reading_rad: Mapping[str, float], offset_px, axis_order: str | None = None) -> dict:
    """The operator's next move (seed 000 Table 1, by hand): the Newton step of the free axes that
    cancels ``offset_px`` under the nominal offset model, and the command it gives (rounded to the
    rig's command resolution). Angles in degrees."""
    r = dict(reading_rad)
    free = [a for a in FREE_AXES if a in r]
    model = offset_model(rig, r, axis_order)
    J = numerical_jacobian(model, r, free)
    dx, *_ = np.linalg.lstsq(J, -np.asarray(offset_px, float), rcond=None)
    q = rig.procedure.command_resolution_deg
    step = {a: math.degrees(float(d)) for a, d in zip(free, dx)}
    nxt = {a: math.degrees(v) for a, v in r.items()}
    for a, d in step.items():
        x = nxt[a] + d
        nxt[a] = round(x / q) * q if q > 0 else x
    return {"step_deg": step, "next_reading_deg": nxt, "px_per_deg": (J * math.pi / 180.0).tolist(),
            "command_resolution_deg": q}


def autocollimator_optics(rig: CubeMirrorRig):
    """The autocollimator's nominal optics (its calibration: spot position → reading), with its
    beam splitter plate when ``[effects.beam_splitter]`` is on (the factory calibration is made
    with it)."""
    from rigsim.optics.autocollimator import AutocollimatorOptics
    from rigsim.rig.effects_autocollimator import beam_splitter_of

    if rig.autocollimator is None:
        raise InputError(f"rig {rig.name!r} has no autocollimator (seed 001's method)")
    return AutocollimatorOptics(rig.autocollimator, beam_splitter=beam_splitter_of(rig))


def autocollimator_targets(rig: CubeMirrorRig) -> dict[str, tuple[str, float]]:
    """The mirrors this rig's autocollimator looks at: {target: (outline, size mm)} — the cube face
    (square, its edge) and, when the rig has one, the inner-frame plane mirror (disk, diameter)."""
    out = {"face": ("square", float(rig.cube.edge_mm))}
    if rig.plane_mirror is not None:
        out["plane_mirror"] = ("disk", float(rig.plane_mirror.diameter_mm))
    return out


@functools.lru_cache(maxsize=64)
def _roi_px(ac_json: str, targets: tuple) -> int:
    from rigsim.optics.autocollimator import AutocollimatorOptics, centroid_roi_px, peak_over_noise

    ac = Autocollimator.model_validate_json(ac_json)
    optics = AutocollimatorOptics(ac)
    p = peak_over_noise(ac.detector)
    return max(centroid_roi_px(optics.spot_extent(optics.centred_mirror(shape, size), peak_over_noise=p,
                                                  k_sigma=THRESHOLD_SIGMA))
               for _, (shape, size) in targets)


def autocollimator_roi_px(rig: CubeMirrorRig, target: str | None = None) -> int:
    """Side (odd, px) of the centroid window on this rig's autocollimator frames of ``target``
    (``"face"`` or ``"plane_mirror"``), derived from its geometry
    (:func:`rigsim.optics.autocollimator.centroid_roi_px`, docs/autocollimation.md): the return
    spot of the mirror centred at its null — ray-optics image plus the diffraction pattern above
    ``THRESHOLD_SIGMA`` of the background — at the renderer's brightness setting (peak at half the
    full well). ``target=None`` (a frame whose mirror is not known): the largest over the rig's
    targets (:func:`autocollimator_targets`). Default rig: 59 px on a face (and for ``None``),
    41 px on the plane mirror. Cached per autocollimator and target (the first call traces ~0.3 s)."""
    if rig.autocollimator is None:
        raise InputError(f"rig {rig.name!r} has no autocollimator (seed 001's method)")
    targets = autocollimator_targets(rig)
    if target is not None:
        if target not in targets:
            raise InputError(f"target = {target!r}: rig {rig.name!r} has {', '.join(targets)}")
        targets = {target: targets[target]}
    return _roi_px(rig.autocollimator.model_dump_json(), tuple(sorted(targets.items())))


def read_autocollimator(rig: CubeMirrorRig, dn: np.ndarray, optics=None,
                        target: str | None = None, *, method: str = "tcom",
                        construction: str = "optics") -> tuple[np.ndarray, np.ndarray, SpotMeasurement]:
    """The autocollimator's reading (θx, θy) in arcsec of one frame, its 1σ (the centroid's noise
    through the calibration), and the spot measurement (centroid window
    :func:`autocollimator_roi_px` of ``target``, the frame's mirror if known). The reading is NaN
    when the spot is not measurable (``SpotMeasurement.problem`` says why). ``method="model"``: the
    spot's forward-model fit (:func:`rigsim.procedures.cube_mirror.model_spots.fit_autocollimator_spot`;
    needs ``target``; ``construction="renderer"`` for rigsim's rendered frames)."""
    if method not in ("tcom", "model"):
        raise ValueError(f"method = {method!r}: 'tcom' or 'model'")
    optics = optics if optics is not None else autocollimator_optics(rig)
    if method == "model":
        targets = autocollimator_targets(rig)
        if target not in targets:
            raise InputError(f"the autocollimator's spot model needs the frame's mirror (target: {', '.join(targets)})")
        from rigsim.procedures.cube_mirror.model_spots import fit_autocollimator_spot

        sm, _ = fit_autocollimator_spot(rig, dn, targets[target], optics=optics,
                                        roi_px=autocollimator_roi_px(rig, target), construction=construction)
    else:
        sm = measure_spot(dn, rig.autocollimator.detector, roi_px=autocollimator_roi_px(rig, target))
    if not sm.ok:
        return np.full(2, np.nan), np.full(2, np.nan), sm
    m = optics.reading(sm.uv) * ARCSEC_PER_RAD
    J = np.empty((2, 2))
    for k in range(2):
        d = np.zeros(2)
        d[k] = 0.01
        J[:, k] = (optics.reading(sm.uv + d) - optics.reading(sm.uv - d)) * ARCSEC_PER_RAD / 0.02
    sig = np.sqrt(np.diag(J @ np.diag(sm.sigma_uv**2) @ J.T)) if sm.sigma_uv is not None else np.full(2, np.nan)
    return m, sig, sm


# ------------------------------------------------------------------------------ what one frame can judge

NOISE_LIMIT = 5.0  # a frame whose background noise is this many times the detector model's is not of this camera
HOLE_LIMIT = 2.0   # a hole whose size is off the rig's by more than this factor is not the diaphragm's hole


def frame_noise_problems(rig: CubeMirrorRig, camera: str, frames: Mapping[str, np.ndarray]) -> tuple[list[str], str]:
    """The frames whose background noise (clipped rms) exceeds :data:`NOISE_LIMIT` times the
    rig's detector model at their level (the σ of every measurement on them rests on that model),
    and a phrase with the largest ratio."""
    from rigsim.procedures.detector_settings import detector_settings, frame_background

    n = detector_settings(rig, camera).noise
    out, worst = [], 0.0
    for name, img in frames.items():
        med, sd = frame_background(img)
        model = float(np.sqrt(n.variance(max(med, n.offset_dn))))
        ratio = sd / model if model > 0 else math.inf
        worst = max(worst, ratio)
        if not ratio <= NOISE_LIMIT:
            out.append(f"{name}: background noise {sd:.3g} DN, {ratio:.3g}× the rig's {camera} model ({model:.3g} DN): "
                       "a frame of another camera, or the rig's detector is not this camera's")
    return out, f"background noise {worst:.3g}× the rig's {camera} model at most"


def concentricity_quality(rig: CubeMirrorRig, m: dict, hole_dn: np.ndarray, spot_dn: np.ndarray,
                          names=("HOLE", "SPOT")) -> FitQuality:
    """What a hole/spot pair can judge (one measurement: no χ²): the frames' noise against the
    aiming camera's model (:func:`frame_noise_problems`) and the hole's size against the rig's
    diaphragm (its equivalent diameter, from the pixels above half its peak, within a factor
    :data:`HOLE_LIMIT` of ``diaphragm_screen.hole_diameter_mm``)."""
    problems, noise = frame_noise_problems(rig, "aiming-camera", dict(zip(names, (hole_dn, spot_dn))))
    d = 2.0 * math.sqrt(max(m["hole_pixels"], 0) / math.pi) * rig.aiming_camera.object_pixel_mm
    d0 = rig.diaphragm_screen.hole_diameter_mm
    if not (d0 / HOLE_LIMIT <= d <= d0 * HOLE_LIMIT):
        problems.append(f"{names[0]}: the hole is {d:.3g} mm across, the rig's is {d0:g} mm: not a frame of the lit "
                        "hole with the return blocked")
    return not_judged(f"one hole/spot pair, no χ²: hole {d:.3g} mm across (the rig's {d0:g} mm), {noise}",
                      problems=problems)


# ------------------------------------------------------------------------------ commands

def parse_reading(text: str | None, rig: CubeMirrorRig, face_index: int, option: str = "--reading",
                  every_axis: bool = True) -> dict[str, float]:
    """``"X=181.4,Y=0.55"`` (degrees) → {axis: rad} for every axis of the rig; an axis named twice is refused,
    and so is a missing one when ``every_axis`` (a turntable's reading names every axis; a render's ``--pose``
    leaves the others at 0); empty: the search start of the face ``face_index``."""
    if not text:
        return {k: math.radians(v) for k, v in rig.procedure.search_start[face_index].items()}
    from rigsim.files.numbers import parse_float

    labels = [a.label for a in rig.turntable.axes]
    want = ",".join(f"{a}=DEGREES" for a in labels)
    out = {}
    for part in text.split(","):
        k, sep, v = (x.strip() for x in part.partition("="))
        if not sep or k not in labels:
            raise CliError(f"{option} = {text!r}: expected {want} (every axis of the turntable)")
        if k in out:
            raise CliError(f"{option} = {text!r}: axis {k} given twice; expected {want}")
        try:
            x = parse_float(v)
        except ValueError:
            raise CliError(f"{option} = {text!r}: {v!r} is not a number of degrees in ASCII digits") from None
        if not (math.isfinite(x) and -360.0 <= x <= 360.0):
            raise CliError(f"{option} = {text!r}: {k} = {v}: allowed -360 to 360 degrees")
        out[k] = math.radians(x)
    missing = [a for a in labels if a not in out]
    if not every_axis:
        return {a: out.get(a, 0.0) for a in labels}
    if missing:  # a reading without an axis is not a reading at 0
        raise CliError(f"{option} = {text!r}: no angle for axis {', '.join(missing)}; expected {want} (every axis of the "
                       "turntable, as its encoders read)")
    return out


def parse_offset(text: str | None, option: str) -> np.ndarray:
    """``"X,Y"`` (px, each finite and within ±10⁴) → (2,); None: (0, 0)."""
    if text is None:
        return np.zeros(2)
    parts = [p.strip() for p in text.split(",")]
    try:
        v = np.array([float(p) for p in parts], float)
    except ValueError:
        v = np.array([])
    if v.shape != (2,) or not np.all(np.isfinite(v)) or np.any(np.abs(v) > 1e4):
        raise CliError(f"{option} = {text!r}: expected two numbers X,Y in px, each within ±10000")
    return v


def add_cli(groups: dict) -> None:
    sub = groups["top"]
    c = sub.add_parser(
        "concentricity", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        help="hole and returned-spot centres on the diaphragm screen and the turntable step to the null (seed 000)",
        description="Seed 000's Table 1 loop by hand: from the aiming camera's hole frame (the returned spot "
                    "blocked) and spot frame, the hole and spot centres (px and mm on the screen), their offset in "
                    "aiming-camera px and µm on the screen, and the step of the X'/Y' axes that nulls it under the "
                    "nominal geometry.")
    c.add_argument("hole", metavar="HOLE", help="aiming-camera frame of the lit hole, the return blocked")
    c.add_argument("spot", metavar="SPOT", help="aiming-camera frame with the returned spot")
    c.add_argument("--rig", default=DEFAULT_RIG, help="rig file or default name (nominal values only)")
    c.add_argument("--face", default=None, help="the face being nulled (default the procedure's first)")
    c.add_argument("--reading", default=None, help="turntable reading of the frames, e.g. X=181.4,Y=0.55 (degrees; "
                   "default the face's search start)")
    c.add_argument("--axis-order", default=None, help="nesting reading of the nominal model (default the rig's)")
    c.add_argument("--null-offset-px", default=None, metavar="X,Y",
                   help="the offset (spot − hole, aiming-camera px) at which your aiming camera shows concentricity: its "
                        "mounting offset, as your procedure defines the null (`run cube-mirror --export-frames` writes the "
                        "campaign's in null_frames.csv); default 0,0")
    c.add_argument("--method", default="moments", choices=["moments", "model"],
                   help="the spot's centre: the moments of spot − hole, or the forward model of the divergent spot "
                        "fitted to the spot frame (docs/forward-model-spots.md)")
    c.add_argument("--flat", nargs="+", default=None, metavar="FLAT",
                   help="frames of the screen lit evenly by a lamp, the simulator shuttered (`run cube-mirror "
                        "--export-frames` writes the campaign's as aiming-flat_*): their mean, less the hole frame, "
                        "divides the spot, removing the screen's grain and the camera's PRNU (docs/effects-screen.md)")
    c.add_argument("--json", default=None, metavar="FILE", help="also write the result as JSON")
    add_accept_option(c)
    c.set_defaults(func=cmd_concentricity)
    declare(c, "json")
    a = sub.add_parser("autocollimator", help="the autocollimator's reading of a frame (seed 001)")
    acs = a.add_subparsers(dest="autocollimator_command", metavar="ACTION")
    r = acs.add_parser("read", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
                       help="the reading (θx, θy) in arcsec of one autocollimator frame, with its σ",
                       description="Find and centroid the return spot of an autocollimator frame and convert it to "
                                   "the instrument's reading with its nominal calibration.")
    r.add_argument("frame", metavar="FRAME", help="autocollimator frame (PNG/TIFF/FITS)")
    r.add_argument("--rig", default="sun_sensor_3axis_autocollimator", help="rig file or default name")
    r.add_argument("--method", default="tcom", choices=["tcom", "model"],
                   help="the spot's centroid: thresholded centre of mass, or the forward model of the return spot "
                        "fitted by maximum likelihood (needs --target; docs/forward-model-spots.md)")
    r.add_argument("--target", default=None, choices=["face", "plane_mirror"],
                   help="the frame's mirror (default: not known; the centroid window is the largest)")
    r.add_argument("--json", default=None, metavar="FILE", help="also write the result as JSON")
    add_accept_option(r)
    r.set_defaults(func=cmd_autocollimator_read)
    declare(r, "json")


def _write_json(path, obj) -> None:
    from rigsim.files import write_json

    write_json(path, obj)


def cmd_concentricity(args) -> int:
    from rigsim.files import read_image
    from rigsim.rig.load import load_rig

    rig = load_rig(args.rig)
    if rig.aiming_camera is None:
        raise CliError(f"--rig {args.rig}: no aiming camera (seed 000's method); this rig uses {rig.procedure.method}")
    faces = list(rig.procedure.faces)
    face = args.face or faces[0]
    if face not in faces:
        raise CliError(f"--face = {face!r}: the procedure's faces are {', '.join(faces)}")
    if args.axis_order is not None:
        from rigsim.procedures.cube_mirror.files import axis_orders

        allowed = axis_orders(rig)
        if args.axis_order not in allowed:
            raise CliError(f"--axis-order = {args.axis_order!r}: allowed for this {len(rig.turntable.axes)}-axis table: "
                           f"{', '.join(allowed)}")
    parse_reading(args.reading, rig, faces.index(face))  # a bad reading is refused before the frames are read
    from rigsim.files.inputs import check_distinct

    flats = list(getattr(args, "flat", None) or [])
    check_distinct([args.hole, args.spot, *flats], "HOLE/SPOT/FLAT", by_name=False)
    shape = tuple(rig.aiming_camera.resolution_px[::-1])
    hole = read_image(args.hole, shape=shape, what="aiming-camera frame")
    spot = read_image(args.spot, shape=shape, what="aiming-camera frame")
    flat_dn = _mean_flat(flats, shape, hole) if flats else None
    method = getattr(args, "method", "moments")
    m = measure_concentricity(rig, hole, spot, method=method, flat_dn=flat_dn)
    if method == "model" and m.get("spot_problem"):
        raise InputError(f"{args.spot}: {m['spot_problem']}")
    q = concentricity_quality(rig, m, hole, spot)
    verdict = judge(q, [("HOLE and SPOT swapped", lambda: concentricity_quality(
        rig, measure_concentricity(rig, spot, hole), spot, hole, ("SPOT", "HOLE")))], accept=args.accept_poor_fit,
        what="concentricity measurement")
    if not np.all(np.isfinite(m["offset_px"])):
        raise InputError(f"{args.spot}: no returned spot above 10 % of its peak outside the hole's glow")
    reading = parse_reading(args.reading, rig, faces.index(face))
    zero = parse_offset(args.null_offset_px, "--null-offset-px")
    off = np.asarray(m["offset_px"], float) - zero
    thr = rig.aiming_camera.concentric_threshold_px
    nulled = bool(np.all(np.abs(off) < thr))
    st = null_step(rig, reading, off, args.axis_order)
    px_um = rig.aiming_camera.object_pixel_mm * 1000.0
    print(f"hole centre {m['hole_mm'][0]:+.4f}, {m['hole_mm'][1]:+.4f} mm; spot centre {m['spot_mm'][0]:+.4f}, "
          f"{m['spot_mm'][1]:+.4f} mm (screen axes)")
    print(f"offset spot − hole: x {m['offset_px'][0]:+.3f} px, y {m['offset_px'][1]:+.3f} px "
          f"({m['offset_mm'][0] * 1000:+.1f}, {m['offset_mm'][1] * 1000:+.1f} µm on the screen; 1 px = {px_um:.1f} µm)")
    if np.any(zero != 0):
        print(f"against the null offset ({zero[0]:+.3f}, {zero[1]:+.3f}) px: x {off[0]:+.3f} px, y {off[1]:+.3f} px")
    if nulled:
        print(f"concentric: both offsets below the rig's threshold ({thr:g} px); this reading is the face's null")
    else:
        print("step to the null: " + ", ".join(f"{k} {v:+.5f}°" for k, v in st["step_deg"].items())
              + "; next command " + ", ".join(f"{k}={v:.4f}°" for k, v in st["next_reading_deg"].items())
              + (f" (rounded to {st['command_resolution_deg']:g}°)" if st["command_resolution_deg"] else ""))
    res = {"kind": "concentricity", "rig": rig.name, "face": face, "hole_mm": m["hole_mm"], "spot_mm": m["spot_mm"],
           "offset_mm": m["offset_mm"], "offset_um": np.asarray(m["offset_mm"]) * 1000.0, "offset_px": m["offset_px"],
           "hole_pixels": m["hole_pixels"], "spot_pixels": m["spot_pixels"],
           "reading_deg": {k: math.degrees(v) for k, v in reading.items()}, "null_offset_px": zero,
           "offset_from_null_px": off, "threshold_px": thr, "nulled": nulled, **st, "fit": verdict.block()}
    for line in verdict.lines():
        print(line)
    if args.json:
        _write_json(args.json, res)
    return 0


def _mean_flat(paths, shape, hole) -> np.ndarray:
    """The mean of the --flat frames; refused (one line) when they are not lit above the hole frame."""
    from rigsim.files import read_image

    mean = np.mean([read_image(p, shape=shape, what="aiming-camera flat frame").astype(float) for p in paths], axis=0)
    try:
        flat_field([mean], hole)
    except ValueError as e:  # the median level above the hole frame is not > 0
        raise InputError(f"{paths[0]}: --flat: {e} (a flat is the screen lit evenly by a lamp; is this a dark or a "
                         "hole frame?)") from None
    return mean


def cmd_autocollimator_read(args) -> int:
    from rigsim.files import read_image
    from rigsim.rig.load import load_rig

    rig = load_rig(args.rig)
    if rig.autocollimator is None:
        raise CliError(f"--rig {args.rig}: no autocollimator (seed 001's method); this rig uses {rig.procedure.method}")
    dn = read_image(args.frame, shape=tuple(rig.autocollimator.resolution_px[::-1]), what="autocollimator frame")
    m, sig, sm = read_autocollimator(rig, dn, None, getattr(args, "target", None), method=getattr(args, "method", "tcom"))
    if not sm.ok:
        raise InputError(f"{args.frame}: {sm.problem}")
    problems, noise = frame_noise_problems(rig, "autocollimator", {str(args.frame): dn})
    verdict = judge(not_judged(f"one spot on one frame, no χ²: {noise}", problems=problems),
                    accept=args.accept_poor_fit, what="autocollimator reading")
    print(f"reading θx {m[0]:+.4f}″ ± {sig[0]:.4f}″, θy {m[1]:+.4f}″ ± {sig[1]:.4f}″ (spot at u {sm.uv[0]:.3f}, "
          f"v {sm.uv[1]:.3f} px)")
    thr = rig.autocollimator.null_threshold_arcsec
    nulled = bool(np.all(np.abs(m) < thr))
    print(f"{'nulled' if nulled else 'not nulled'}: the rig's null threshold is {thr:g}″ on both readings")
    res = {"kind": "autocollimator reading", "rig": rig.name, "reading_arcsec": m, "sigma_arcsec": sig,
           "spot_uv_px": sm.uv, "spot_sigma_uv_px": sm.sigma_uv, "peak_dn": sm.peak_dn,
           "background_dn": sm.background_dn, "threshold_arcsec": thr, "nulled": nulled, "fit": verdict.block()}
    for line in verdict.lines():
        print(line)
    if args.json:
        _write_json(args.json, res)
    print(json.dumps({"reading_arcsec": m.tolist(), "sigma_arcsec": sig.tolist()}))
    return 0
