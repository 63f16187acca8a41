"""Lost in space on the four real night-sky frames of docs/examples/real-star-frames, checked star by
star against an independent solver (cedar-solve, its solutions committed beside the frames): every
frame identified, no star given another HIP number than cedar gives the same centroid, the
boresight within 1′ of cedar's and the focal length within 0.1 % of cedar's field of view.

The centroids come from sep (a library independent of rigsim's extractor), as docs/lost-in-space.md
describes; the nominal camera is what a user knows: a 35 mm lens on 6.9 µm pixels (0.9 % shorter
than the focal length cedar finds), principal point at the detector centre, no distortion."""

from __future__ import annotations

import numpy as np
import pytest
from real_frames import (EPOCH, FRAMES, MAGNITUDE_LIMIT, cedar_solutions, compare_with_cedar, real_camera,
                         sep_centroids)

from rigsim.estimation.star_lis import identify_lost_in_space
from rigsim.optics.sky import SkyCatalogue

CEDAR = cedar_solutions()
NAMES = sorted(CEDAR)


@pytest.fixture(scope="module")
def sky_2019():
    return SkyCatalogue.load(MAGNITUDE_LIMIT, EPOCH)


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
    cmp = compare_with_cedar(CEDAR[name], uv, res.obs_index, res.hip, res.R_cam_from_icrs, res.f_px)
    assert cmp["wrong"] == 0, cmp
    assert cmp["common"] >= 0.9 * cmp["cedar"], cmp  # the stars cedar matched are found too (sep finds them all)
    assert cmp["boresight_arcmin"] < 1.0, cmp
    assert abs(cmp["f_rel"]) < 1e-3, cmp  # the nominal is 0.9 % off
    assert res.false_match_probability < 1e-9
    assert res.residual_rms_px < 0.5
