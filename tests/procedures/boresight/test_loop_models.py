"""The two loop models against independent derivations: the paper's loop is the exact inverse of
eqs 1-4; the physical loop is today's ray trace bit for bit; the Monte-Carlo noise under each loop
against first-order error propagation (eqs 19-22 / 3, the gain ratios, the physical loop's beta
excess from a finite-difference Jacobian); eq 20's focal-length threshold in both readings."""

import math

import numpy as np
import pytest

from rigsim.estimation.dvad import dvad, estimate, simplified
from rigsim.frames import ARCSEC_PER_RAD as AS
from rigsim.optics.line_camera import CameraGeometry, rotation_xyz, spots_uv
from rigsim.optics.loop_models import loop_spots_uv
from rigsim.procedures.boresight.studies import PARAMS, beta_noise_excess, eq20_focal_threshold, mc_errors, predicted_3sigma
from rigsim.rig.load import load_boresight_rig

G = CameraGeometry.from_rig(load_boresight_rig().cameras[0])
N = 20000                       # relative error of a Monte-Carlo std: 1/sqrt(2N) = 0.5 %
MC_TOL = 4 / math.sqrt(2 * N)   # 4 sigma of the Monte Carlo's own error
NREF = 100


def _states(n, seed, arcsec=20.0, df_um=20.0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, (n, 3)) * arcsec / AS, rng.uniform(-1, 1, n) * df_um * 1e-3


def test_paper_loop_single_axis_displacements_are_the_papers_gains():
    """Closed forms written from eqs 1-4 (consistent reading), beta_h from the detector centres:
    half the angle between (F tan w, +-L/2, -F) is atan(L cos w / (2F))."""
    F, L, w, Kf, d = G.F, G.L_mm, G.off_axis_rad, G.telecentric_factor, G.pitch_mm
    bh = math.atan(L * math.cos(w) / (2 * F))
    a = 7.0 / AS
    ref = loop_spots_uv(G, loop_model="paper")
    np.testing.assert_array_equal(ref, spots_uv(G))                     # same reference spots
    cases = {
        (a, 0, 0, 0): [[0, -2 * F * math.tan(a) / math.cos(bh) ** 2]] * 2,   # eq 2: common y, doubled
        (0, a, 0, 0): [[2 * F * math.tan(a) / math.cos(w) ** 2, 0]] * 2,     # eq 3: common x, doubled
        (0, 0, a, 0): [[L * math.tan(a), 0], [-L * math.tan(a), 0]],         # eq 4: 2a at the lever arm L/2
        (0, 0, 0, 0.004): [[0, 0.004 / Kf * L / F], [0, -0.004 / Kf * L / F]],  # eq 1: y only
    }
    for (al, be, ga, df), exp in cases.items():
        got = (loop_spots_uv(G, rotation_xyz(al, be, ga), df, loop_model="paper") - ref) * d
        np.testing.assert_allclose(got, np.array(exp), rtol=1e-9, atol=1e-12)


def test_simplified_method_inverts_the_paper_loop_exactly():
    ang, df = _states(500, 1)
    meas = loop_spots_uv(G, rotation_xyz(*ang.T), df, loop_model="paper")
    est = simplified(G, G.reference_uv, meas)
    assert np.abs(est.angles_arcsec - ang * AS).max() < 1e-9            # arcsec
    assert np.abs(est.delta_f_mm - df).max() * 1e3 < 1e-9                # µm
    # and it does not invert the physical loop (the test can fail): beta leaks into df there
    phys = simplified(G, G.reference_uv, spots_uv(G, rotation_xyz(*ang.T), df))
    assert np.abs(phys.delta_f_mm - df).max() * 1e3 > 1.0


def test_physical_loop_is_todays_ray_trace_bit_for_bit():
    ang, df = _states(200, 2, 250.0, 200.0)
    E = rotation_xyz(*ang.T)
    for g, tilt in ((G, None), (G.with_(tilt_rad=(0.02, -0.03), reference_xy_px=((150.0, -40.0), (-90.0, 60.0))),
                                (0.021, -0.029))):
        np.testing.assert_array_equal(loop_spots_uv(g, E, df, tilt, loop_model="physical"), spots_uv(g, E, df, tilt))
        np.testing.assert_array_equal(loop_spots_uv(g, E, df, tilt), spots_uv(g, E, df, tilt))
        meas = spots_uv(g, E, df)
        a, b = dvad(g, g.reference_uv, meas), dvad(g, g.reference_uv, meas, loop_model="physical")
        np.testing.assert_array_equal(a.R_hrc, b.R_hrc)
        np.testing.assert_array_equal(a.delta_f_mm, b.delta_f_mm)
    e0 = mc_errors(G, 0.1, 300, np.random.default_rng(3))
    e1 = mc_errors(G, 0.1, 300, np.random.default_rng(3), loop_model="physical")
    for m in ("dvad", "simplified"):
        for p in PARAMS:
            np.testing.assert_array_equal(e0[m][p], e1[m][p])


def test_bad_loop_model():
    with pytest.raises(ValueError, match="loop_model"):
        loop_spots_uv(G, loop_model="papers")
    with pytest.raises(ValueError, match="loop_model"):
        estimate(G, G.reference_uv, G.reference_uv, "dvad", loop_model="exact")


