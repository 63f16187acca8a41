"""The README's figure of one rendered frame of every kind: runs each `rigsim render` command (fixed
seeds, modest spp) into a folder and composes renders/frames_of_every_kind.png, every panel with the
exact truth from the frame's JSON sidecar (or its CSV) drawn on the 16-bit frame.

Usage: python scripts/readme_frames.py [--out PNG] [--frames DIR]
  --out     the figure (default renders/frames_of_every_kind.png)
  --frames  keep the rendered frames in DIR (default: a temporary folder, removed afterwards)

About half a minute on 2 cores. The frames are the same on every run (fixed seeds); the render times in
the panel titles are the ones each command prints, so they vary a little from run to run."""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

# key, rig, `rigsim render` arguments (the folder and file stem are added); the README lists the same commands
COMMANDS = {
    "sun": ("sun_sensor_2axis_diaphragm",
            ["sun-sensor", "--rig", "sun_sensor_2axis_diaphragm", "--pose", "X=35,Y=-20", "--spp", "256", "--seed", "0"]),
    "aim": ("sun_sensor_2axis_diaphragm",
            ["aiming-camera", "--rig", "sun_sensor_2axis_diaphragm", "--pose", "X=181.43,Y=0.50", "--seed", "0"]),
    "ac": ("sun_sensor_3axis_autocollimator",
           ["autocollimator", "--rig", "sun_sensor_3axis_autocollimator", "--spp", "256", "--seed", "0"]),
    "roi": ("dual_line_array_prism",
            ["boresight-roi", "--rig", "dual_line_array_prism", "--alpha", "30", "--df-um", "5", "--seed", "0"]),
    "star": ("star_sensor", ["star-field", "--rig", "star_sensor", "--spp", "256", "--seed", "0"]),
    "board": ("sun_sensor_2axis_diaphragm",
              ["target", "--rig", "sun_sensor_2axis_diaphragm", "--target", "chessboard:10x7:20", "--spread", "1",
               "--seed", "3", "--quiet"]),  # seed 3: the board well inside the field (seed 0's is cut by the edge)
}

HOLE = "#56b4e9"    # sky blue: the hole, the autocollimator's axis
SPOT = "#ff9f1c"    # orange: the spot, the exact truth positions
BOX = {"fontsize": 8.5, "color": "white", "linespacing": 1.3,
       "bbox": {"boxstyle": "round,pad=0.3", "fc": "black", "ec": "none", "alpha": 0.7}}


def _halo(w: float = 2.5):
    """A black outline under marks and labels, so they read on white and on black."""
    from matplotlib import patheffects

    return [patheffects.withStroke(linewidth=w, foreground="black")]


def grey_lstar(n: int = 256):
    """A grey colormap linear in CIE L* (perceptually uniform lightness), black to white."""
    from matplotlib.colors import ListedColormap

    L = np.linspace(0.0, 100.0, n)
    Y = np.where(L > 8.0, ((L + 16.0) / 116.0) ** 3, L / 903.3)
    s = np.where(Y <= 0.0031308, 12.92 * Y, 1.055 * Y ** (1 / 2.4) - 0.055)
    return ListedColormap(np.stack([s, s, s, np.ones(n)], axis=1), name="grey_Lstar")


def render_all(folder: Path) -> dict[str, dict]:
    """Run every command into ``folder``; returns per key the printed output, the printed render time and
    the wall time of the command (in this process)."""
    from rigsim.cli import main as rigsim

    runs = {}
    for key, (rig, args) in COMMANDS.items():
        where = ["--out", str(folder / "board")] if key == "board" else ["--out", str(folder), "--name", key]
        buf = io.StringIO()
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(buf):
            rc = rigsim(["render", *args, *where])
        wall = time.perf_counter() - t0
        out = buf.getvalue()
        print(f"$ rigsim render {' '.join(args)}   [{wall:.1f} s]\n" + "".join(f"    {ln}\n" for ln in out.splitlines()),
              end="", flush=True)
        if rc != 0:
            raise SystemExit(f"rigsim render {' '.join(args)}: exit {rc}")
        m = re.search(r" in ([0-9.]+) s", out)
        runs[key] = {"rig": rig, "out": out, "wall": wall, "secs": float(m.group(1)) if m else wall}
    return runs


