"""Lost-in-space identification on real night-sky frames: the old identifier (geometric pair voting,
the package at ``--base``) and the new one (4-star pattern hashing, the working tree) side by side,
per frame, in one run, both checked star by star against cedar-solve's solutions.

Centroids: sep (background map, 5 σ, at least 3 px), brightest first, computed once here and
handed to both sides, so that only the identifiers differ. Nominal camera: 1024 × 768 px,
principal point at the centre, no distortion, and the focal length in four cases: ``exact``
(cedar's mean field of view), ``+5%`` and ``-5%`` of it, and ``lens`` (35 mm / 6.9 µm, what a
user knows before calibrating). Catalogue: Hipparcos 2 to Hp 8 at epoch 2019.58.

Per frame and side: identified or not, stars identified, stars in common with cedar (a centroid
within 1 px of cedar's), wrong stars (another HIP than cedar's), the boresight's offset from
cedar's (arcmin), the implied focal length's offset from cedar's (ppm; new side only) and the
identification time (median of ``--repeat`` runs, after extraction). The new side also reports the
pattern database's build time (a fresh cache folder) and its load time from the cache.

Run:  .venv/bin/python benchmarks/lost_in_space.py [FRAMES…] [--cedar JSON…] [--repeat 5] [--base COMMIT]
(default: the four frames of docs/examples/real-star-frames and their cedar-solve-solutions.json)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "estimation"))
from _compare import REPO, old_src  # noqa: E402
from real_frames import FRAMES, H, W, cedar_f_px, cedar_solutions, compare_with_cedar, sep_centroids  # noqa: E402

BASE = "441788c"  # the last commit with the geometric-voting identifier

_CHILD = r"""
import json, math, sys, time
import numpy as np
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.sky import SkyCatalogue
from rigsim.estimation.star_lis import identify_lost_in_space
new = {new}
data = np.load({cents!r})
names = json.loads({names!r})
sky = SkyCatalogue.load(8.0, 2019.58)
out = {{}}
if new:
    from rigsim.estimation import star_patterns as sp
    from rigsim.estimation.star_lis import database_for
    t0 = time.perf_counter(); db = database_for(sky, PinholeBrown({f0}, {f0}, {cx}, {cy}, width={W}, height={H}))
    out["_db"] = {{"seconds": time.perf_counter() - t0, "source": db.source, "patterns": len(db),
                  "build_seconds": db.build_seconds}}
for case, f in json.loads({cases!r}).items():
    cam = PinholeBrown(f, f, {cx}, {cy}, width={W}, height={H})
    if new:  # the database of this focal length: build or load it before timing
        t0 = time.perf_counter(); db = database_for(sky, cam)
        out.setdefault("_db_cases", {{}})[case] = {{"seconds": time.perf_counter() - t0, "source": db.source,
                                                  "patterns": len(db), "build_seconds": db.build_seconds}}
    kw = {{}} if new else {{"search_radius_px": 60.0, "match_tolerance_px": 2.0, "min_matches": 4}}
    for n in names:
        uv = data[n]
        times = []
        for _ in range({repeat}):
            t0 = time.perf_counter()
            r = identify_lost_in_space(uv, sky, cam, **kw)
            times.append(time.perf_counter() - t0)
        out[case + "|" + n] = {{"ok": bool(r.ok), "obs": r.obs_index.tolist(), "hip": r.hip.tolist(),
                               "R": np.asarray(r.R_cam_from_icrs).tolist(), "reason": r.reason,
                               "f": float(getattr(r, "f_px", float("nan"))),
                               "p": float(getattr(r, "false_match_probability", float("nan"))),
                               "seconds": float(np.median(times))}}
