"""Lost in space on the four real night-sky frames of docs/examples/real-star-frames, checked star by
star against an independent solver (cedar-solve, its solutions committed beside the frames): every
frame identified, no star given another HIP number than cedar gives the same centroid, the
boresight within 1′ of cedar's and the focal length within 0.1 % of cedar's field of view.

The centroids come from sep (a library independent of rigsim's extractor), as docs/lost-in-space.md
describes; the nominal camera is what a user knows: a 35 mm lens on 6.9 µm pixels (0.9 % shorter
than the focal length cedar finds), principal point at the detector centre, no distortion."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from rigsim.estimation.star_lis import identify_lost_in_space
from rigsim.files import read_image
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.sky import SkyCatalogue, radec_to_unit

FRAMES = Path(__file__).resolve().parents[2] / "docs" / "examples" / "real-star-frames"
CEDAR = json.loads((FRAMES / "cedar_solutions.json").read_text())
NAMES = sorted(k for k in CEDAR if not k.startswith("_"))
W, H = 1024, 768
F_NOMINAL = 35.0e3 / 6.9  # px: the lens's 35 mm on the binned 6.9 µm pixels


def real_camera(f: float = F_NOMINAL) -> PinholeBrown:
    return PinholeBrown(f, f, (W - 1) / 2.0, (H - 1) / 2.0, width=W, height=H)


def sep_centroids(path: Path) -> np.ndarray:
    """sep's centroids of a frame, brightest first (12-bit data stored × 16)."""
    import sep

    img = np.ascontiguousarray(read_image(path), dtype=np.float64) / 16.0
    bkg = sep.Background(img)
    objs = sep.extract(img - bkg.back(), 5, err=bkg.rms(), minarea=3)
    o = np.argsort(-objs["flux"], kind="stable")
    return np.stack([objs["x"][o], objs["y"][o]], axis=1)


def cedar_f_px(name: str) -> float:
    """cedar's focal length: its horizontal field of view spans the detector's width."""
    return (W / 2.0) / math.tan(math.radians(CEDAR[name]["FOV"]) / 2.0)


def compare_with_cedar(name: str, uv: np.ndarray, res) -> dict:
    """Wrong stars (another HIP than cedar's for a centroid within 1 px of one of cedar's), stars in
    common, the boresight's offset from cedar's (arcmin) and the focal length's from cedar's (relative)."""
    c = CEDAR[name]
    cedar_uv = np.array(c["matched_centroids"], float)[:, ::-1] - 0.5  # (y, x), (0.5, 0.5) → rigsim's (u, v)
    d, j = cKDTree(cedar_uv).query(uv[res.obs_index])
    same = d < 1.0
    wrong = int(np.sum(np.array(c["matched_catID"])[j[same]] != res.hip[same]))
    centre = res.R_cam_from_icrs.T @ real_camera(res.f_px).unproject(np.array([(W - 1) / 2.0, (H - 1) / 2.0]))
    ref = radec_to_unit(math.radians(c["RA"]), math.radians(c["Dec"]))
    off = math.degrees(math.acos(min(1.0, float(centre @ ref)))) * 60.0
    return {"wrong": wrong, "common": int(same.sum()), "cedar": len(cedar_uv), "boresight_arcmin": off,
            "f_rel": res.f_px / cedar_f_px(name) - 1.0}


@pytest.fixture(scope="module")
def sky_2019():
    return SkyCatalogue.load(8.0, 2019.58)  # the frames show stars to about Hp 8; taken 2019-07-29


@pytest.fixture(scope="module")
def centroids():
    return {n: sep_centroids(FRAMES / n) for n in NAMES}


def test_the_committed_frames_and_cedar_solutions_belong_together():
    assert len(NAMES) == 4 and all((FRAMES / n).is_file() for n in NAMES)
    assert (FRAMES / "LICENSE-Apache-2.0.txt").is_file()
    fov = [CEDAR[n]["FOV"] for n in NAMES]
    assert max(fov) - min(fov) < 0.01 and abs(np.mean(fov) - 11.4230) < 0.005


@pytest.mark.parametrize("name", NAMES)
def test_real_frame_identified_as_cedar_does(name, sky_2019, centroids):
    uv = centroids[name]
    res = identify_lost_in_space(uv, sky_2019, real_camera())
    assert res.ok, res.reason
    cmp = compare_with_cedar(name, uv, res)
    assert cmp["wrong"] == 0, cmp
    assert cmp["common"] >= 0.9 * cmp["cedar"], cmp  # the stars cedar matched are found too (sep finds them all)
    assert cmp["boresight_arcmin"] < 1.0, cmp
    assert abs(cmp["f_rel"]) < 1e-3, cmp  # the nominal is 0.9 % off
    assert res.false_match_probability < 1e-9
    assert res.residual_rms_px < 0.5