def _frame(path: Path) -> tuple[np.ndarray, dict]:
    from rigsim.files import read_image

    return read_image(path).astype(np.float64), json.loads(path.with_suffix(".json").read_text())


def _stretch(img: np.ndarray, lo: float, hi: float, a: float | None) -> np.ndarray:
    """(img − lo)/(hi − lo) clipped to [0, 1], then asinh(x/a)/asinh(1/a) if a is given (small a = strong)."""
    x = np.clip((img - lo) / (hi - lo), 0.0, 1.0)
    return x if a is None else np.arcsinh(x / a) / np.arcsinh(1.0 / a)


def _show(ax, img, cmap, u0: float = 0.0, v0: float = 0.0, step: int = 1):
    """img[v, u] with pixel (u0, v0)'s centre at (u0, v0): axes in detector pixels (``step`` > 1: each
    shown pixel is a step × step block of the frame)."""
    h, w = img.shape
    ax.imshow(img, cmap=cmap, vmin=0, vmax=1, interpolation="nearest",
              extent=(u0 - 0.5, u0 + w * step - 0.5, v0 + h * step - 0.5, v0 - 0.5))


def _title(ax, kind: str, run: dict) -> None:
    ax.set_title(f"{kind}\n{run['rig']} · rendered in {run['secs']:.2f} s", fontsize=9.5, loc="left", linespacing=1.4)


def _mark(ax, u, v, colour, marker="+", ms=14):
    ax.plot(u, v, marker, color=colour, ms=ms, mew=1.6, path_effects=_halo(3.5))


def _crosshair(ax, u, v, colour, gap: float, length: float, diagonal: bool = False):
    """Four ticks pointing at (u, v) from ``gap`` to ``gap + length`` (data px): the position without hiding the spot
    (``diagonal``: at 45°, clear of a diffraction cross)."""
    dirs = ((0.7071, 0.7071), (-0.7071, 0.7071), (0.7071, -0.7071), (-0.7071, -0.7071)) if diagonal else \
        ((1, 0), (-1, 0), (0, 1), (0, -1))
    for du, dv in dirs:
        ax.plot([u + du * gap, u + du * (gap + length)], [v + dv * gap, v + dv * (gap + length)], color=colour, lw=2.0,
                solid_capstyle="butt", path_effects=_halo(4))


def _note(ax, text: str, top: bool = False) -> None:
    ax.text(0.025, 0.975 if top else 0.025, text, transform=ax.transAxes, va="top" if top else "bottom", **BOX)


def _locator(ax, shape, box, marks, cmap, img=None, size=0.34, label=None, bottom=False):
    """An inset (top right, or bottom right) of the whole detector with the crop's box and marks
    [(u, v, colour, marker)]."""
    from matplotlib.patches import Rectangle

    h, w = shape
    s = max(w, h)
    ww, hh = size * w / s, size * h / s
    ins = ax.inset_axes([0.985 - ww, 0.015 if bottom else 0.985 - hh, ww, hh])
    if img is None:
        img = np.zeros(shape)
    ins.imshow(img, cmap=cmap, vmin=0, vmax=1, extent=(-0.5, w - 0.5, h - 0.5, -0.5))
    u0, v0, u1, v1 = box
    ins.add_patch(Rectangle((u0, v0), u1 - u0, v1 - v0, fill=False, ec=SPOT, lw=1.3))
    for u, v, c, mk in marks:
        ins.plot(u, v, mk, color=c, ms=6, mew=1.4)
    ins.set_xticks([])
    ins.set_yticks([])
    for sp in ins.spines.values():
        sp.set_edgecolor("0.75")
    ins.text(0.04, 0.04, label or f"whole detector\n{w}×{h} px", transform=ins.transAxes, fontsize=7, color="0.85",
             va="bottom", linespacing=1.1)
    return ins


def _axes_px(ax, xlabel="u [px]", ylabel="v [px]"):
    ax.set_xlabel(xlabel, fontsize=8, labelpad=1)
    ax.set_ylabel(ylabel, fontsize=8, labelpad=1)
    ax.tick_params(labelsize=7.5)


