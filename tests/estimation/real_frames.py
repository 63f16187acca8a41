"""The real night-sky frames of docs/examples/real-star-frames and cedar-solve's solutions of them,
shared by the lost-in-space tests and benchmarks/lost_in_space.py: sep centroids (a library
independent of rigsim's extractor) and a star-by-star comparison with cedar."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from rigsim.files import read_image
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.sky import radec_to_unit

FRAMES = Path(__file__).resolve().parents[2] / "docs" / "examples" / "real-star-frames"
W, H = 1024, 768
F_LENS_PX = 35.0e3 / 6.9  # the lens's 35 mm on the binned 6.9 µm pixels: what a user knows
EPOCH = 2019.58           # 2019-07-29
MAGNITUDE_LIMIT = 8.0     # the frames show catalogue stars to about Hp 8


def cedar_solutions(*paths) -> dict:
    """Frame name → cedar's solution (``scripts/cedar_solutions.py``); default: the committed one."""
    out = {}
    for p in paths or (FRAMES / "cedar-solve-solutions.json",):
        out.update({k: v for k, v in json.loads(Path(p).read_text()).items() if not k.startswith("_")})
    return out


def real_camera(f: float = F_LENS_PX) -> PinholeBrown:
    """The nominal camera: principal point at the detector centre, no distortion."""
    return PinholeBrown(f, f, (W - 1) / 2.0, (H - 1) / 2.0, width=W, height=H)


def sep_centroids(path) -> np.ndarray:
    """sep's centroids of a frame (background map, 5 σ, at least 3 px), brightest first; the TIFFs
    hold 12-bit data × 16."""
    import sep

    img = np.ascontiguousarray(read_image(path), dtype=np.float64) / 16.0
    bkg = sep.Background(img)
    objs = sep.extract(img - bkg.back(), 5, err=bkg.rms(), minarea=3)
    o = np.argsort(-objs["flux"], kind="stable")
    return np.stack([objs["x"][o], objs["y"][o]], axis=1)


def cedar_f_px(sol: dict) -> float:
    """cedar's focal length: its horizontal field of view spans the detector's width."""
    return (W / 2.0) / math.tan(math.radians(sol["FOV"]) / 2.0)


def compare_with_cedar(sol: dict, uv: np.ndarray, obs_index, hip, R_cam_from_icrs, f_px: float) -> dict:
    """Against cedar's solution: wrong stars (another HIP than cedar's for a centroid within 1 px of one
    cedar matched), stars in common, cedar's count, the boresight's offset from cedar's image centre
    (arcmin) and the focal length's from cedar's (relative; NaN without an f)."""
    cedar_uv = np.array(sol["matched_centroids"], float)[:, ::-1] - 0.5  # (y, x), (0.5, 0.5) → rigsim's (u, v)
    d, j = cKDTree(cedar_uv).query(uv[np.asarray(obs_index, int)])
    same = d < 1.0
    wrong = int(np.sum(np.array(sol["matched_catID"])[j[same]] != np.asarray(hip)[same]))
    f = f_px if math.isfinite(f_px) else cedar_f_px(sol)
    centre = np.asarray(R_cam_from_icrs).T @ real_camera(f).unproject(np.array([(W - 1) / 2.0, (H - 1) / 2.0]))
    ref = radec_to_unit(math.radians(sol["RA"]), math.radians(sol["Dec"]))
    return {"wrong": wrong, "common": int(same.sum()), "cedar": len(cedar_uv),
            "boresight_arcmin": math.degrees(math.acos(min(1.0, float(centre @ ref)))) * 60.0,
            "f_rel": f_px / cedar_f_px(sol) - 1.0}
