"""The ``rigsim`` command: the root parser, ``doctor`` and ``rig``; every rig family adds its own
commands (:mod:`rigsim.families`), datasets and the 3D view serve all of them."""

from __future__ import annotations

import argparse
import errno
import json
import os
import sys

import rigsim
from rigsim.dataset import cli as dataset_cli
from rigsim.errors import CliError, RigsimError
from rigsim.families import FAMILIES, family_of
from rigsim.files.options import integer, number
from rigsim.files.outputs import declare
from rigsim.procedures import centroid as centroid_stage
from rigsim.procedures import readings_commands, robustness_commands
from rigsim.procedures import target_commands
from rigsim.view import cli as view_cli

EPILOG = """\
examples:
  rigsim run cube-mirror                        seed 000 campaign on rendered frames (default rig), report in renders/
  rigsim run cube-mirror --rig sun_sensor_3axis_autocollimator      seed 001 on rendered frames
  rigsim run cube-mirror --ideal --no-budget    noise-free ideal rig: the simulator's own error
  rigsim run cube-mirror --analytic             the same campaign without rendering (seconds)
  rigsim run boresight                          seed 003: dual line-array camera, DVAD vs simplified
  rigsim run star-calibration                   seed 004: star-sensor calibration, AD vs ADS
  rigsim run robustness star_sensor             what hot pixels, cosmic rays, stray light do to the calibration
  rigsim triad 181.398 0.528 91.386 -0.048      R(pm<-rot) from Table 1's final angles
  rigsim centroid frames/*.png --rig sun_sensor_2axis_diaphragm --out centroids.csv    your own frames
  rigsim calibrate sun-sensor --angles angles.csv --centroids centroids.csv --out sun.json
  rigsim star calibrate frames/*.fits --attitudes attitudes.csv --out cal                docs/user-data.md
  rigsim render target --target chessboard:10x7:20 --poses poses.csv --out board   a target through the true camera
  rigsim rig check my_rig.toml                  validate a rig file (and print its geometry)
  rigsim rig copy star_sensor my.toml           a packaged rig as the start of your own
  rigsim rig new star-sensor --resolution 1024x768 --pixel-pitch-um 6.9 --focal-length-mm 35 --out my.toml
  rigsim doctor                                 versions, libLLVM, Mitsuba variant, where the default rigs are installed

--rig takes a rig file's path, or the name of a default rig installed with rigsim (rigsim rig list; rigsim rig
copy NAME DEST makes one yours). The guides (docs/*.md) are in rigsim's source repository, not in the installed package.
"""


# ------------------------------------------------------------------------------ rig / doctor

def cmd_rig_check(args) -> int:
    from rigsim.reporting import safe_text
    from rigsim.rig.cube_mirror import CubeMirrorRig
    from rigsim.rig.load import load_any_rig, resolve_rig_path
    from rigsim.rig.star import StarRig

    rig = load_any_rig(args.rig)
    extra = ""
    if isinstance(rig, CubeMirrorRig):
        from rigsim.rig.geometry import check_geometry, geometry_summary

        extra = f", {rig.turntable.kind} turntable, method {rig.procedure.method}"
        _print_lines(geometry_summary(rig))
        check_geometry(rig, resolve_rig_path(args.rig))
    elif isinstance(rig, StarRig):
        from rigsim.rig.star_check import star_summary

        _print_lines(star_summary(rig))
    print(f"{args.rig}: OK — '{safe_text(rig.name)}' (seed {rig.seed_document}, family {family_of(rig).name}{extra})")
    return 0


def _print_lines(lines) -> None:
    """``rig check``'s lines: a mark (blank, ``!`` a warning, ``✗`` an error), the item, the value."""
    w = max(len(g.item) for g in lines)
    for g in lines:
        mark = {"ok": " ", "warning": "!", "error": "✗"}[g.status]
        print(f"{mark} {g.item:{w}s}  {g.value}")


def cmd_rig_list(args) -> int:
    from rigsim.rig import default_rigs
    from rigsim.rig.load import load_any_rig

    for p in default_rigs():
        r = load_any_rig(p)
        print(f"{p.stem:40s} seed {r.seed_document}  {family_of(r).name:12s} {r.description}")
    return 0


