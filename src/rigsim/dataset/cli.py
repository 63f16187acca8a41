"""``rigsim dataset generate | score | verify | info`` (registered by rigsim.cli through add_cli)."""

from __future__ import annotations

import argparse
import json
import sys

from rigsim.files.options import SEED, SPP, integer, number
from rigsim.files.outputs import declare

EPILOG = """\
examples:
  rigsim dataset generate sun_sensor_2axis_diaphragm --out data/sun --frames 200 --seed 7
  rigsim dataset generate sun_sensor_2axis_diaphragm --out data/grid --sweep "X=-60:60:10 Y=-60:60:10"
  rigsim dataset generate sun_sensor_2axis_diaphragm --out data/sun --frames 200 --scheduler tcp://head:8786
  rigsim dataset score data/sun my_centroids.csv          # columns: frame,u,v  (or frame,x,y,z)
  rigsim dataset generate star_sensor --out data/stars --frames 500      # FITS, one truth row per star
  rigsim dataset verify data/sun

Rerunning the same generate command resumes an interrupted run. Format and CSV columns: docs/datasets.md.
"""


def _gen(args) -> int:
    from rigsim.dataset.runner import generate

    r = generate(args.rig, args.out, frames=args.frames, sweep=args.sweep, seed=args.seed, generator=args.generator,
                 workers=args.workers, scheduler=args.scheduler, spp=args.spp, retries=args.retries,
                 progress=not args.quiet, renderer=args.renderer)
    print(f"dataset {r.root}: {r.n_frames} frames ({r.n_resumed} already complete, {r.n_rendered} rendered"
          + (f", {r.retries} retried tasks" if r.retries else "") + f") in {r.seconds:.1f} s"
          + (f", {r.frames_per_second:.2f} frames/s" if r.n_rendered else ""))
    print(f"truth: {r.root / 'truth.parquet'} (+ truth.csv), manifest: {r.root / 'manifest.json'}")
    return 0


def _score(args) -> int:
    from rigsim.dataset.score import score

    if not (0 < args.match_radius <= 50):
        from rigsim.errors import DatasetError

        raise DatasetError(f"--match-radius = {args.match_radius}: allowed range is (0, 50] px")
    s = score(args.dataset, args.predictions, mode=args.mode, truth_ref=args.truth_ref, outlier=args.outlier,
              match_radius_px=args.match_radius, outlier_abs=args.outlier_abs)
    print(s.text())
    if args.json_out:
        from rigsim.files.atomic import atomic_write_text

        atomic_write_text(args.json_out, json.dumps(s.as_dict(), indent=1, default=float) + "\n")
    if args.errors_out:
        from rigsim.files.tables import write_table

        keys = list(s.rows[0]) if s.rows else ["frame"]
        write_table(args.errors_out, {k: [r[k] for r in s.rows] for k in keys})
        print(f"wrote {args.errors_out}: {len(s.rows)} rows")
    return 0


def _verify(args) -> int:
    from rigsim.dataset.runner import verify

    bad = verify(args.dataset, progress=True)
    if bad:  # the problems are the command's output (stdout); one line on stderr says the dataset is not whole
        from rigsim.reporting import safe_text

        print("\n".join(safe_text(b, 500) for b in bad[:200]) + (f"\n... and {len(bad) - 200} more" if len(bad) > 200 else ""))
        print(f"rigsim: {args.dataset}: {len(bad)} problem(s) found (listed on stdout)", file=sys.stderr)
        return 1
    print(f"{args.dataset}: every file matches the manifest")
    return 0


def _info(args) -> int:
    from rigsim.dataset.reader import open_dataset

    ds = open_dataset(args.dataset)
    m = ds.manifest
    print(f"{ds.root}: {len(ds)} {m['image_format'].upper()} frames, generator {m['generator']}, rig {m['rig_file']}, seed {m['seed']}")
    print("truth columns: " + ", ".join(ds.columns))
    return 0


