"""rigsim's attack suite: every option and positional of every subcommand given hostile values, through the
command's body (not only its parser), and scenarios on valid inputs where one thing is hostile: an output that
names an input or the other output, a device node, FIFO, socket, folder or /proc link where a file is written,
an input given twice, a number in other digits, a reading that cannot be one. Each case runs ``rigsim.cli.main``
in a forked process, in its own folder, with a time limit and a 6 GB data limit (``RIGSIM_MEMORY_GB=4``), and is
classified:

  ok        exit 0
  clear     exit 2 (or 1 for a full disk / interrupted run, 3 for a poor fit) with exactly one line on stderr
  traceback an exception escaped main(), or a Python traceback was printed
  crash     the process died of a signal (a segmentation fault, an abort)
  unclear   another exit status, or several lines of error
  hang      still running after the time limit (a valid value that starts a long run is counted too and
            listed, so that it can be checked by hand)

and, across cases:

  outside        a file appeared outside the case's folder, or the precious file outside it changed
  inputs_lost    an input file of a scenario (or of the shared inputs) changed or vanished
  nodes_replaced a device node, FIFO, socket, folder or link where an output was named is no longer what it was
  partial        a refused command left some of its outputs behind (outputs are all written or none)
  accepted       a scenario that must be refused (a duplicate input, a number in other digits, two outputs on
                 one file, an impossible reading) ran to completion: a silent wrong answer

Usage: python tests/attack/attack.py [--limit S] [--jobs N] [--only SUBSTRING] [--report FILE.json]
                                     [--classes generic,scenario]
Prints one line per non-clean case and the counts. docs/reliability.md explains the figures.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

NASTY = ["", "nan", "-1", "1e308", "../../escape", "\x1b[31mred", "x" * 300, "@dir", "@garbage", "@empty", "@fifo",
         "@link", "@json-list", "@csv-wrong", "@png-8bit"]
HOSTILE_FILES = ["@png-bomb", "@tiff-bomb", "@fits-bomb", "@png-16k", "@tiff-pages", "@fits-1e300", "@deep-json",
                 "@long-int-json", "@deep-yaml", "@matrix-bomb", "@csv-arabic", "@csv-underscore", "@deep-dataset"]
"""Files whose header lies or claims too much, or that nest too deep: given to every option or positional that
takes a file (untyped, no fixed choices)."""
DATA_LIMIT = 6 << 30  # each case's RLIMIT_DATA: a decoding bomb fails in the case, never takes the machine down
CHILD_ENV = {"RIGSIM_MEMORY_GB": "4", "RIGSIM_HEARTBEAT_S": "0"}
CHEAP = {  # flags that keep a valid run of a heavy command short (the option under attack overrides its own)
    ("run", "cube-mirror"): ["--analytic", "--no-budget", "--quiet"],
    ("run", "boresight"): ["--no-orbit", "--runs", "10", "--quiet"],
    ("run", "star-calibration"): ["--no-study", "--renderer", "analytic", "--trials", "2", "--quiet"],
    ("dataset", "generate"): ["--frames", "1", "--spp", "1", "--workers", "1"],
    ("render", "sun-sensor"): ["--spp", "1"],
    ("render", "aiming-camera"): ["--spp", "1"],
    ("render", "autocollimator"): ["--spp", "1"],
    ("render", "boresight-roi"): ["--spp", "1"],
    ("render", "star-field"): ["--renderer", "analytic"],
    ("render", "target"): ["--spread", "1", "--spp", "1"],
}
RIG_DESTS = {"rig"}
VALID = {  # a valid value for a required option, so that the other options' cases reach the command's body
    ("render", "target", "target"): "chessboard:8x6:10",
    ("boresight", "centroid", "camera"): "forward",
    ("rig", "import-camera", "out"): "new.toml",  # outputs of the kind each command writes: past its suffix check
    ("centroid", "out"): "o.csv",
    ("boresight", "centroid", "out"): "o.csv",
    ("calibrate", "sun-sensor", "out"): "o.json",
}
OUTPUT_DESTS = {"out", "json_out", "xml", "preview", "export_frames", "json", "opencv", "errors_out", "screenshot", "html",
                "export"}  # where the user names the destination: a shared hostile file given there gets its own copy


def leaves():
    from rigsim.cli import build_parser

    out = []

    def walk(p, path):
        subs = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        if subs:
            for a in subs:
                for name, sp in a.choices.items():
                    walk(sp, (*path, name))
            return
        out.append((path, p))

    walk(build_parser(), ())
    return out


def inputs(root: Path) -> dict[str, str]:
    d = root / "inputs"
    d.mkdir()
    (d / "folder").mkdir()
    (d / "garbage.png").write_bytes(os.urandom(4096))
    (d / "empty.csv").write_bytes(b"")
    os.mkfifo(d / "fifo.csv")
    (root / "precious.txt").write_text("must survive\n")
    (d / "link.csv").symlink_to(root / "precious.txt")
    (d / "list.json").write_text("[1, 2, 3]\n")
    (d / "wrong.csv").write_text("a,b,c\n1,2,3\nnan,inf,-inf\n")
    import cv2
    import numpy as np

    cv2.imwrite(str(d / "eight.png"), np.full((64, 64), 200, np.uint8))
    import hostile_inputs as H

    (d / "deep_ds").mkdir()
    H.deep_json(d / "deep_ds" / "manifest.json")
    H.deep_json(d / "deep_ds" / "plan.json")
    (d / "arabic.csv").write_text("frame,x_deg,y_deg,u_px,v_px,face,time_s,qw,qx,qy,qz,u,v\n"
                                  "f0.png,١٢,1,2,3,+Z,0,1,0,0,0,1,2\n", encoding="utf-8")
    (d / "underscore.csv").write_text("frame,x_deg,y_deg,u_px,v_px,face,time_s,qw,qx,qy,qz,u,v\n"
                                      "f0.png,1_0,1,2,3,+Z,0,1,0,0,0,1,2\n")
    return {"@dir": str(d / "folder"), "@garbage": str(d / "garbage.png"), "@empty": str(d / "empty.csv"),
            "@fifo": str(d / "fifo.csv"), "@link": str(d / "link.csv"), "@json-list": str(d / "list.json"),
            "@csv-wrong": str(d / "wrong.csv"), "@png-8bit": str(d / "eight.png"),
            "@png-bomb": str(H.png_header_bomb(d / "bomb.png")), "@tiff-bomb": str(H.tiff_header_bomb(d / "bomb.tif")),
            "@fits-bomb": str(H.fits_header_bomb(d / "bomb.fits")), "@png-16k": str(H.png_zero_bomb(d / "z16k.png")),
            "@tiff-pages": str(H.tiff_pages(d / "pages.tif")), "@fits-1e300": str(H.fits_huge_values(d / "huge.fits")),
            "@deep-json": str(H.deep_json(d / "deep.json")), "@long-int-json": str(H.long_integer_json(d / "long.json")),
            "@deep-yaml": str(H.deep_yaml(d / "deep.yml")), "@matrix-bomb": str(H.opencv_matrix_bomb(d / "matrix.yml")),
            "@csv-arabic": str(d / "arabic.csv"), "@csv-underscore": str(d / "underscore.csv"),
            "@deep-dataset": str(d / "deep_ds")}


def cases(files: dict[str, str]):
    for path, p in leaves():
        pos = [a for a in p._actions if not a.option_strings]
        opts = [a for a in p._actions if a.option_strings and a.dest != "help"]
        required = [a for a in opts if a.required]

        def base(skip=None):
            argv = list(path)
            for a in pos:
                if a is skip:
                    continue
                v = "sun_sensor_2axis_diaphragm" if a.dest in RIG_DESTS else files["@garbage"]
                argv += [v] if a.nargs in (None, "?") else [v]
            for a in required:
                if a is skip:
                    continue
                v = VALID.get((*path, a.dest)) or ("out" if a.dest in ("out", "xml") else files["@garbage"])
                argv += [a.option_strings[0], v]
            return argv

        cheap = CHEAP.get(tuple(path), [])
        for a in pos + opts:
            takes_value = a.nargs != 0 and not isinstance(a, (argparse._StoreTrueAction, argparse._StoreFalseAction,
                                                               argparse._VersionAction, argparse._CountAction))
            if not takes_value:
                continue
            file_slot = a.type is None and not a.choices
            for v in NASTY + (HOSTILE_FILES if file_slot else []):
                val = files.get(v, v)
                spec = None
                if a.dest in OUTPUT_DESTS and v in files:  # the case's own copy: writing it is what the user asked
                    val = "target" + Path(files[v]).suffix
                    spec = {"target": (files[v], val)}
                argv = base(skip=a)
                if a.option_strings:
                    argv += [f"{a.option_strings[0]}={val}"]
                else:
                    argv = argv[:len(path)] + [val] + argv[len(path):]
                argv += [x for i, x in enumerate(cheap) if not (a.option_strings and x == a.option_strings[0])
                         and not (i > 0 and a.option_strings and cheap[i - 1] == a.option_strings[0])]
                yield " ".join(path), a.dest, v, argv, spec


def _child(argv, cwd: Path, out: Path, err: Path, stdin: Path | None):
    """In the forked child: a fresh command in its own folder, its data bounded."""
    import resource

    try:
        os.setsid()
        os.chdir(cwd)
        fo, fe = os.open(out, os.O_WRONLY | os.O_CREAT, 0o644), os.open(err, os.O_WRONLY | os.O_CREAT, 0o644)
        os.dup2(fo, 1)
        os.dup2(fe, 2)
        if stdin is not None:
            os.dup2(os.open(stdin, os.O_RDONLY), 0)
            sys.stdin = open(0, closefd=False, newline="")
        os.environ.update({"TMPDIR": str(cwd), "HOME": str(cwd), "RIGSIM_CACHE_DIR": str(cwd.parent / ".cache"),
                           "PYTHONWARNINGS": "ignore", "TQDM_DISABLE": "1", **CHILD_ENV})
        soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
        resource.setrlimit(resource.RLIMIT_DATA, (DATA_LIMIT, hard if hard != resource.RLIM_INFINITY and hard < DATA_LIMIT
                                                  else hard))
        tempfile.tempdir = None
        from rigsim.cli import main

        rc = main(argv)
        sys.stdout.flush()
        os._exit(int(rc) & 0xFF)
    except SystemExit as e:
        os._exit(e.code if isinstance(e.code, int) else 2)
    except BaseException:
        traceback.print_exc()
        sys.stderr.flush()
        os._exit(99)


def run_case(argv, cwd: Path, limit: float, spec: dict | None = None):
    """Run one case; returns (outcome, exit status, stderr, findings). ``spec`` (scenario cases): the files to lay
    out in the case's folder first and what to check after."""
    cwd.mkdir(parents=True)
    pre = setup_scenario(cwd, spec) if spec else None
    out, err = cwd / ".stdout", cwd / ".stderr"
    pid = os.fork()
    if pid == 0:
        _child(argv, cwd, out, err, cwd / spec["stdin"] if spec and spec.get("stdin") else None)
    t0 = time.time()
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.time() - t0 > limit:
            os.killpg(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return "hang", None, err.read_text(errors="replace"), check_scenario(cwd, spec, pre, None)
        time.sleep(0.05)
    rc = os.waitstatus_to_exitcode(status)
    text = err.read_text(errors="replace")
    found = check_scenario(cwd, spec, pre, rc) if spec else {}
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith(("rigsim: note:", "rigsim: warning:"))
             and "WARN" not in ln]
    if rc < 0:
        return "crash", rc, text + f"\n(killed by signal {-rc})", found
    if rc == 99 or "Traceback (most recent call last)" in text:
        return "traceback", rc, text, found
    if rc == 0:
        return "ok", rc, text, found
    if rc in (1, 2, 3, 130) and len(lines) == 1 and lines[0].startswith("rigsim"):
        return "clear", rc, text, found
    return "unclear", rc, text, found


