"""DVAD and the simplified method (eqs 1-4) against truths derived outside dvad.py: the paper's loop
(rigsim.optics.loop_models, itself checked against the paper's gains by hand) on a camera whose
detectors and reference spots are not symmetric, closed forms worked by hand for eq 12's columns,
and the exact ray trace (rigsim.optics.line_camera) for the solver's paths."""

import math

import numpy as np
import pytest

from rigsim.estimation.dvad import DVADSolver, dvad, estimate, simplified, triad_columns
from rigsim.frames import ARCSEC_PER_RAD as AS
from rigsim.optics.line_camera import CameraGeometry, rotation_xyz, spots_uv
from rigsim.optics.loop_models import loop_spots_uv
from rigsim.rig.load import load_boresight_rig

G = CameraGeometry.from_rig(load_boresight_rig().cameras[0])
# detectors at +620 / −280 mm (not symmetric about the axis), reference spots off centre with u ≠ v and
# different on the two detectors, untilted (eqs 1-4 ignore the tilts, so the paper's loop is their
# exact inverse only without them)
GA = G.with_(center_y_mm=(620.0, -280.0), tilt_rad=(0.0, 0.0), reference_xy_px=((130.0, -70.0), (-45.0, 95.0)))


def _states(n, seed, arcsec=40.0, df_um=50.0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, (n, 3)) * arcsec / AS, rng.uniform(-1, 1, n) * df_um * 1e-3


def test_simplified_inverts_the_paper_loop_on_an_asymmetric_camera():
    ang, df = _states(300, 11)
    meas = loop_spots_uv(GA, rotation_xyz(*ang.T), df, loop_model="paper")
    est = simplified(GA, GA.reference_uv, meas)
    assert np.abs(est.angles_rad - ang).max() < 1e-14
    assert np.abs(est.delta_f_mm - df).max() < 1e-12
    # as printed: eq 2's opposite sign; eq 1's and eq 4's L as the unsigned distances |Lc1| + |Lc2| = 900 mm
    p = simplified(GA, GA.reference_uv, meas, "as_printed")
    assert np.abs(p.alpha_rad + ang[:, 0]).max() < 1e-14
    assert np.abs(p.angles_rad[:, 1:] - ang[:, 1:]).max() < 1e-14
    assert np.abs(p.delta_f_mm - df).max() < 1e-12


def test_simplified_as_printed_takes_the_unsigned_distances_on_a_one_sided_camera():
    """Both detectors on the same side (+700, +200 mm): the consistent L = Lc1 − Lc2 = 500 mm inverts the paper's
    loop; the printed |Lc1| + |Lc2| = 900 mm scales eq 1's Δf and eq 4's tan γ by 500/900."""
    g = GA.with_(center_y_mm=(700.0, 200.0))
    ang, df = _states(50, 16)
    meas = loop_spots_uv(g, rotation_xyz(*ang.T), df, loop_model="paper")
    est = simplified(g, g.reference_uv, meas)
    assert np.abs(est.angles_rad - ang).max() < 1e-14 and np.abs(est.delta_f_mm - df).max() < 1e-12
    p = simplified(g, g.reference_uv, meas, "as_printed")
    np.testing.assert_allclose(p.delta_f_mm, df * 500 / 900, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.tan(p.gamma_rad), np.tan(ang[:, 2]) * 500 / 900, rtol=0, atol=1e-14)
    np.testing.assert_allclose(p.beta_rad, ang[:, 1], rtol=0, atol=1e-14)


def test_paper_loop_dvad_takes_eq15_and_removes_the_focal_shift():
    """The paper's loop puts Δf only in the spots' antisymmetric y shift, s·(Δf/Kf)·L/F: eq 15 in eq 1's form
    returns Δf exactly, and once the shift is removed a pure Δf leaves the spots where they were (no rotation)."""
    ang, df = _states(200, 12)
    for g in (GA, G):
        est = dvad(g, g.reference_uv, loop_spots_uv(g, rotation_xyz(*ang.T), df, loop_model="paper"),
                   loop_model="paper")
        assert np.abs(est.delta_f_mm - df).max() < 1e-12
        np.testing.assert_allclose(est.info["loop_focal_change_mm"], df / g.telecentric_factor, rtol=0, atol=2e-12)
        pure = dvad(g, g.reference_uv, loop_spots_uv(g, None, df, loop_model="paper"), loop_model="paper")
        assert np.abs(pure.delta_f_mm - df).max() < 1e-12
        assert np.abs(pure.angles_rad).max() < 1e-14
        assert np.abs(pure.R_hrc - np.eye(3)).max() < 1e-14