def add_cli(groups: dict) -> None:
    """Add the command to the parser groups {"top", "run", "render"} of ``rigsim``."""
    top = groups["top"]
    d = top.add_parser("dataset", help="generate, verify and score synthetic datasets (docs/datasets.md)",
                       description="Synthetic datasets at scale.", epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    ds = d.add_subparsers(dest="dataset_cmd", metavar="COMMAND")
    from rigsim.dataset.generators import GENERATORS

    g = ds.add_parser("generate", help="render a dataset (resumable)", epilog=EPILOG,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    g.add_argument("rig", help="rig file path or default rig name")
    g.add_argument("--out", required=True, metavar="DIR", help="dataset directory (created; rerun to resume)")
    g.add_argument("--frames", type=integer(1, 10_000_000), default=None, metavar="N", help="N random draws of rig errors and poses")
    g.add_argument("--sweep", default=None, metavar="SPEC", help='pose grid, e.g. "X=-60:60:5 Y=0,10,20" (degrees)')
    g.add_argument("--seed", type=SEED, default=0, help="the dataset seed: the whole dataset is reproducible from it")
    g.add_argument("--generator", default=None, choices=sorted(GENERATORS), help="frame kind (default: the rig's)")
    g.add_argument("--workers", type=integer(1, 512), default=None, help="local worker processes (default: the CPU count)")
    g.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT", help="run on a Dask distributed cluster")
    g.add_argument("--spp", type=SPP, default=None, help="Mitsuba samples per pixel (default: the generator's: "
                   + ", ".join(f"{k} {c.default_spp}" for k, c in sorted(GENERATORS.items())) + ")")
    g.add_argument("--renderer", default=None, choices=("analytic", "mitsuba"),
                   help="star-field only: the analytic pixel-integrated PSF (default) or Mitsuba through the "
                        "distorted pinhole (--spp honoured)")
    g.add_argument("--retries", type=integer(0, 20), default=2, help="retries of a failed task")
    g.add_argument("--quiet", action="store_true", help="no progress bar")
    g.set_defaults(func=_gen)
    declare(g, "out", folder=True)
    s = ds.add_parser("score", help="score an external pipeline's predictions CSV against the truth")
    s.add_argument("dataset", metavar="DIR")
    s.add_argument("predictions", metavar="CSV",
                   help="columns frame and u,v / u_px,v_px / xcentroid,ycentroid (photutils) / x,y (sep) for centroids, "
                        "or frame,x,y,z for directions; a NaN or empty value is a failed fit (counted as missing)")
    s.add_argument("--mode", choices=["centroid", "direction"], default=None, help="default: from the columns")
    s.add_argument("--truth-ref", choices=["centre", "pixel-centroid"], default="centre",
                   help="centroid truth: the sun centre's projection, or the exact pixel first moment")
    s.add_argument("--outlier", type=number(1e-9, 1e9), default=None,
                   help="a floor under the outlier threshold (px or arcsec); default 5 robust σ")
    s.add_argument("--outlier-abs", type=number(1e-9, 1e9), default=None, metavar="VALUE",
                   help="an absolute outlier threshold (px or arcsec) instead of the robust one")
    s.add_argument("--match-radius", type=number(1e-3, 1e4), default=2.0, help="star frames: match radius (px)")
    s.add_argument("--json-out", default=None, metavar="FILE", help="the summary as JSON")
    s.add_argument("--errors-out", default=None, metavar="CSV",
                   help="every frame's (star frames: every matched star's) prediction, truth and error")
    s.set_defaults(func=_score)
    declare(s, "json_out")
    declare(s, "errors_out", suffixes=(".csv", ".parquet"))
    v = ds.add_parser("verify", help="check every file against the manifest's checksums")
    v.add_argument("dataset", metavar="DIR")
    v.set_defaults(func=_verify)
    i = ds.add_parser("info", help="summary of a dataset")
    i.add_argument("dataset", metavar="DIR")
    i.set_defaults(func=_info)