def snapshot(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.iterdir()}


def _digest(p: Path):
    try:
        st = os.lstat(p)
    except FileNotFoundError:
        return None
    if stat.S_ISREG(st.st_mode):
        return hashlib.sha256(p.read_bytes()).hexdigest()
    return ("node", stat.S_IFMT(st.st_mode), st.st_ino)


# ------------------------------------------------------------------------------ scenarios on valid inputs

RIG = "sun_sensor_2axis_diaphragm"
RIG3 = "sun_sensor_3axis_autocollimator"


def build_fixtures(d: Path) -> None:
    """Valid inputs for every file command (about a minute): run once, in a subprocess (the renderer is never
    loaded in the process the cases fork from)."""
    import valid_inputs as V

    from rigsim.cli import main as rigsim

    d.mkdir(parents=True, exist_ok=True)
    V.sweep_tables(d)
    V.nulls(d)
    steps = [
        ["triad", "--nulls", str(d / "nulls.csv"), "--out", str(d / "cube.json")],
        ["calibrate", "sun-sensor", "--angles", str(d / "angles.csv"), "--centroids", str(d / "centroids.csv"), "--out",
         str(d / "sun.json")],
        ["render", "aiming-camera", "--spp", "1", "--out", str(d / "r"), "--name", "aim"],
        ["render", "autocollimator", "--spp", "16", "--out", str(d / "r"), "--name", "ac"],
        ["render", "boresight-roi", "--spp", "1", "--detector", "M1", "--out", str(d / "r"), "--name", "m1"],
        ["render", "boresight-roi", "--spp", "1", "--detector", "M2", "--out", str(d / "r"), "--name", "m2"],
        ["boresight", "centroid", "--camera", "forward", "--m1", str(d / "r" / "m1.png"), "--m2", str(d / "r" / "m2.png"),
         "--out", str(d / "spots.csv")],
        ["run", "star-calibration", "--no-study", "--export-frames", str(d / "star"), "--frame-format", "png", "--out",
         str(d / "r" / "star_report"), "--quiet"],
        ["dataset", "generate", RIG, "--out", str(d / "ds"), "--frames", "2", "--spp", "1", "--workers", "1", "--quiet"],
    ]
    for argv in steps:
        if rigsim(argv) != 0:
            raise SystemExit(f"fixture step failed: {' '.join(argv)}")
    for a, b in (("aim_hole.png", "hole.png"), ("aim_spot.png", "spot.png"), ("ac.png", "ac.png"), ("m1.png", "m1.png"),
                 ("m2.png", "m2.png")):
        shutil.copy(d / "r" / a, d / b)
    (d / "pred.csv").write_text("frame,u,v\n0,500.2,500.1\n1,510.3,505.2\n")
    from rigsim.files.opencv import write_opencv_camera

    write_opencv_camera(d / "cam.yml", 272.7, 272.8, 512.0, 512.0, [-0.02, 0.001, 0, 0, 0], 1024, 1024)
    shutil.rmtree(d / "r")