def test_triad_columns_by_hand_batched_and_of_any_length():
    # first row: a = 3x, b = 0.5y; eq 12 sums the vectors as given, a + b = (3, 0.5, 0): c1 = z,
    # c2 = (6, 1, 0)/√37, c3 = c1 × c2 = (−1, 6, 0)/√37 (the columns of the expected matrix)
    a = np.array([[3.0, 0, 0], [0, 0, 2.0]])
    b = np.array([[0, 0.5, 0], [4.0, 0, 0]])
    got = triad_columns(a, b)
    r = math.sqrt(37.0)
    # second row: a = 2z, b = 4x: c1 = z × x = y, c2 = (4, 0, 2)/√20, c3 = y × c2 = (2, 0, −4)/√20
    s = math.sqrt(20.0)
    exp = np.array([[[0, 6 / r, -1 / r], [0, 1 / r, 6 / r], [1, 0, 0]],
                    [[0, 4 / s, 2 / s], [1, 0, 0], [0, 2 / s, -4 / s]]])
    np.testing.assert_allclose(got, exp, rtol=0, atol=1e-15)


def test_estimate_dispatches_to_each_method():
    """estimate(method=…) inverts the exact ray trace (DVAD, with its keywords) and the paper's loop (the
    simplified method, which takes loop_model and refuses an unknown one)."""
    ang, df = _states(20, 17)
    est = estimate(G, G.reference_uv, spots_uv(G, rotation_xyz(*ang.T), df), method="dvad", iterations=4)
    assert est.method == "dvad" and np.abs(est.angles_rad - ang).max() < 1e-12
    meas = loop_spots_uv(GA, rotation_xyz(*ang.T), df, loop_model="paper")
    for kw in ({}, {"loop_model": "paper"}, {"loop_model": "physical"}):
        est = estimate(GA, GA.reference_uv, meas, "simplified", **kw)
        assert est.method == "simplified" and np.abs(est.angles_rad - ang).max() < 1e-14
    with pytest.raises(ValueError, match="loop_model"):
        estimate(GA, GA.reference_uv, meas, "simplified", loop_model="exact")


def test_estimate_refuses_every_unknown_method():
    with pytest.raises(TypeError):                  # iterations and loop_model are keyword-only
        dvad(G, G.reference_uv, G.reference_uv, "consistent", 2)
    for m in ("quest", "batch", "triad", ""):      # names on both sides of "dvad" and "simplified"
        with pytest.raises(ValueError, match="method"):
            estimate(G, G.reference_uv, G.reference_uv, method=m)


def test_estimate_units_and_rotation_of_the_simplified_method():
    """as_dict: µm and arcsec (1 rad = 180·3600/π arcsec), one sample by index; rotation() of an estimate
    without DVAD's matrix is Rx(α)·Ry(β)·Rz(γ) (scipy's intrinsic "XYZ")."""
    from scipy.spatial.transform import Rotation

    ang, df = _states(4, 13)
    est = simplified(GA, GA.reference_uv, loop_spots_uv(GA, rotation_xyz(*ang.T), df, loop_model="paper"))
    arcsec = 180 * 3600 / math.pi
    d = est.as_dict()
    np.testing.assert_allclose(d["delta_f_um"], df * 1e3, rtol=1e-10)
    for k, name in enumerate(("alpha", "beta", "gamma")):
        np.testing.assert_allclose(d[f"{name}_arcsec"], ang[:, k] * arcsec, rtol=1e-10)
    np.testing.assert_allclose(est.angles_arcsec, ang * arcsec, rtol=1e-10)
    one = est.as_dict(index=2)
    assert one["method"] == "simplified" and one["reading"] == "consistent"
    assert one["beta_arcsec"] == pytest.approx(ang[2, 1] * arcsec, rel=1e-10)
    assert one["delta_f_um"] == pytest.approx(df[2] * 1e3, rel=1e-10)
    np.testing.assert_allclose(est.rotation(), Rotation.from_euler("XYZ", ang).as_matrix(), rtol=0, atol=1e-15)
    # DVAD's own matrix is returned as it is
    dv = dvad(G, G.reference_uv, spots_uv(G, rotation_xyz(*ang.T), df))
    assert dv.rotation() is dv.R_hrc


