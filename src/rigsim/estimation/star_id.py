"""Star identification near a known approximate attitude (no lost-in-space solver).

Inputs: measured centroids (px), the a-priori attitude ``R_cam_from_icrs`` (e.g. propagated by
gyros), the *nominal* camera (assumed intrinsics) and the catalogue. No truth is used.

1. **Predict**: catalogue stars within the field cone (widened by the search radius) are
   projected with the prior attitude and the nominal camera.
2. **Vote for the offset**: an error of the prior attitude moves every star by nearly the same
   image displacement (the pointing error; the roll error adds r·δψ). Every (observed, predicted)
   pair closer than ``search_radius_px`` proposes a displacement; the displacement with the most
   pairs within ``vote_tolerance_px`` of it wins (ties: smallest spread).
3. **Refine**: the voted pairs give an attitude (Wahba's problem, ``Rotation.align_vectors`` on
   unit vectors through the nominal camera); all stars are re-predicted and re-matched as
   mutual nearest neighbours within ``match_tolerance_px``, discarding a match when a second
   catalogue star is predicted within 2× the tolerance (ambiguous doubles). Three rounds.
4. **Accept** when at least ``min_matches`` stars match; the result carries the attitude, the
   matched pairs and the residual rms.

Limits (measured in tests/star/test_identify.py and docs/star_calibration.md): the pointing
error must stay below the search radius in the image (60 px ≈ 1.2° here), the roll error below
about ``vote_tolerance_px`` / (half-diagonal) ≈ 0.4°; unresolved doubles closer than the match
tolerance are dropped; the nominal focal length may be off by a few px (a scale error moves
corner stars by r·δf/f ≈ 0.75 px for 3 px). Voting fails in nearly empty fields (fewer than
``min_matches`` stars brighter than the magnitude limit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from rigsim.optics.sky import SkyCatalogue, field_cone_cos

__all__ = ["IdentResult", "identify"]


@dataclass(frozen=True)
class IdentResult:
    ok: bool
    obs_index: np.ndarray        # (M,) indices into the observations
    cat_index: np.ndarray        # (M,) indices into sky.catalogue / sky.vectors
    hip: np.ndarray              # (M,)
    dirs_icrs: np.ndarray        # (M, 3)
    R_cam_from_icrs: np.ndarray  # estimated attitude (nominal camera)
    residual_rms_px: float
    n_voted: int
    reason: str = ""
    f_px: float = float("nan")   # lost in space: the focal length the matched stars imply (nominal distortion)
    false_match_probability: float = float("nan")  # lost in space: chance that the match is a coincidence
    seconds: float = float("nan")  # lost in space: identification time

    def __len__(self) -> int:
        return int(self.obs_index.shape[0])


def _empty(R, reason, n_voted=0) -> IdentResult:
    z = np.zeros(0, dtype=np.int64)
    return IdentResult(False, z, z, z, np.zeros((0, 3)), np.asarray(R, float), float("nan"), n_voted, reason)


def identify(obs_uv: np.ndarray, sky: SkyCatalogue, R_prior: np.ndarray, camera, *, search_radius_px: float = 60.0,
             match_tolerance_px: float = 2.0, vote_tolerance_px: float = 5.0, min_matches: int = 4,
             obs_weight: np.ndarray | None = None, rounds: int = 3) -> IdentResult:
    """Match observed centroids to catalogue stars near the prior attitude.

    ``sky``: the catalogue at the observation epoch (:class:`rigsim.optics.sky.SkyCatalogue`);
    ``R_prior``: the a-priori attitude (e.g. the commanded one); ``camera``: the *nominal*
    :class:`rigsim.optics.camera.PinholeBrown`, which also sets the field cone searched.
    """
    if not isinstance(sky, SkyCatalogue):
        raise TypeError(f"sky must be a rigsim.optics.sky.SkyCatalogue (catalogue only), got {type(sky).__name__}")
    obs_uv = np.asarray(obs_uv, dtype=float)
    R_prior = np.asarray(R_prior, dtype=float)
    good = np.all(np.isfinite(obs_uv), axis=1)
    obs_idx_all = np.flatnonzero(good)
    uv_obs = obs_uv[good]
    if uv_obs.shape[0] < min_matches:
        return _empty(R_prior, f"only {uv_obs.shape[0]} stars observed (need {min_matches})")
    widen = np.arctan(search_radius_px / camera.fx)
    cos_lim = np.cos(np.arccos(field_cone_cos(camera)) + widen)
    cidx = np.flatnonzero(sky.vectors @ R_prior[2] >= cos_lim)
    if cidx.size < min_matches:
        return _empty(R_prior, f"only {cidx.size} catalogue stars near the prior attitude")
    V = sky.vectors[cidx]
    pred = camera.project(V @ R_prior.T)
    fin = np.all(np.isfinite(pred), axis=1)
    cidx, V, pred = cidx[fin], V[fin], pred[fin]
    # 2. offset voting
    tree = cKDTree(pred)
    pairs = tree.query_ball_point(uv_obs, r=search_radius_px)
    oi = np.repeat(np.arange(len(pairs)), [len(p) for p in pairs])
    ci = np.fromiter((c for p in pairs for c in p), dtype=np.int64, count=oi.size)
    if oi.size == 0:
        return _empty(R_prior, "no catalogue star predicted within the search radius of any observed star")
    disp = uv_obs[oi] - pred[ci]
    dtree = cKDTree(disp)
    counts = np.array([len(x) for x in dtree.query_ball_point(disp, r=vote_tolerance_px)])
    best = int(np.argmax(counts))
    sel = np.linalg.norm(disp - disp[best], axis=1) <= vote_tolerance_px
    # one catalogue star per observation and vice versa among the voters
    vo, vc = oi[sel], ci[sel]
    _, first_o = np.unique(vo, return_index=True)
    vo, vc = vo[first_o], vc[first_o]
    _, first_c = np.unique(vc, return_index=True)
    vo, vc = vo[first_c], vc[first_c]
    n_voted = int(vo.size)
    if n_voted < max(3, min_matches - 1):
        return _empty(R_prior, f"offset vote found only {n_voted} consistent stars", n_voted)
    b_obs = camera.unproject(uv_obs[vo])
    R = _wahba(b_obs, V[vc])
    mo = mc = np.zeros(0, dtype=np.int64)
    res = np.zeros(0)
    for _ in range(rounds):
        pred = camera.project(V @ R.T)
        fin = np.all(np.isfinite(pred), axis=1)
        ptree = cKDTree(np.where(fin[:, None], pred, 1e9))
        d, j = ptree.query(uv_obs, k=2)
        otree = cKDTree(uv_obs)
        _, back = otree.query(pred[j[:, 0]])
        ok = (d[:, 0] <= match_tolerance_px) & (d[:, 1] > 2.0 * match_tolerance_px) & (back == np.arange(len(uv_obs)))
        mo = np.flatnonzero(ok)
        mc = j[ok, 0]
        if mo.size < 3:
            break
        R = _wahba(camera.unproject(uv_obs[mo]), V[mc])
        res = np.linalg.norm(camera.project(V[mc] @ R.T) - uv_obs[mo], axis=1)
    if mo.size < min_matches:
        return _empty(R, f"{mo.size} stars matched within {match_tolerance_px} px (need {min_matches})", n_voted)
    return IdentResult(True, obs_idx_all[mo], cidx[mc], sky.hip[cidx[mc]], V[mc], R,
                       float(np.sqrt(np.mean(res**2))) if res.size else float("nan"), n_voted)


def _wahba(b_cam: np.ndarray, r_icrs: np.ndarray) -> np.ndarray:
    """R_cam_from_icrs minimising Σ |b − R r|² (scipy's Kabsch solution)."""
    rot, _ = Rotation.align_vectors(b_cam, r_icrs)
    return rot.as_matrix()