def _star(fix: Path) -> list[str]:
    return sorted(p.name for p in (fix / "star").glob("star_*.png"))


def _cell(text: str, row: int, col: int, value: str) -> str:
    lines = text.splitlines()
    f = lines[row].split(",")
    f[col] = value
    lines[row] = ",".join(f)
    return "\n".join(lines) + "\n"


def scenarios(fix: Path):
    """(command, slot, value, argv, spec) of every scenario case. A spec lists the fixture files to copy into the
    case's folder ("inputs": checked after the case), files to write ("write"), links and nodes to make, the outputs
    a refusal must not leave ("outputs"), and whether the case must be refused ("refuse")."""
    star = _star(fix)
    star_in = [f"star/{n}" for n in star]
    S = {  # command: (argv before the outputs, its input files, its outputs {option: (value, folder?)})
        "calibrate sun-sensor": (["calibrate", "sun-sensor", "--angles", "angles.csv", "--centroids", "centroids.csv"],
                                 ["angles.csv", "centroids.csv"], {"--out": "o.json", "--opencv": "o.yml"}),
        "triad": (["triad", "--nulls", "nulls.csv"], ["nulls.csv"], {"--out": "o.json"}),
        "compose": (["compose", "--cube-from-rot", "cube.json", "--sun-from-rot", "sun.json"], ["cube.json", "sun.json"],
                    {"--out": "o.json"}),
        "concentricity": (["concentricity", "hole.png", "spot.png"], ["hole.png", "spot.png"], {"--json": "o.json"}),
        "autocollimator read": (["autocollimator", "read", "ac.png"], ["ac.png"], {"--json": "o.json"}),
        "centroid": (["centroid", "hole.png", "spot.png", "--rig", RIG, "--camera", "aiming-camera"],
                     ["hole.png", "spot.png"], {"--out": "o.csv"}),
        "boresight centroid": (["boresight", "centroid", "--camera", "forward", "--m1", "m1.png", "--m2", "m2.png"],
                               ["m1.png", "m2.png"], {"--out": "o.csv"}),
        "boresight solve": (["boresight", "solve", "--reference", "spots.csv", "--measured", "spots.csv"], ["spots.csv"],
                            {"--out": "o.csv", "--json-out": "o.json"}),
        "star calibrate": (["star", "calibrate", *star_in, "--attitudes", "star/attitudes.csv"],
                           [*star_in, "star/attitudes.csv"], {"--out": "cal", "--opencv": "o.yml"}),
        "dataset score": (["dataset", "score", "ds", "pred.csv"], ["pred.csv", "ds/truth.csv", "ds/manifest.json"],
                          {"--json-out": "o.json", "--errors-out": "o.csv"}),
        "rig import-camera": (["rig", "import-camera", "cam.yml"], ["cam.yml"], {"--out": "o.toml"}),
    }
    folders = {("star calibrate", "--out")}
    root = os.geteuid() == 0
    for cmd, (head, ins, outs) in S.items():
        copy = sorted({*ins, *(["ds"] if cmd == "dataset score" else [])})
        for opt, own in outs.items():
            others = {o: v for o, v in outs.items() if o != opt}
            suf = Path(own).suffix
            # an input of the output's own kind when there is one: a name the command would otherwise accept
            same = next((i for i in ins if Path(i).suffix == suf), ins[0])
            targets = [(f"input {i}", i, {}) for i in dict.fromkeys(ins[:3] + ins[-1:]) if (cmd, opt) not in folders]
            if (cmd, opt) not in folders:
                targets += [("input, another spelling", f"./sub/../{same}", {"dirs": ["sub"]}),
                            ("input, a hard link", f"hard{Path(same).suffix}", {"hardlinks": {f"hard{Path(same).suffix}": same}}),
                            ("input, through a link to its folder", f"lnk/{Path(same).name}",
                             {"symlinks": {"lnk": str(Path(same).parent)}})]
                targets += [(f"the other output {o}", None, {"both": o}) for o in others]
                kinds = (["device"] if root else []) + ["fifo", "socket", "folder", "proc-link"]
                targets += [(f"a {k}", f"node{suf}", {"node": k, "node_name": f"node{suf}"}) for k in kinds]
            else:
                targets += [("a file", ins[-1], {})] + ([("a device", "node", {"node": "device", "node_name": "node"})]
                                                         if root else [])
            for what, value, extra in targets:
                o_val = dict(others)
                if extra.get("both"):  # both outputs on one name that each would accept on its own
                    value = o_val[extra.pop("both")] = f"same{suf or '.out'}"
                rest = [x for o, v in o_val.items() for x in (o, v)]
                argv = [*head, opt, value, *rest]
                spec = {"copy": copy, "inputs": ins, "outputs": [own, *others.values(), value], "refuse": True, **extra}
                yield cmd, opt, f"output = {what}", argv, spec
        if len(outs) > 1:  # all or nothing: the second output cannot be written, the first must not be either
            (o1, v1), (o2, v2) = list(outs.items())[:2]
            bad = ("file/x" + Path(v2).suffix) if (cmd, o2) not in folders else "file/x"
            spec = {"copy": copy, "inputs": ins, "outputs": [v1, v2], "refuse": True, "write": {"file": ""}}
            yield cmd, o2, "second output unwritable", [*head, o1, v1, o2, bad], spec
    # a derived output onto an input: star calibrate --out . writes stars.csv and calibration.json there
    spec = {"copy": [*star_in, "star/attitudes.csv"], "inputs": [*star_in, "stars.csv"], "outputs": ["calibration.json"],
            "refuse": True, "rename": {"star/attitudes.csv": "stars.csv"}}
    yield "star calibrate", "--out", "derived output = an input", ["star", "calibrate", *star_in, "--attitudes",
                                                                    "stars.csv", "--out", "."], spec
    # duplicate inputs
    dup = [
        ("star calibrate", "frame twice", ["star", "calibrate", *star_in, star_in[0], "--attitudes", "star/attitudes.csv",
                                            "--out", "cal"], {}),
        ("star calibrate", "two frames of one name", ["star", "calibrate", *star_in, f"sub/{star[1]}", "--attitudes",
                                                       "star/attitudes.csv", "--out", "cal"], {"copies": {f"sub/{star[1]}": star_in[1]}}),
        ("centroid", "frame twice", ["centroid", "hole.png", "./hole.png", "--out", "o.csv"], {}),
        ("centroid", "two frames of one name", ["centroid", "hole.png", "sub/hole.png", "--out", "o.csv"],
         {"copies": {"sub/hole.png": "spot.png"}}),
        ("concentricity", "one frame as both", ["concentricity", "hole.png", "hole.png"], {}),
        ("boresight solve", "table twice", ["boresight", "solve", "--reference", "spots.csv", "--measured", "spots.csv",
                                            "spots.csv"], {}),
        ("calibrate sun-sensor", "a centroid row twice", ["calibrate", "sun-sensor", "--angles", "angles.csv", "--centroids",
                                                          "centroids.csv", "--out", "o.json"], {"dup_row": "centroids.csv"}),
    ]
    base = ["angles.csv", "centroids.csv", "hole.png", "spot.png", "spots.csv", *star_in, "star/attitudes.csv"]
    for cmd, what, argv, extra in dup:
        yield cmd, "inputs", f"duplicate: {what}", argv, {"copy": base, "inputs": [], "outputs": ["o.csv", "o.json", "cal"],
                                                          "refuse": True, **extra}
    # numbers in other digits, and readings that cannot be readings
    ang = (fix / "angles.csv").read_text()
    cen = (fix / "centroids.csv").read_text()
    att = (fix / "star" / "attitudes.csv").read_text()
    spots = (fix / "spots.csv").read_text()
    strict = [
        ("calibrate sun-sensor", "angles ١٢", ["calibrate", "sun-sensor", "--angles", "a.csv", "--centroids", "centroids.csv",
                                               "--out", "o.json"], {"a.csv": _cell(ang, 3, 1, "١٢")}),
        ("calibrate sun-sensor", "angles 1_0", ["calibrate", "sun-sensor", "--angles", "a.csv", "--centroids",
                                                "centroids.csv", "--out", "o.json"], {"a.csv": _cell(ang, 3, 1, "1_0")}),
        ("calibrate sun-sensor", "centroids ٥٠٠", ["calibrate", "sun-sensor", "--angles", "angles.csv", "--centroids", "c.csv",
                                                   "--out", "o.json"], {"c.csv": _cell(cen, 3, 1, "٥٠٠")}),
        ("triad", "nulls ١٨١", ["triad", "--nulls", "n.csv", "--out", "o.json"],
         {"n.csv": "face,x_deg,y_deg\n+Z,١٨١.398,0.528\n+Y,91.386,-0.048\n"}),
        ("triad", "θ ١٨١", ["triad", "١٨١.398", "0.528", "91.386", "-0.048"], {}),
        ("triad", "θ 1_81", ["triad", "1_81.398", "0.528", "91.386", "-0.048"], {}),
        ("triad", "--sigma-arcsec 1_0", ["triad", "--sigma-arcsec", "1_0", "181.398", "0.528", "91.386", "-0.048"], {}),
        ("star calibrate", "time ١٠", ["star", "calibrate", *star_in, "--attitudes", "t.csv", "--out", "cal"],
         {"t.csv": _cell(att, 2, 1, "١٠")}),
        ("boresight solve", "spot ٢٥٥٩", ["boresight", "solve", "--reference", "spots.csv", "--measured", "m.csv"],
         {"m.csv": _cell(spots, 1, 4, "٢٥٥٩.5")}),
        ("dataset score", "prediction ٥٠٠", ["dataset", "score", "ds", "p.csv"], {"p.csv": "frame,u,v\n0,٥٠٠,500\n"}),
        ("concentricity", "--reading ١٨١", ["concentricity", "hole.png", "spot.png", "--reading", "X=١٨١.4,Y=0.55"], {}),
        ("render sun-sensor", "--pose ١٠", ["render", "sun-sensor", "--spp", "1", "--pose", "X=١٠,Y=0", "--out", "f"], {}),
        ("concentricity", "--reading X twice", ["concentricity", "hole.png", "spot.png", "--reading", "X=1,X=2"], {}),
        ("concentricity", "--reading X alone", ["concentricity", "hole.png", "spot.png", "--reading", "X=181.4"], {}),
        ("concentricity", "--axis-order ZZ", ["concentricity", "hole.png", "spot.png", "--axis-order", "ZZ"], {}),
        ("triad", "null 1e308", ["triad", "--nulls", "n.csv"], {"n.csv": "face,x_deg,y_deg\n+Z,1e308,0.528\n+Y,91.386,-0.048\n"}),
        ("triad", "two equal nulls", ["triad", "--nulls", "n.csv"],
         {"n.csv": "face,x_deg,y_deg\n+Z,181.398,0.528\n+Y,181.398,0.528\n"}),
        ("triad", "θ of two equal nulls", ["triad", "181.398", "0.528", "181.398", "0.528"], {}),
        ("calibrate sun-sensor", "centroid 1e300", ["calibrate", "sun-sensor", "--angles", "angles.csv", "--centroids",
                                                    "c.csv", "--out", "o.json"], {"c.csv": _cell(cen, 3, 1, "1e300")}),
        ("boresight solve", "spot 1e308", ["boresight", "solve", "--reference", "spots.csv", "--measured", "m.csv"],
         {"m.csv": _cell(spots, 1, 4, "1e308")}),
        ("star calibrate", "log scalar last", ["star", "calibrate", *star_in, "--attitudes", "q.csv", "--out", "cal"],
         {"q.csv": "\n".join([att.splitlines()[0]] + [",".join([*r.split(",")[:2], *r.split(",")[3:6], r.split(",")[2]])
                                                      for r in att.splitlines()[1:]]) + "\n"}),
        ("star calibrate", "log conjugated", ["star", "calibrate", *star_in, "--attitudes", "q.csv", "--out", "cal"],
         {"q.csv": "\n".join([att.splitlines()[0]] + [",".join([*r.split(",")[:3], *(repr(-float(x)) for x in r.split(",")[3:6])])
                                                      for r in att.splitlines()[1:]]) + "\n"}),
    ]
    for cmd, what, argv, write in strict:
        yield cmd, "value", f"strict: {what}", argv, {"copy": base + ["ds"], "inputs": [], "outputs": ["o.json", "o.csv", "cal"],
                                                      "refuse": True, "write": write}
    # a hostile file in a command whose other inputs are valid: it reaches the reader
    hostile = {"png-bomb": "bomb.png", "tiff-bomb": "bomb.tif", "fits-bomb": "bomb.fits", "png-16k": "z16k.png",
               "tiff-pages": "pages.tif", "fits-1e300": "huge.fits"}
    for key, name in hostile.items():
        f = f"h/{name}"
        for cmd, argv in (("centroid", ["centroid", f, "--out", "o.csv"]),
                          ("centroid", ["centroid", f, "--rig", RIG, "--camera", "aiming-camera", "--out", "o.csv"]),
                          ("concentricity", ["concentricity", f, "spot.png", "--json", "o.json"]),
                          ("autocollimator read", ["autocollimator", "read", f, "--json", "o.json"]),
                          ("boresight centroid", ["boresight", "centroid", "--camera", "forward", "--m1", f, "--m2", "m2.png",
                                                  "--out", "o.csv"]),
                          ("star calibrate", ["star", "calibrate", *star_in[:-1], f, "--out", "cal"])):
            yield cmd, "frame", f"hostile file: {key}", argv, {"copy": ["spot.png", "m2.png", *star_in], "inputs": [],
                                                               "outputs": ["o.csv", "o.json", "cal"], "refuse": True,
                                                               "hostile": {f: key}}
    for key in ("deep-json", "long-int-json", "deep-yaml", "deep-xml", "matrix-bomb"):
        f = {"deep-json": "h/c.json", "long-int-json": "h/c.json", "deep-yaml": "h/c.yml", "deep-xml": "h/c.xml",
             "matrix-bomb": "h/c.yml"}[key]
        yield "rig import-camera", "camera", f"hostile file: {key}", ["rig", "import-camera", f, "--out", "new.toml"], \
            {"copy": [], "inputs": [], "outputs": ["new.toml"], "refuse": True, "hostile": {f: key}}
    for key in ("deep-json", "long-int-json"):
        yield "compose", "--cube-from-rot", f"hostile file: {key}", ["compose", "--cube-from-rot", "h/c.json",
                                                                      "--sun-from-rot", "sun.json", "--out", "o.json"], \
            {"copy": ["sun.json"], "inputs": [], "outputs": ["o.json"], "refuse": True, "hostile": {"h/c.json": key}}
        for part in ("manifest.json", "plan.json"):
            for cmd, argv in (("dataset verify", ["dataset", "verify", "ds"]), ("dataset info", ["dataset", "info", "ds"]),
                              ("dataset score", ["dataset", "score", "ds", "pred.csv"])):
                yield cmd, "DIR", f"hostile file: {key} {part}", argv, {  # info and score do not read the plan
                    "copy": ["ds", "pred.csv"], "inputs": [], "outputs": [],
                    "refuse": part == "manifest.json" or cmd == "dataset verify", "hostile": {f"ds/{part}": key}}
    # a CRLF stream: solved, and no carriage return in the result
    rows = "camera,u_m1_px,v_m1_px,u_m2_px,v_m2_px,sample\r\n" + "".join(
        f"forward,{ln.split(',')[4]},{ln.split(',')[5]},{ln.split(',')[6]},{ln.split(',')[7]},{k}\r\n"
        for k, ln in enumerate(spots.splitlines()[1:]))
    yield "boresight solve", "--stream", "CRLF stdin", ["boresight", "solve", "--reference", "spots.csv", "--stream"], \
        {"copy": ["spots.csv"], "inputs": ["spots.csv"], "outputs": [], "refuse": False, "write": {"in.txt": rows},
         "stdin": "in.txt", "no_cr": True}