def test_solver_with_its_default_reference_and_with_a_batch_of_references():
    """DVADSolver(geom) takes the design reference spots; a reference per sample (n, 2, 2) is accepted (a
    (n, 1, 2) one refused), and both invert the exact ray trace (to 1e-9 mm and 1e-12 rad: the round trip)."""
    ang, df = _states(3, 14, 200.0, 150.0)
    meas = spots_uv(G, rotation_xyz(*ang.T), df)
    refs = np.repeat(G.reference_uv[None], 3, axis=0)
    for solver in (DVADSolver(G), DVADSolver(G, ref_uv=refs)):
        est = solver.solve(meas)
        assert np.abs(est.angles_rad - ang).max() < 1e-12 and np.abs(est.delta_f_mm - df).max() < 1e-9
    with pytest.raises(TypeError):                  # iterations and loop_model are keyword-only
        DVADSolver(G, refs, 2)
    # shapes on both sides of (2, 2) in tuple order
    for bad in (np.zeros((3, 1, 2)), np.zeros((2, 3)), np.zeros((3, 2))):
        with pytest.raises(ValueError, match="ref_uv must have shape"):
            DVADSolver(G, bad)
        with pytest.raises(ValueError, match="meas_uv must have shape"):
            DVADSolver(G).solve(bad)
        for f in (dvad, simplified):
            with pytest.raises(ValueError, match="meas_uv must have shape"):
                f(G, G.reference_uv, bad)
            with pytest.raises(ValueError, match="ref_uv must have shape"):
                f(G, bad, G.reference_uv)


def test_as_printed_dvad_against_the_printed_equations_with_scipy():
    """The printed eqs 11-14 on large rotations (up to 1.5° per axis, where eq 14's tan-of-asin and its
    ratios differ from their first order) and a batch: M_Rot by scipy's align_vectors (Wahba's problem on the
    printed triad's two orthogonal vectors, the normal and the bisector of the unnormalised v'' = (x, y, −F),
    solved exactly), then eq 14 as printed."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(15)
    ang = rng.uniform(-1.5, 1.5, (5, 3)) * math.pi / 180
    df = rng.uniform(-0.2, 0.2, 5)
    g = G.with_(tilt_rad=(0.01, -0.02))
    meas = spots_uv(g, rotation_xyz(*ang.T), df)
    got = dvad(g, g.reference_uv, meas, reading="as_printed")
    # the same with a reference per sample (M0 then a batch of matrices too)
    per = dvad(g, np.repeat(g.reference_uv[None], 5, axis=0), meas, reading="as_printed")
    np.testing.assert_allclose(per.angles_rad, got.angles_rad, rtol=1e-12, atol=1e-18)
    F, w = g.F, g.off_axis_rad
    P0, P = g.xy_to_focal(g.uv_to_xy(g.reference_uv)), g.xy_to_focal(g.uv_to_xy(meas))

    def pair(Q):
        a, b = (np.array([Q[j, 0], Q[j, 1], -F]) for j in (0, 1))
        n = np.cross(a, b)
        return np.array([n / np.linalg.norm(n), (a + b) / np.linalg.norm(a + b)])

    for k in range(5):
        M = Rotation.align_vectors(pair(P[k]), pair(P0))[0].as_matrix()
        rx, rz = -M[2, 1] / M[2, 2], -M[1, 0] / M[0, 0]
        exp = [0.5 * (rx * math.cos(w) + rz * math.sin(w)), 0.5 * math.tan(math.asin(M[2, 0])),
               0.5 * (rx * math.sin(w) + rz * math.cos(w))]
        np.testing.assert_allclose(got.angles_rad[k], exp, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(got.info["M_rot_ota"][k], M, rtol=0, atol=1e-12)
        # eq 15 as printed, the sign kept: −(Kf/2)·F·(Δy1 − Δy2)/(y1 − y2) of the focal-plane points
        dy = (P[k, 0, 1] - P0[0, 1]) - (P[k, 1, 1] - P0[1, 1])
        assert got.delta_f_mm[k] == pytest.approx(-g.telecentric_factor / 2 * F * dy / (P0[0, 1] - P0[1, 1]), rel=1e-12)