def cmd_rig_import_camera(args) -> int:
    from pathlib import Path

    from rigsim.files.atomic import atomic_write_text
    from rigsim.rig.cube_mirror import CubeMirrorRig
    from rigsim.rig.load import RIG_MODELS, parse_model, parse_rig_text, read_rig_text, resolve_rig_path
    from rigsim.rig.opencv_camera import import_camera, read_opencv_camera

    src = resolve_rig_path(args.rig)
    out = Path(args.out)
    if out.suffix != ".toml":
        raise CliError(f"--out {out}: a rig file name ends in .toml")
    if out.exists() and out.resolve() == src.resolve():
        raise CliError(f"--out {out}: is the rig file itself; write a new file (the original stays as it was)")
    cam = read_opencv_camera(args.camera)
    text, changes, left = import_camera(read_rig_text(src), src, cam, pixel_pitch_um=args.pixel_pitch_um,
                                        source=args.camera)
    data = parse_rig_text(text, out)  # the new rig is checked as `rig check` would, before anything is written
    rig = parse_model(RIG_MODELS.get(str(data.get("seed_document", "")), CubeMirrorRig), data, out)
    if isinstance(rig, CubeMirrorRig):
        from rigsim.rig.geometry import check_geometry

        check_geometry(rig, out)
    atomic_write_text(out, text)
    print("changed:")
    for c in changes:
        print(f"  {c}")
    print("left as it was:")
    for c in left:
        print(f"  {c}")
    print(f"wrote {out}: {src.name} with the camera of {args.camera}; check it: rigsim rig check {out}")
    return 0