def _gains_physical_over_paper():
    """First-order spot gains of the physical loop over the paper's (docs/boresight.md's table):
    alpha 2F(1/cos w + cos w tan^2 th) vs 2F/cos^2 beta_h; gamma L/cos w vs L; beta and df equal."""
    F, L, w = G.F, G.L_mm, G.off_axis_rad
    th = math.atan(0.5 * L / F)
    bh = math.atan(L * math.cos(w) / (2 * F))
    return {"delta_f_um": 1.0, "alpha_arcsec": (1 / math.cos(w) + math.cos(w) * math.tan(th) ** 2) * math.cos(bh) ** 2,
            "beta_arcsec": 1.0, "gamma_arcsec": 1 / math.cos(w)}


def test_paper_loop_monte_carlo_noise_is_eqs_19_to_22():
    e = mc_errors(G, 0.1, N, np.random.default_rng(5), n_ref=NREF, loop_model="paper",
                  methods=("dvad", "simplified", "dvad_physical_loop"))
    pred = predicted_3sigma(G, 0.1)
    gain = _gains_physical_over_paper()
    for p in PARAMS:
        expect = pred[p] / 3 * math.sqrt(1 + 1 / NREF)
        s_simple = np.std(e["simplified"][p], ddof=1)
        s_dvad = np.std(e["dvad"][p], ddof=1)
        assert s_simple == pytest.approx(expect, rel=MC_TOL), p
        # the paper loop's DVAD on the same draws: its rotation step reads spot motion with the
        # physical gains, so its noise is eqs 19-22's divided by the gain ratio (0.55 % for alpha, gamma)
        assert s_dvad / s_simple == pytest.approx(1 / gain[p], rel=2e-3), p
        assert abs(np.mean(e["simplified"][p])) < 4 * s_simple / math.sqrt(N), p      # exact inverse: unbiased
    # no beta excess under the paper loop ...
    assert np.std(e["dvad"]["beta_arcsec"], ddof=1) / (pred["beta_arcsec"] / 3) < 1.05
    # ... but the physical loop's DVAD on the same spots keeps it: the excess belongs to the estimator
    assert np.std(e["dvad_physical_loop"]["beta_arcsec"], ddof=1) / (pred["beta_arcsec"] / 3) > 1.5


def test_physical_loop_dvad_pays_the_derived_beta_excess():
    """First-order propagation from a finite-difference Jacobian of the exact forward model: the
    x mean and y difference carry (beta, df) together; beta_noise_excess is its closed form."""
    h = 1e-7
    cols = []
    for k in range(4):
        a, df = np.zeros(3), 0.0
        if k < 3:
            a[k] = h
        else:
            df = h
        cols.append(((spots_uv(G, rotation_xyz(*a), df) - spots_uv(G, rotation_xyz(*-a), -df)) / (2 * h)).ravel())
    J = np.array(cols).T                          # px per (rad, rad, rad, mm)
    row_beta = np.linalg.inv(J)[1]                # beta from the four spot coordinates
    excess = np.linalg.norm(row_beta) / (math.cos(G.off_axis_rad) ** 2 * G.pitch_mm / (2 * G.F) / math.sqrt(2))
    assert beta_noise_excess(G) == pytest.approx(excess, rel=1e-4)
    e = mc_errors(G, 0.1, N, np.random.default_rng(6), n_ref=NREF, methods=("dvad",))
    got = np.std(e["dvad"]["beta_arcsec"], ddof=1) / (predicted_3sigma(G, 0.1)["beta_arcsec"] / 3 * math.sqrt(1 + 1 / NREF))
    assert got == pytest.approx(excess, rel=MC_TOL)
    assert 1.55 < got < 1.70


def test_eq20_threshold_fixed_and_reevaluated():
    sigma, target = 0.1, 0.1
    K = 3 * math.sqrt(2) * G.pitch_mm * sigma / (4 * target / AS)
    w, L = G.off_axis_rad, G.L_mm
    fixed = eq20_focal_threshold(G, sigma, target, cos2beta="fixed")
    assert fixed["F_mm"] == pytest.approx(K * math.cos(math.atan(L * math.cos(w) / (2 * G.F))) ** 2, rel=1e-12)
    re = eq20_focal_threshold(G, sigma, target)
    assert re["cos2beta"] == "reevaluated"
    F = re["F_mm"]
    assert F == pytest.approx(K * math.cos(math.atan(L * math.cos(w) / (2 * F))) ** 2, rel=1e-10)
    assert re["beta_half_angle_deg"] == pytest.approx(math.degrees(math.atan(L * math.cos(w) / (2 * F))), rel=1e-9)
    assert F < fixed["F_mm"] - 50.0              # beta grows as F shrinks at fixed L: a lower threshold
    # eq 20 itself at the re-evaluated F is the target
    g = G.with_(focal_length_mm=F)
    assert predicted_3sigma(g, sigma)["alpha_arcsec"] == pytest.approx(target, rel=1e-9)
    with pytest.raises(ValueError, match="cos2beta"):
        eq20_focal_threshold(G, sigma, target, cos2beta="nominal")