def _block_max(img: np.ndarray, k: int) -> np.ndarray:
    h, w = (img.shape[0] // k) * k, (img.shape[1] // k) * k
    return img[:h, :w].reshape(h // k, k, w // k, k).max(axis=(1, 3))


def compose(folder: Path, runs: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle
    from scipy.ndimage import gaussian_filter

    cmap = grey_lstar()
    fig, axs = plt.subplots(2, 3, figsize=(14, 10), dpi=100)
    fig.subplots_adjust(left=0.045, right=0.985, top=0.875, bottom=0.05, wspace=0.22, hspace=0.28)
    fig.suptitle("One rendered frame of every kind: 16-bit PNG frames, marks at the exact positions from each "
                 "frame's JSON sidecar or CSV", fontsize=12, y=0.985)
    fig.text(0.5, 0.945, "grey linear in CIE L*; stretch linear from the dark level, or asinh where the signal is faint; "
             "axes in detector pixels (pixel centres at integers)", ha="center", fontsize=9.5, color="0.3")

    # --- sun sensor: a 4 px sun image on a 1024² detector -> a crop, and where it sits
    ax = axs[0, 0]
    img, side = _frame(folder / "sun.png")
    c = np.array(side["truth"]["spot"]["center_uv"])
    half = 12
    u0, v0 = int(np.rint(c[0])) - half, int(np.rint(c[1])) - half
    crop = img[v0:v0 + 2 * half + 1, u0:u0 + 2 * half + 1]
    dark = float(np.median(img))
    _show(ax, _stretch(crop, dark, crop.max(), 0.05), cmap, u0, v0)
    _crosshair(ax, *c, SPOT, 3.5, 4)
    _note(ax, f"pose X′ {side['pose']['X']:g}°, Y′ {side['pose']['Y']:g}°\n"
              f"exact sun-image centre (crosshair)\nu {c[0]:.3f}, v {c[1]:.3f} px")
    _locator(ax, img.shape, (u0 - 20, v0 - 20, u0 + 2 * half + 20, v0 + 2 * half + 20), [], cmap)
    _title(ax, "sun sensor: the sun simulator's image (25 px crop, asinh)", runs["sun"])
    _axes_px(ax)

    # --- aiming camera: the spot frame as the campaign renders it (the divergent return spot, the glowing hole
    #     in it); a crop around the two centres, the hole frame's edge as a contour, the whole frame as an inset
    ax = axs[0, 1]
    spot, sside = _frame(folder / "aim_spot.png")
    hole, _ = _frame(folder / "aim_hole.png")
    t = sside["truth"]
    hc, sc = np.array(t["hole_center_uv"]), np.array(t["spot_center_uv"])
    dark = float(np.median(spot[:40, :40]))
    top = float(np.percentile(spot, 99.5))
    plateau = float(np.median(spot[spot > dark + 0.5 * (top - dark)]))
    hi = dark + 1.6 * (plateau - dark)  # the spot's plateau mid-grey, so that the marks read on it
    hw = hh = 210  # a 421 px crop with the hole centre at 42 % across and 40 % down: clear of the note and the inset
    u0, v0 = int(np.rint(hc[0] - 0.42 * 2 * hw)), int(np.rint(hc[1] - 0.40 * 2 * hh))
    crop = spot[v0:v0 + 2 * hh + 1, u0:u0 + 2 * hw + 1]
    _show(ax, _stretch(crop, dark, hi, None), cmap, u0, v0)
    hs = gaussian_filter(hole, 2.0)
    level = dark + 0.5 * (float(np.percentile(hs, 99.9)) - dark)
    ax.contour(np.arange(u0, u0 + 2 * hw + 1), np.arange(v0, v0 + 2 * hh + 1), hs[v0:v0 + 2 * hh + 1, u0:u0 + 2 * hw + 1],
               levels=[level], colors=HOLE, linewidths=1.6)
    ax.annotate("", xy=sc, xytext=hc, arrowprops={"arrowstyle": "-|>", "color": "white", "lw": 1.2, "shrinkA": 4,
                                                      "shrinkB": 4, "path_effects": _halo(3)})
    _mark(ax, *hc, HOLE, "+", 18)
    _mark(ax, *sc, SPOT, "x", 12)
    ax.text(hc[0] + 10, hc[1] - 12, "hole centre", color=HOLE, fontsize=9, fontweight="bold", path_effects=_halo())
    ax.text(sc[0] - 10, sc[1] + 14, "spot centre", color=SPOT, fontsize=9, fontweight="bold", ha="right", va="top",
            path_effects=_halo())
    ax.text(hc[0] - 100, hc[1] + 98, "hole edge\n(hole frame)", color=HOLE, fontsize=8.5, fontweight="bold",
            ha="center", va="top", path_effects=_halo())
    d = sc - hc
    p = t["pose_deg"]
    _note(ax, f"face {t['face']}, pose X′ {p['X']:g}°, Y′ {p['Y']:g}°\n"
              f"spot − hole: Δu {d[0]:+.1f}, Δv {d[1]:+.1f} px ({np.hypot(*d):.1f} px)\n"
              f"on the screen: {t['offset_mm'][0] * 1e3:+.0f}, {t['offset_mm'][1] * 1e3:+.0f} µm", top=True)
    whole = _stretch(_block_max(spot, 4), dark, hi, None)
    _locator(ax, spot.shape, (u0, v0, u0 + 2 * hw, v0 + 2 * hh), [(*hc, HOLE, "+"), (*sc, SPOT, "x")], cmap, img=whole,
             size=0.40, label="whole spot frame\n1600×1200 px", bottom=True)
    _title(ax, "aiming camera: the divergent return spot beside the hole", runs["aim"])
    _axes_px(ax)

    # --- autocollimator: the return spot of a cube face, small on a 1280×1024 detector
    ax = axs[0, 2]
    img, side = _frame(folder / "ac.png")
    t = side["truth"]
    c = np.array(t["spot_pixel_centroid_uv"])
    ref = np.array(t["reference_uv"])
    half = 40
    u0, v0 = int(np.rint(c[0])) - half, int(np.rint(c[1])) - half
    crop = img[v0:v0 + 2 * half + 1, u0:u0 + 2 * half + 1]
    dark = float(np.median(img))
    _show(ax, _stretch(crop, dark, crop.max(), 0.01), cmap, u0, v0)
    _crosshair(ax, *c, SPOT, 9, 9, diagonal=True)
    tilt = t["true_tilt_arcsec"]
    pd = side["pose"]["true_deg"]
    _note(ax, f"face {t['face']}, pose X {pd['X']:g}°, Y {pd['Y']:g}°, Z {pd['Z']:g}°\n"
              f"exact spot centroid (crosshair) u {c[0]:.3f}, v {c[1]:.3f} px\n"
              f"true tilt θx {tilt[0]:+.2f}″, θy {tilt[1]:+.2f}″")
    ins = _locator(ax, img.shape, (u0, v0, u0 + 2 * half, v0 + 2 * half), [(*ref, HOLE, "+")], cmap)
    ins.text(ref[0] - 30, ref[1] + 60, "axis", color=HOLE, fontsize=7, ha="right", va="top")
    _title(ax, "autocollimator: a cube face's return spot (81 px crop, asinh)", runs["ac"])
    _axes_px(ax)

    # --- boresight ROI: 48×48 px of a CMOS, in detector pixels
    ax = axs[1, 0]
    img, side = _frame(folder / "roi.png")
    o = side["extra"]["roi_origin_uv"]
    c = np.array(side["truth"]["spot_uv"])
    dark = float(np.median(img))
    _show(ax, _stretch(img, dark, img.max(), 0.05), cmap, o[0], o[1])
    _crosshair(ax, *c, SPOT, 4, 6)
    ex = side["extra"]
    _note(ax, f"camera {ex['camera']}, CMOS {ex['detector']}, α 30″, Δf 5 µm\n"
              f"exact spot centre (crosshair) u {c[0]:.3f}, v {c[1]:.3f} px\nROI origin ({o[0]}, {o[1]})")
    _title(ax, "boresight: a CMOS ROI of a laser spot (48×48 px, asinh)", runs["roi"])
    _axes_px(ax, "u [detector px]", "v [detector px]")

    # --- star field: the whole detector (3×3 max-binned to show at this size), a few catalogue stars circled
    ax = axs[1, 1]
    img, side = _frame(folder / "star.png")
    with open(folder / "star_stars.csv", newline="") as f:
        stars = sorted(csv.DictReader(f), key=lambda r: float(r["mag"]))
    k = 3
    binned = _block_max(img, k)
    dark = float(np.median(binned))
    noise = float(np.median(np.abs(binned - dark))) * 1.4826
    _show(ax, _stretch(binned, dark + 2 * noise, float(np.percentile(img, 99.995)), 0.02), cmap, 0, 0, step=k)
    H, W = img.shape
    picked, taken = [], []  # taken: boxes (u0, v0, u1, v1) of the circles and labels placed so far

    def free(b):
        return all(b[2] < t[0] or b[0] > t[2] or b[3] < t[1] or b[1] > t[3] for t in taken)

    for r in stars:
        u, v = float(r["u_px"]), float(r["v_px"])
        if not (60 < u < W - 60 and 60 < v < H - 60) or (u < 600 and v > H - 170):  # clear of the edge and the note
            continue
        circle = (u - 30, v - 30, u + 30, v + 30)
        for right in (True, False):
            label = (u + 28, v - 95, u + 200, v - 20) if right else (u - 200, v - 95, u - 28, v - 20)
            if label[0] > 0 and label[2] < W and free(circle) and free(label):
                picked.append((u, v, r, right))
                taken += [circle, label]
                break
        if len(picked) == 6:
            break
    for u, v, r, right in picked:
        ax.add_patch(Circle((u, v), 24, fill=False, ec=SPOT, lw=1.4, path_effects=_halo(3)))
        ax.text(u + (28 if right else -28), v - 24, f"HIP {r['hip']}\n{float(r['mag']):.1f} mag", color=SPOT,
                fontsize=8.5, fontweight="bold", va="bottom", ha="left" if right else "right", linespacing=1.05,
                path_effects=_halo())
    _note(ax, f"attitude RA 83.8°, Dec −5.4°, roll 0°\n{len(stars)} stars in the CSV; shown 3×3 max-binned")
    _title(ax, "star sensor: the whole detector (asinh)", runs["star"])
    _axes_px(ax)

    # --- chessboard target through the sun sensor's true (distorted) camera
    ax = axs[1, 2]
    img, side = _frame(folder / "board" / "frame_000.png")
    with open(folder / "board" / "points.csv", newline="") as f:
        pts = [r for r in csv.DictReader(f) if r["frame"] == "frame_000.png"]
    dark = float(np.median(img[-50:, :50]))
    _show(ax, _stretch(img, dark, float(np.percentile(img, 99.9)), None), cmap)
    cols, rows = side["truth"]["pattern_size"]
    uv = np.array([[float(r["u_px"]), float(r["v_px"])] for r in pts])
    ax.plot(uv[:, 0], uv[:, 1], ".", color=SPOT, ms=3.5)
    corners = (0, cols - 1, cols * (rows - 1), cols * rows - 1)
    for j in corners:
        u, v = uv[j]
        ax.plot(u, v, "o", ms=10, mfc="none", mec=SPOT, mew=1.6, path_effects=_halo(3.5))
        up = j < cols
        ax.text(u, v + (-22 if up else 22), f"#{j}", color=SPOT, fontsize=9, fontweight="bold", ha="center",
                va="bottom" if up else "top", path_effects=_halo())
    u, v = uv[0]
    _note(ax, f"1 pose (--spread 1), {side['render']['spp']} spp\n"
              f"{len(pts)} exact inner corners (dots) from points.csv\n#0 at u {u:.3f}, v {v:.3f} px")
    _title(ax, "target: a 10×7 chessboard through the sun sensor's lens", runs["board"])
    _axes_px(ax)

    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100, metadata={"Software": None})
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "renders" / "frames_of_every_kind.png")
    ap.add_argument("--frames", type=Path, default=None, help="keep the rendered frames here")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        folder = args.frames or Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="readme_frames_")))
        folder.mkdir(parents=True, exist_ok=True)
        runs = render_all(folder)
        compose(folder, runs, args.out)
    print(f"wrote {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