def _destination(out: str, force: bool) -> "Path":
    """``--out``/DEST of a new rig file: a ``.toml`` name; an existing file only with ``--force``, and never
    anything but a regular file (a folder, a device, a FIFO)."""
    import stat
    from pathlib import Path

    p = Path(out)
    if p.suffix != ".toml":
        raise CliError(f"{out}: a rig file name ends in .toml")
    try:
        st = p.stat()
    except FileNotFoundError:
        return p
    except OSError as exc:
        raise CliError(f"{out}: cannot be used ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise CliError(f"{out}: exists and is not a regular file (a folder, device or FIFO): give another name")
    if not force:
        raise CliError(f"{out}: exists; give --force to replace it")
    return p


def cmd_rig_new(args) -> int:
    from rigsim.files.atomic import atomic_write_text
    from rigsim.rig.load import parse_rig_text, parse_star_rig
    from rigsim.rig.star_check import star_summary
    from rigsim.rig.star_design import StarDesign, design_values, star_rig_text

    out = _destination(args.out, args.force)
    keys = ("focal_length_mm", "fov_deg", "f_number", "adc_bits", "container_bits", "offset_dn", "gain_dn_per_e",
            "full_well_e", "read_noise_e", "exposure_s", "magnitude_limit", "name")
    given = [k for k in keys if getattr(args, k) is not None]
    design = StarDesign(args.resolution, args.pixel_pitch_um, given=given, **{k: getattr(args, k) for k in keys})
    try:
        values = design_values(design)
    except ValueError as exc:
        raise CliError(f"rig new star-sensor: {exc}") from None
    shown = " ".join([f"--resolution {args.resolution[0]}x{args.resolution[1]}", f"--pixel-pitch-um {args.pixel_pitch_um:g}"]
                     + [f"--{k.replace('_', '-')} {getattr(args, k):g}" for k in given if k != "name"])
    text = star_rig_text(values, shown)
    rig = parse_star_rig(parse_rig_text(text, out), out)  # checked as `rig check` would, before anything is written
    atomic_write_text(out, text)
    _print_lines(star_summary(rig))
    sm = values["_summary"]
    instrument = ("sensor", "sensor.psf", "sensor.detector", "nominal", "sky")
    defaults = "; ".join(f"[{t}] " + " ".join(k for k, (_, n) in values[t].items() if n.startswith("default"))
                         for t in instrument)
    print(f"  given           {shown}")
    print(f"  derived         f = {sm['f_px']:.2f} px, FOV {sm['fov_deg'][0]:.3f}° × {sm['fov_deg'][1]:.3f}°, PSF σ "
          f"{sm['psf_sigma_px']:.2f} px, stars to Hp {sm['magnitude_limit']:g} (≈ {sm['stars_per_frame']:.0f} per frame)")
    print(f"  defaults        {defaults}; and the procedure: [sequence] [identification] [calibration] [study] "
          "(each marked `default` in the file: review them)")
    if sm["stars_per_frame"] < 10:
        print(f"! few stars: ≈ {sm['stars_per_frame']:.1f} per frame; identification needs 4 and calibration many more "
              "(a longer --exposure-s, a faster lens, or a wider field)")
    print(f"wrote {out}; next: rigsim rig check {out}, rigsim render star-field --rig {out}, "
          f"rigsim run star-calibration --rig {out}")
    return 0


def cmd_rig_copy(args) -> int:
    from rigsim.files.atomic import atomic_write_text
    from rigsim.rig import default_rigs
    from rigsim.rig.load import read_rig_text

    known = {p.stem: p for p in default_rigs()}
    name = args.name.removesuffix(".toml")
    if name not in known:
        raise CliError(f"rig copy: no packaged rig {args.name!r}; the packaged rigs are {', '.join(sorted(known))}")
    out = _destination(args.dest, args.force)
    atomic_write_text(out, read_rig_text(known[name]))
    print(f"wrote {out}: a copy of the packaged rig {name}; edit it, then: rigsim rig check {out}")
    return 0


def cmd_doctor(args) -> int:
    import platform
    from pathlib import Path

    from rigsim.rig.load import SCENES_DIR

    info: dict = {"rigsim": rigsim.__version__, "python": platform.python_version(),
                  "installed at": str(Path(rigsim.__file__).resolve().parent),
                  "default rigs": f"{SCENES_DIR} (rigsim rig list; rigsim rig copy NAME DEST to start your own)",
                  "result schemas": str(Path(rigsim.__file__).resolve().parent / "schemas"),
                  "guides": "docs/ of rigsim's source repository (not installed with the package)"}
    try:
        from rigsim.render.backend import doctor_report
    except ImportError as exc:  # render package not available
        info["render"] = f"unavailable: {exc}"
    else:
        info.update(doctor_report())
    if args.json:
        print(json.dumps(info, indent=2, default=str))
        return 0
    for k, v in info.items():
        if isinstance(v, list):
            print(f"{k}:")
            for item in v:
                print(f"  - {item}")
        else:
            print(f"{k}: {v}")
    return 0


# ------------------------------------------------------------------------------ render / export


# ------------------------------------------------------------------------------ parser

class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error: the command, the option, the value and what is allowed (exit 2)."""

    def error(self, message: str):
        from rigsim.reporting import safe_text

        self.exit(2, f"{self.prog}: error: {safe_text(message, 2000)} (see {self.prog} --help)\n")


def _resolution(text: str) -> tuple[int, int]:
    """``WxH`` in pixels, each 16 to 8192."""
    w, sep, h = text.lower().replace("×", "x").partition("x")
    try:
        wh = (int(w), int(h)) if sep else None
    except ValueError:
        wh = None
    if wh is None or not all(16 <= v <= 8192 for v in wh):
        raise argparse.ArgumentTypeError(f"{text!r} is not WxH with each from 16 to 8192 px (e.g. 1024x768)")
    return wh


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="rigsim",
        description="rigsim — physically rendered optical simulator of the rigs that calibrate spacecraft attitude sensors.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"rigsim {rigsim.__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    d = sub.add_parser("doctor", help="versions, libLLVM and the Mitsuba variant rigsim will use")
    d.add_argument("--json", action="store_true", help="machine-readable output")
    d.set_defaults(func=cmd_doctor)

    g = sub.add_parser("rig", help="rig files: list and copy the defaults, write a new one, validate a file")
    gs = g.add_subparsers(dest="rig_command", metavar="ACTION")
    gc = gs.add_parser("check", help="validate a rig file")
    gc.add_argument("rig")
    gc.set_defaults(func=cmd_rig_check)
    gl = gs.add_parser("list", help="list the default rigs installed with rigsim (their folder: rigsim doctor)")
    gl.set_defaults(func=cmd_rig_list)
    gi = gs.add_parser("import-camera", help="a rig file with the intrinsics of an OpenCV camera (FileStorage YAML/JSON)",
                       description="Write a copy of RIG whose sun sensor (or star sensor) has the camera matrix, "
                                   "distortion and image size of an OpenCV FileStorage file (camera_matrix, "
                                   "distortion_coefficients k1 k2 p1 p2 k3, image_width, image_height). The focal "
                                   "length in mm is fx times the rig's pixel pitch. Comments and layout are kept.")
    gi.add_argument("camera", help="OpenCV FileStorage file (.yml, .yaml, .json, .xml)")
    gi.add_argument("--rig", default="sun_sensor_2axis_diaphragm", help="rig file path or default rig name")
    gi.add_argument("--out", required=True, metavar="NEW.toml", help="the new rig file")
    gi.add_argument("--pixel-pitch-um", type=number(0.1, 100.0), default=None, metavar="UM",
                    help="the detector's pixel pitch, if not the rig's (OpenCV's matrix is in pixels)")
    gi.set_defaults(func=cmd_rig_import_camera)
    declare(gi, "out", suffixes=(".toml",))
    gn = gs.add_parser("new", help="a complete rig file from what you know of the camera (star-sensor)",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Write a complete star-sensor rig file from the detector size, the pixel pitch and the "
                                   "focal length (or the field of view across the width) and, if you know them, the "
                                   "f-number and the detector's values. Everything else gets a default scaled to the "
                                   "field of view; the file says which values were given, derived or defaulted.",
                       epilog="example (FLIR Blackfly S BFS-U3-31S4M binned 2×2, a 35 mm f/1.9 lens, 12-bit codes in\n"
                              "16-bit frames):\n  rigsim rig new star-sensor --resolution 1024x768 --pixel-pitch-um 6.9 "
                              "--focal-length-mm 35 \\\n      --f-number 1.9 --adc-bits 12 --container-bits 16 --out my.toml")
    gn.add_argument("kind", choices=["star-sensor"], help="the kind of rig (star-sensor)")
    gn.add_argument("--resolution", type=_resolution, required=True, metavar="WxH", help="detector size in px, e.g. 1024x768")
    gn.add_argument("--pixel-pitch-um", type=number(0.6, 100.0), required=True, metavar="UM", help="pixel pitch (µm)")
    fl = gn.add_mutually_exclusive_group(required=True)
    fl.add_argument("--focal-length-mm", type=number(1.5, 5000.0), metavar="MM", help="the lens's focal length")
    fl.add_argument("--fov-deg", type=number(0.1, 120.0), metavar="DEG",
                    help="or the full field of view across the width: f = (W/2) / tan(FOV/2)")
    gn.add_argument("--f-number", type=number(0.5, 64.0), metavar="N", help="f-number (default 2)")
    gn.add_argument("--adc-bits", type=integer(8, 16), metavar="BITS", help="the ADC's bit depth (default 12)")
    gn.add_argument("--container-bits", type=integer(8, 16), metavar="BITS",
                    help="frames hold the codes MSB-aligned in words of this many bits (a 12-bit ADC in 16-bit frames: "
                         "16; default: the codes as they are)")
    gn.add_argument("--offset-dn", type=number(0.0, 65535.0), metavar="CODES", help="black level, in ADC codes (default 1/64 of the range)")
    gn.add_argument("--gain-dn-per-e", type=number(1e-4, 100.0), metavar="K",
                    help="system gain, ADC codes per electron (default: the top code at the full well)")
    gn.add_argument("--full-well-e", type=number(100.0, 1e7), metavar="E", help="full well, electrons (default 40000)")
    gn.add_argument("--read-noise-e", type=number(0.0, 1e4), metavar="E", help="read noise, electrons rms (default 10)")
    gn.add_argument("--exposure-s", type=number(1e-5, 3600.0), metavar="S", help="exposure (default 0.1 s)")
    gn.add_argument("--magnitude-limit", type=number(-2.0, 12.0), metavar="HP",
                    help="faintest star rendered (default: the magnitude at SNR 10)")
    gn.add_argument("--name", default=None, help="the rig's name (default from its size and focal length)")
    gn.add_argument("--out", required=True, metavar="NEW.toml", help="the new rig file")
    gn.add_argument("--force", action="store_true", help="replace --out if it exists")
    gn.set_defaults(func=cmd_rig_new)
    gp = gs.add_parser("copy", help="copy a packaged default rig to a file of yours, as a starting point",
                       description="Copy one of the rigs packaged with rigsim (rigsim rig list) to DEST, comments and all.")
    gp.add_argument("name", metavar="NAME", help="a packaged rig (rigsim rig list), e.g. star_sensor")
    gp.add_argument("dest", metavar="DEST.toml", help="the new file")
    gp.add_argument("--force", action="store_true", help="replace DEST if it exists")
    gp.set_defaults(func=cmd_rig_copy)
    declare(gn, "out", suffixes=(".toml",))
    declare(gp, "dest", suffixes=(".toml",))

    r = sub.add_parser("run", help="run a documented procedure end to end")
    rs = r.add_subparsers(dest="procedure", metavar="PROCEDURE")
    rd = sub.add_parser("render", help="render frames of a rig (Mitsuba + detector model)")
    rds = rd.add_subparsers(dest="frame_type", metavar="FRAME")
    groups = {"top": sub, "run": rs, "render": rds}
    # every rig family adds its commands (rigsim.families); datasets and the 3D view serve all of them
    for fam in FAMILIES:
        fam.add_cli(groups)
    centroid_stage.add_cli(groups)
    target_commands.add_cli(groups)
    readings_commands.add_cli(groups)
    robustness_commands.add_cli(groups)
    dataset_cli.add_cli(groups)
    view_cli.add_cli(groups)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # --help, --version, or a one-line usage error already printed
        return e.code if isinstance(e.code, int) else 2
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        from rigsim.files.outputs import guard
        from rigsim.render.threads import command_threads

        inputs = _checked_files(parser, args)
        with _Heartbeat(" ".join(a for a in (argv if argv is not None else sys.argv[1:])[:2] if not a.startswith("-"))), \
                command_threads(), guard(inputs):
            rc = int(args.func(args) or 0)
        sys.stdout.flush()
        return rc
    except RigsimError as exc:
        from rigsim.reporting import safe_text

        parts = [ln.strip().removeprefix("- ") for ln in str(exc).splitlines() if ln.strip()] or [type(exc).__name__]
        one = parts[0] + (" " + "; ".join(parts[1:]) if len(parts) > 1 else "")
        print(f"rigsim: error: {safe_text(one, 4000)}", file=sys.stderr)  # one line, control characters escaped
        return int(getattr(exc, "exit_status", 2))
    except KeyboardInterrupt:
        print("rigsim: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (rigsim … | head): stop quietly, as the shell's SIGPIPE would
        _silence_stdout()
        return 141
    except OSError as exc:
        from rigsim.reporting import safe_text

        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            print(f"rigsim: error: no space left on the device writing {exc.filename or 'the output'}; free some and "
                  "run the command again", file=sys.stderr)
            return 1
        if exc.filename is not None and exc.errno in _PATH_ERRNOS:  # a path given by the user that cannot be used
            print(f"rigsim: error: {safe_text(str(exc.filename), 300)}: {exc.strerror}", file=sys.stderr)
            return 2
        raise


def _leaf_parser(parser: argparse.ArgumentParser, args) -> argparse.ArgumentParser:
    """The subcommand's own parser (``rigsim calibrate sun-sensor`` → that of ``sun-sensor``)."""
    p = parser
    while True:
        subs = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        name = getattr(args, subs[0].dest, None) if subs else None
        if name is None or name not in subs[0].choices:
            return p
        p = subs[0].choices[name]


def _checked_files(parser: argparse.ArgumentParser, args) -> list:
    """Before the command runs: its inputs (every file or folder named by an option or positional that is not one
    of its declared outputs) as (label, path), after :func:`rigsim.files.outputs.check_plan` has refused any output
    that would destroy one of them or another output, or that cannot be written."""
    from pathlib import Path

    from rigsim.files.outputs import check_plan, declared_outputs

    leaf = _leaf_parser(parser, args)
    labels = {a.dest: (a.option_strings[0] if a.option_strings else (a.metavar if isinstance(a.metavar, str) else
                                                                        a.dest.upper()))
              for a in leaf._actions if a.dest != "help"}
    outputs, out_dests = declared_outputs(args, labels)
    inputs = []
    for dest, label in labels.items():
        if dest in out_dests:
            continue
        v = getattr(args, dest, None)
        for x in (v if isinstance(v, (list, tuple)) else [v]):
            if isinstance(x, str) and x and os.path.lexists(x):
                inputs.append((label, Path(x)))
    check_plan(outputs, inputs)
    return inputs


_PATH_ERRNOS = {errno.ENAMETOOLONG, errno.ENOENT, errno.ENOTDIR, errno.EISDIR, errno.ELOOP, errno.EACCES, errno.EPERM,
                errno.EROFS, errno.EEXIST, errno.ENXIO}


HEARTBEAT_ENV = "RIGSIM_HEARTBEAT_S"
"""Seconds between the heartbeat lines of a command whose stderr is not a terminal (default 30; 0: none)."""


class _Heartbeat:
    """On a terminal, a command that runs longer than ``delay`` seconds without a progress bar of its own shows
    the seconds it has been working on stderr (one line, rewritten in place, erased at the end). When stderr is not
    a terminal (a log file, a batch job, a pipe), a long command writes a note line every ``log_interval`` seconds
    (``RIGSIM_HEARTBEAT_S``, default 30): a hung run and a slow one no longer look the same in a log."""

    def __init__(self, label: str, delay: float = 2.0, interval: float = 0.5, stream=None,
                 log_interval: float | None = None):
        import threading

        self.label, self.delay, self.interval = f"rigsim {label}".strip(), delay, interval
        self.stream = stream if stream is not None else sys.stderr
        self.log_interval = _heartbeat_seconds() if log_interval is None else float(log_interval)
        self.stop, self.shown, self.thread = threading.Event(), False, None

    def _log(self) -> None:
        """Off a terminal: one line every ``log_interval`` seconds, while the command runs."""
        import time

        k = 0
        while not self.stop.wait(self.log_interval):
            k += 1
            m, s = divmod(int(round(k * self.log_interval)), 60)
            try:
                self.stream.write(f"rigsim: note: {self.label} still working ({f'{m} min ' if m else ''}{s} s; "
                                  f"{time.strftime('%H:%M:%S')})\n")
                self.stream.flush()
            except (OSError, ValueError):  # the log went away: the command goes on
                return

    def _run(self) -> None:
        import time

        t0 = time.monotonic()
        if self.stop.wait(self.delay):
            return
        while not self.stop.is_set():
            try:
                from tqdm import tqdm

                busy = bool(getattr(tqdm, "_instances", None))
            except ImportError:
                busy = False
            if not busy:
                self.stream.write(f"\r\x1b[K{self.label}: working, {time.monotonic() - t0:.0f} s")
                self.stream.flush()
                self.shown = True
            self.stop.wait(self.interval)

    def __enter__(self):
        import threading

        try:
            tty = self.stream.isatty()
        except (AttributeError, ValueError):
            tty = False
        if tty:
            self.thread = threading.Thread(target=self._run, name="rigsim-heartbeat", daemon=True)
            self.thread.start()
        elif self.log_interval > 0:
            self.thread = threading.Thread(target=self._log, name="rigsim-heartbeat", daemon=True)
            self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        if self.thread is not None:
            self.stop.set()
            self.thread.join()
            if self.shown:
                self.stream.write("\r\x1b[K")
                self.stream.flush()


def _heartbeat_seconds() -> float:
    text = os.environ.get(HEARTBEAT_ENV, "").strip()
    if not text:
        return 30.0
    try:
        from rigsim.files.numbers import parse_float

        v = parse_float(text, special=False)
    except ValueError:
        return 30.0
    return v if 0 <= v <= 86400 else 30.0


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that Python's exit-time flush does not raise again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    sys.exit(main())
