"""rigsim's attack suite: every option and positional of every subcommand given hostile values, through the
command's body (not only its parser). Each case runs ``rigsim.cli.main`` in a forked process, in its own
folder, with a time limit, and is classified:

  ok        exit 0
  clear     exit 2 (or 1 for a full disk / interrupted run, 3 for a poor fit) with exactly one line on stderr
  traceback an exception escaped main(), or a Python traceback was printed
  unclear   another exit status, or several lines of error
  hang      still running after the time limit (a valid value that starts a long run is counted too and
            listed, so that it can be checked by hand)
  outside   a file appeared outside the case's folder, or the precious file outside it changed

Usage: python tests/attack/attack.py [--limit S] [--jobs N] [--only SUBSTRING] [--report FILE.json]
Prints one line per non-clean case and the counts. docs/reliability.md explains the figures.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import signal
import sys
import tempfile
import time
import traceback
from pathlib import Path

NASTY = ["", "nan", "-1", "1e308", "../../escape", "\x1b[31mred", "x" * 300, "@dir", "@garbage", "@empty", "@fifo",
         "@link", "@json-list", "@csv-wrong", "@png-8bit"]
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
}
OUTPUT_DESTS = {"out", "json_out", "xml", "preview", "export_frames"}  # where the user names the destination


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
    return {"@dir": str(d / "folder"), "@garbage": str(d / "garbage.png"), "@empty": str(d / "empty.csv"),
            "@fifo": str(d / "fifo.csv"), "@link": str(d / "link.csv"), "@json-list": str(d / "list.json"),
            "@csv-wrong": str(d / "wrong.csv"), "@png-8bit": str(d / "eight.png")}


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
            for v in NASTY:
                val = files.get(v, v)
                argv = base(skip=a)
                if a.option_strings:
                    argv += [f"{a.option_strings[0]}={val}"]
                else:
                    argv = argv[:len(path)] + [val] + argv[len(path):]
                argv += [x for i, x in enumerate(cheap) if not (a.option_strings and x == a.option_strings[0])
                         and not (i > 0 and a.option_strings and cheap[i - 1] == a.option_strings[0])]
                yield " ".join(path), a.dest, v, argv


def run_case(argv, cwd: Path, limit: float):
    cwd.mkdir(parents=True)
    out, err = cwd / ".stdout", cwd / ".stderr"
    pid = os.fork()
    if pid == 0:  # the child: a fresh command in its own folder
        try:
            os.setsid()
            os.chdir(cwd)
            fo, fe = os.open(out, os.O_WRONLY | os.O_CREAT, 0o644), os.open(err, os.O_WRONLY | os.O_CREAT, 0o644)
            os.dup2(fo, 1)
            os.dup2(fe, 2)
            os.environ.update({"TMPDIR": str(cwd), "HOME": str(cwd), "RIGSIM_CACHE_DIR": str(cwd.parent / ".cache"),
                               "PYTHONWARNINGS": "ignore", "TQDM_DISABLE": "1"})
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
    t0 = time.time()
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.time() - t0 > limit:
            os.killpg(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return "hang", None, err.read_text(errors="replace")
        time.sleep(0.05)
    rc = os.waitstatus_to_exitcode(status)
    text = err.read_text(errors="replace")
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith(("rigsim: note:", "rigsim: warning:"))
             and "WARN" not in ln]
    if rc == 99 or "Traceback (most recent call last)" in text:
        return "traceback", rc, text
    if rc == 0:
        return "ok", rc, text
    if rc in (1, 2, 3, 130) and len(lines) == 1 and lines[0].startswith("rigsim"):
        return "clear", rc, text
    return "unclear", rc, text


def snapshot(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.iterdir()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limit", type=float, default=60.0, help="seconds per case before it counts as a hang")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--only", default="", help="only subcommands containing this text")
    ap.add_argument("--report", default=None, help="write every case's outcome to this JSON file")
    args = ap.parse_args()
    import rigsim.cli  # noqa: F401  (imported once; every case is a fork of this process)

    root = Path(tempfile.mkdtemp(prefix="rigsim-attack-"))
    files = inputs(root)
    precious = hashlib.sha256((root / "precious.txt").read_bytes()).hexdigest()
    todo = [c for c in cases(files) if args.only in c[0]]
    before = snapshot(root)
    results, running = [], {}
    counts: dict[str, int] = {}
    k = 0
    print(f"{len(todo)} cases in {root}", flush=True)
    import concurrent.futures as cf

    with cf.ThreadPoolExecutor(args.jobs) as ex:  # threads only wait: every case is its own forked process
        futs = {ex.submit(run_case, c[3], root / "cases" / f"{i:05d}", args.limit): (i, c) for i, c in enumerate(todo)}
        for f in cf.as_completed(futs):
            i, (cmd, dest, v, argv) = futs[f]
            kind, rc, text = f.result()
            counts[kind] = counts.get(kind, 0) + 1
            results.append({"case": i, "command": cmd, "option": dest, "value": v, "argv": argv, "outcome": kind,
                            "exit": rc, "stderr": text[-800:]})
            k += 1
            if kind not in ("ok", "clear"):
                print(f"[{kind}] {cmd} {dest}={v[:20]!r}: exit {rc}: {text.strip().splitlines()[-1][:200] if text.strip() else ''}",
                      flush=True)
            if k % 100 == 0:
                print(f"... {k}/{len(todo)} {counts}", flush=True)
    named = {r["value"].split("/")[-1] for r in results if r["option"] in OUTPUT_DESTS and r["value"].startswith("../")}
    outside = sorted(snapshot(root) - before - {"cases", ".cache"} - named)  # a destination the user named is theirs
    changed = hashlib.sha256((root / "precious.txt").read_bytes()).hexdigest() != precious
    counts["outside"] = len(outside) + int(changed)
    print(json.dumps({"cases": len(todo), **counts, "written_outside": outside, "precious_changed": changed}))
    if args.report:
        Path(args.report).write_text(json.dumps({"counts": counts, "results": results}, indent=1))


if __name__ == "__main__":
    main()