print("@@RESULT@@" + json.dumps(out))
"""


def run_side(src: Path, new: bool, cents: str, names: list, cases: dict, repeat: int, env: dict) -> dict:
    code = _CHILD.format(new=new, cents=cents, names=json.dumps(names), cases=json.dumps(cases), repeat=int(repeat),
                         f0=cases["exact"], cx=(W - 1) / 2.0, cy=(H - 1) / 2.0, W=W, H=H)
    e = dict(os.environ, PYTHONPATH=str(src), **env)
    p = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=e,
                       cwd=str(REPO), check=False)
    if p.returncode:
        raise RuntimeError(f"benchmark child failed ({src}):\n{p.stderr[-4000:]}")
    return json.loads(p.stdout.rsplit("@@RESULT@@", 1)[1])


def against_cedar(res: dict, uv: np.ndarray, sol: dict) -> dict:
    if not res["ok"]:
        return {}
    c = compare_with_cedar(sol, uv, res["obs"], res["hip"], np.array(res["R"]), res["f"])
    return dict(c, boresight=c["boresight_arcmin"], f_ppm=c["f_rel"] * 1e6)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("frames", nargs="*", type=Path, help="16-bit TIFF frames (default: docs/examples/real-star-frames)")
    ap.add_argument("--cedar", nargs="*", type=Path, help="cedar-solve solutions (scripts/cedar_solutions.py)")
    ap.add_argument("--repeat", type=int, default=5, help="identifications per frame and side (default 5)")
    ap.add_argument("--base", default=BASE, help=f"the old side's commit (default {BASE})")
    a = ap.parse_args(argv)
    frames = sorted(a.frames or FRAMES.glob("*.tiff"))
    cedar = cedar_solutions(*(a.cedar or []))
    names = [f.name for f in frames if f.name in cedar]
    missing = [f.name for f in frames if f.name not in cedar]
    if missing:
        print(f"no cedar solution for {', '.join(missing)}: left out", file=sys.stderr)
    f_exact = float(np.mean([cedar_f_px(cedar[n]) for n in names]))
    cases = {"exact": f_exact, "+5%": 1.05 * f_exact, "-5%": 0.95 * f_exact, "lens": 35.0e3 / 6.9}
    cents = {f.name: sep_centroids(f) for f in frames if f.name in cedar}
    with tempfile.TemporaryDirectory(prefix="rigsim-lis-bench-") as tmp:
        cpath = str(Path(tmp) / "centroids.npz")
        np.savez(cpath, **cents)
        cache = {"RIGSIM_CACHE_DIR": str(Path(tmp) / "cache")}  # a fresh cache: the new side builds its databases
        new_cold = run_side(REPO / "src", True, cpath, names, {"exact": f_exact}, 1, cache)
        new = run_side(REPO / "src", True, cpath, names, cases, a.repeat, cache)  # now from the cache
        old = run_side(old_src(a.base), False, cpath, names, cases, a.repeat, {})
    print(f"lost in space on {len(names)} real frames; sep centroids; Hipparcos to Hp 8; cedar's f = {f_exact:.1f} px")
    print(f"new: pattern database of {new_cold['_db']['patterns']} patterns built in {new_cold['_db']['build_seconds']:.2f} s "
          f"(fresh cache), loaded from the cache in {new['_db']['seconds']:.3f} s")
    hdr = f"{'f case':<6} {'frame':<26} | {'old (voting)':<34} | {'new (patterns)':<58}"
    print(hdr)
    print(f"{'':<6} {'':<26} | {'ok stars ∩cedar wrong  arcmin   ms':<34} | "
          f"{'ok stars ∩cedar wrong  arcmin   f ppm  P(false)      ms':<58}")
    summary = {"old": {"ok": 0, "wrong": 0, "t": []}, "new": {"ok": 0, "wrong": 0, "t": []}}
    for case in cases:
        for n in names:
            row = f"{case:<6} {n.replace('2019-07-29T204726_', '').replace('_Try1.tiff', ''):<26} |"
            for side, res_all in (("old", old), ("new", new)):
                r = res_all[case + "|" + n]
                c = against_cedar(r, cents[n], cedar[n])
                summary[side]["t"].append(r["seconds"])
                if r["ok"]:
                    summary[side]["ok"] += 1
                    summary[side]["wrong"] += c["wrong"]
                    cell = (f" yes {len(r['obs']):>5} {c['common']:>3}/{c['cedar']:<3} {c['wrong']:>4} {c['boresight']:>7.2f} "
                            f"{1e3 * r['seconds']:>5.1f}")
                    if side == "new":
                        cell = cell[:-6] + f" {c['f_ppm']:>+7.0f}  {r['p']:>8.0e} {1e3 * r['seconds']:>5.1f}"
                else:
                    cell = f" no  {r['reason'][:24]:<24} {1e3 * r['seconds']:>5.1f}"
                row += f"{cell:<35}|" if side == "old" else cell
            print(row)
    for side in ("old", "new"):
        s = summary[side]
        print(f"{side}: {s['ok']} of {len(cases) * len(names)} identified, {s['wrong']} wrong stars against cedar, "
              f"median {1e3 * np.median(s['t']):.1f} ms per frame (after extraction)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