def setup_scenario(cwd: Path, spec: dict) -> dict:
    if "target" in spec:  # a generic case's output option pointed at its own copy of a shared hostile input
        src, name = spec["target"]
        p, st = cwd / name, os.lstat(src)
        if stat.S_ISFIFO(st.st_mode):
            os.mkfifo(p)
        elif stat.S_ISDIR(st.st_mode):
            p.mkdir()
        elif stat.S_ISLNK(st.st_mode):
            p.symlink_to(os.readlink(src))
        else:
            shutil.copy(src, p)
        spec.update(node_name=name, node=("kept" if stat.S_ISREG(st.st_mode) or stat.S_ISLNK(st.st_mode) else "fifo"
                                           if stat.S_ISFIFO(st.st_mode) else "folder"))
        return {"digests": {name: _digest(p)}, "files": {str(q.relative_to(cwd)) for q in cwd.rglob("*")}}
    fix = Path(spec["fixtures"])
    checked = set(spec.get("inputs", [])) | set(spec.get("hardlinks", {}).values()) | set(spec.get("rename", {}))
    for name in spec.get("copy", []):
        src, dst = fix / name, cwd / name
        dst.parent.mkdir(parents=True, exist_ok=True)
        if src.is_dir():
            shutil.copytree(src, dst)
        elif name in checked or any(c.startswith(name + "/") for c in checked):
            shutil.copy(src, dst)  # a watched input: its own copy
        else:
            os.link(src, dst)  # read only by the case: a second name is enough
    for a, b in spec.get("rename", {}).items():
        (cwd / a).rename(cwd / b)
    for d in spec.get("dirs", []):
        (cwd / d).mkdir(parents=True, exist_ok=True)
    for name, text in spec.get("write", {}).items():
        (cwd / name).write_text(text, encoding="utf-8")
    if spec.get("hostile"):
        import hostile_inputs as H

        makers = {"png-bomb": H.png_header_bomb, "tiff-bomb": H.tiff_header_bomb, "fits-bomb": H.fits_header_bomb,
                  "png-16k": H.png_zero_bomb, "tiff-pages": H.tiff_pages, "fits-1e300": H.fits_huge_values,
                  "deep-json": H.deep_json, "long-int-json": H.long_integer_json, "deep-yaml": H.deep_yaml,
                  "deep-xml": H.deep_xml, "matrix-bomb": H.opencv_matrix_bomb}
        for name, key in spec["hostile"].items():
            (cwd / name).parent.mkdir(parents=True, exist_ok=True)
            if (cwd / name).exists():
                (cwd / name).unlink()
            makers[key](cwd / name)
    for name, src in spec.get("copies", {}).items():
        (cwd / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(cwd / src, cwd / name)
    for name, src in spec.get("hardlinks", {}).items():
        os.link(cwd / src, cwd / name)
    for name, src in spec.get("symlinks", {}).items():
        (cwd / name).symlink_to((cwd / src).resolve())
    if spec.get("dup_row"):
        p = cwd / spec["dup_row"]
        lines = p.read_text().splitlines()
        p.write_text("\n".join([*lines, lines[3]]) + "\n")
    node = spec.get("node")
    if node:
        p = cwd / spec.get("node_name", "node")
        if node == "device":
            os.mknod(p, stat.S_IFCHR | 0o666, os.makedev(1, 3))  # a /dev/null of the case's own
        elif node == "fifo":
            os.mkfifo(p)
        elif node == "socket":
            s = socket.socket(socket.AF_UNIX)
            s.bind(str(p))
            s.close()
        elif node == "folder":
            p.mkdir()
        else:
            p.symlink_to("/proc/self/fd/1")
    watched = [*spec.get("inputs", []), *spec.get("hardlinks", {}), *([spec.get("node_name", "node")] if node else [])]
    return {"digests": {n: _digest(cwd / n) for n in watched},
            "files": {str(p.relative_to(cwd)) for p in cwd.rglob("*")}}


def check_scenario(cwd: Path, spec: dict | None, pre: dict | None, rc) -> dict:
    if not spec:
        return {}
    found = {}
    node = spec.get("node_name")
    lost = [n for n, d in pre["digests"].items() if n != node and _digest(cwd / n) != d]
    if lost:
        found["inputs_lost"] = lost
    if node and spec.get("node") != "kept" and _digest(cwd / node) != pre["digests"][node]:
        found["nodes_replaced"] = [spec.get("node")]
    if rc not in (0, None):
        new = {str(p.relative_to(cwd)) for p in cwd.rglob("*")} - pre["files"] - {".stdout", ".stderr"}
        left = sorted(n for n in new if n in spec.get("outputs", []) or Path(n).parts[0] in spec.get("outputs", []))
        if left:
            found["partial"] = left
    if rc == 0 and spec.get("refuse"):
        found["accepted"] = True
    if spec.get("no_cr") and b"\r" in (cwd / ".stdout").read_bytes():
        found["accepted"] = True  # a CR in the result: the stream was not read as lines
    return found


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limit", type=float, default=60.0, help="seconds per case before it counts as a hang")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--only", default="", help="only subcommands containing this text")
    ap.add_argument("--classes", default="generic,scenario", help="generic (hostile values in every slot), "
                    "scenario (valid inputs, one hostile thing)")
    ap.add_argument("--report", default=None, help="write every case's outcome to this JSON file")
    ap.add_argument("--build-fixtures", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.build_fixtures:
        build_fixtures(Path(args.build_fixtures))
        return
    root = Path(tempfile.mkdtemp(prefix="rigsim-attack-"))
    classes = set(args.classes.split(","))
    fix = root / "fixtures"
    if "scenario" in classes:
        t0 = time.time()
        subprocess.run([sys.executable, __file__, "--build-fixtures", str(fix)], check=True, stdout=subprocess.DEVNULL,
                       env={**os.environ, "TQDM_DISABLE": "1"})
        print(f"fixtures built in {time.time() - t0:.0f} s", flush=True)
    import rigsim.cli  # noqa: F401  (imported once; every case is a fork of this process)

    files = inputs(root)
    shared = {p: _digest(root / "inputs" / p) for p in os.listdir(root / "inputs")}
    precious = hashlib.sha256((root / "precious.txt").read_bytes()).hexdigest()
    todo = [c for c in cases(files) if args.only in c[0]] if "generic" in classes else []
    if "scenario" in classes:
        todo += [(c, o, v, a, {**sp, "fixtures": str(fix)}) for c, o, v, a, sp in scenarios(fix) if args.only in c]
    before = snapshot(root)
    results = []
    counts: dict[str, int] = {}
    finds: dict[str, int] = {"inputs_lost": 0, "nodes_replaced": 0, "partial": 0, "accepted": 0}
    k = 0
    print(f"{len(todo)} cases in {root}", flush=True)
    import concurrent.futures as cf

    with cf.ThreadPoolExecutor(args.jobs) as ex:  # threads only wait: every case is its own forked process
        futs = {ex.submit(run_case, c[3], root / "cases" / f"{i:05d}", args.limit, c[4]): (i, c)
                for i, c in enumerate(todo)}
        for f in cf.as_completed(futs):
            i, (cmd, dest, v, argv, spec) = futs[f]
            kind, rc, text, found = f.result()
            counts[kind] = counts.get(kind, 0) + 1
            for key in found:
                finds[key] += 1
            results.append({"case": i, "command": cmd, "option": dest, "value": v, "argv": argv, "outcome": kind,
                            "exit": rc, "findings": found, "stderr": text[-800:]})
            k += 1
            if kind not in ("ok", "clear") or found:
                last = text.strip().splitlines()[-1][:200] if text.strip() else ""
                print(f"[{kind}{' ' + ','.join(found) if found else ''}] {cmd} {dest}={v[:40]!r}: exit {rc}: {last}",
                      flush=True)
            if k % 100 == 0:
                print(f"... {k}/{len(todo)} {counts}", flush=True)
    named = {r["value"].split("/")[-1] for r in results if r["option"] in OUTPUT_DESTS and r["value"].startswith("../")}
    outside = sorted(snapshot(root) - before - {"cases", ".cache"} - named)  # a destination the user named is theirs
    changed = hashlib.sha256((root / "precious.txt").read_bytes()).hexdigest() != precious
    counts["outside"] = len(outside) + int(changed)
    now = {p: _digest(root / "inputs" / p) for p in shared}
    gone = sorted(p for p in shared if now[p] != shared[p])
    finds["inputs_lost"] += sum(1 for p in gone if not isinstance(shared[p], tuple))
    finds["nodes_replaced"] += sum(1 for p in gone if isinstance(shared[p], tuple))
    print(json.dumps({"cases": len(todo), **counts, **finds, "written_outside": outside, "precious_changed": changed,
                      "shared_inputs_changed": gone}))
    if args.report:
        Path(args.report).write_text(json.dumps({"counts": {**counts, **finds}, "results": results}, indent=1))


if __name__ == "__main__":
    main()
