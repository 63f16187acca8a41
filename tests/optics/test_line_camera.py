"""Exact forward model of seed 003 against independent first-order derivations.

Independent model used here (not the code's reflection formula): to first order a camera
rotation δ (HRC) turns every returning beam by −2δ (each facet is an autocollimator), i.e. the
return vector v = (x, y, −F) (OTA) gets dv = ω × v with ω = −2·R_ota_from_hrc·δ, and the spot is
the central projection p = F·(v_x, v_y)/(−v_z).
"""

import math

import numpy as np
import pytest

from rigsim.optics.line_camera import CameraGeometry, facet_normals_ota, loop_trace, rotation_xyz, spots_uv
from rigsim.rig.load import load_boresight_rig

RIG = load_boresight_rig()
G = CameraGeometry.from_rig(RIG.cameras[0])


def _first_order_shift_px(g, delta_hrc):
    """Spot shift (2 detectors, [dx, dy]) in px from the independent first-order model."""
    om = -2.0 * g.R_ota_from_hrc @ np.asarray(delta_hrc, float)
    out = np.zeros((2, 2))
    for j, e in enumerate(g.emitter_mm):
        v = np.array([e[0], e[1], -g.F])
        dv = np.cross(om, v)
        dp = g.F * (dv[:2] * (-v[2]) + v[:2] * dv[2]) / v[2] ** 2
        out[j] = dp / g.pitch_mm
    return out


def test_frames():
    # Z_HRC points from the CCD centre (F tan w, 0, -F) to O; Y_HRC = Y_OTA
    z = G.R_ota_from_hrc @ [0, 0, 1.0]
    ccd = np.array([G.F * math.tan(G.off_axis_rad), 0.0, -G.F])
    np.testing.assert_allclose(z, -ccd / np.linalg.norm(ccd), atol=1e-15)
    np.testing.assert_allclose(G.R_ota_from_hrc @ [0, 1.0, 0], [0, 1, 0], atol=1e-15)
    # eq 11 with d: one pixel is 10 um in the focal plane; round trip px <-> mm
    xy = np.array([[12.25, -7.5], [-300.0, 41.0]])
    P = G.xy_to_focal(xy)
    np.testing.assert_allclose(P[0] - G.centers_mm[0], 0.010 * xy[0], atol=1e-12)
    np.testing.assert_allclose(G.focal_to_xy(P), xy, atol=1e-9)
    Gt = G.with_(tilt_rad=(0.01, -0.02))
    np.testing.assert_allclose(Gt.focal_to_xy(Gt.xy_to_focal(xy)), xy, atol=1e-9)


def test_reference_spots_land_on_the_reference_points():
    # autocollimation: each facet is normal to its own beam at the reference
    np.testing.assert_allclose(spots_uv(G), G.reference_uv, atol=1e-9)
    g2 = G.with_(reference_xy_px=((120.0, -35.0), (-80.0, 400.0)))
    np.testing.assert_allclose(spots_uv(g2), g2.reference_uv, atol=1e-9)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_rotation_sensitivity_matches_first_order_model(axis):
    d = np.zeros(3)
    d[axis] = 2e-7  # 0.04": second-order terms are ~2e-7 relative
    got = spots_uv(G, rotation_xyz(*d)) - G.reference_uv
    exp = _first_order_shift_px(G, d)
    assert np.abs(got - exp).max() <= 1e-5 * np.abs(exp).max() + 1e-10


def test_first_order_gains_and_the_papers_gains():
    """Closed-form first-order gains of the off-axis loop (docs/boresight.md, 'Gains'):
    alpha: dy = -2aF(1/cos w + cos w tan^2 t), t = atan(Lc/F); beta: dx = 2bF/cos^2 w;
    gamma: dx = +-2g(L/2)/cos w, dy = 2g sin(w) Lc^2/F. The paper's eq 3 is exact; eqs 2 and 4 use 1/cos^2(beta) and 1,
    which are 0.55 % off with w = 6 deg (a first-order error of the simplified method)."""
    a = 1e-7
    w, F, d = G.off_axis_rad, G.F, G.pitch_mm
    t = math.atan(500.0 / F)
    s = spots_uv(G, rotation_xyz(a, 0, 0)) - G.reference_uv
    exact = -2 * a * F * (1 / math.cos(w) + math.cos(w) * math.tan(t) ** 2) / d
    assert s[:, 1] == pytest.approx([exact, exact], rel=1e-5)
    paper = -2 * F * a / math.cos(G.beta_half_angle_rad) ** 2 / d
    assert exact / paper - 1 == pytest.approx(0.0055, abs=2e-4)
    s = spots_uv(G, rotation_xyz(0, a, 0)) - G.reference_uv
    assert s[:, 0] == pytest.approx([2 * F * a / math.cos(w) ** 2 / d] * 2, rel=1e-5)
    s = spots_uv(G, rotation_xyz(0, 0, a)) - G.reference_uv
    assert (s[0, 0] - s[1, 0]) / 2 * d == pytest.approx(a * G.L_mm / math.cos(w), rel=1e-5)
    # and a small common y shift 2 g sin(w) Lc^2 / F (a 7e-4 crosstalk into alpha for the simplified method)
    assert s[:, 1] * d == pytest.approx([2 * a * math.sin(w) * 500.0 ** 2 / F] * 2, rel=1e-4)


def test_focal_change_moves_the_ends_apart_as_eq_1_says():
    df = 1e-4  # mm
    s = spots_uv(G, None, df) - G.reference_uv
    # eq 1 inverted: (dy1 - dy2)/2 * d = df * L / (Kf * F)
    assert (s[0, 1] - s[1, 1]) / 2 * G.pitch_mm == pytest.approx(df * G.L_mm / (G.telecentric_factor * G.F), rel=1e-4)
    # and both spots move outward in x by (2/Kf)(df/F) F tan(w): the off-axis field
    assert s[:, 0] * G.pitch_mm == pytest.approx([2 / G.telecentric_factor * df * math.tan(G.off_axis_rad)] * 2, rel=1e-4)


def test_a_plane_mirror_is_blind_to_rotation_about_its_normal():
    f_ota = facet_normals_ota(G)
    for j in range(2):
        axis_hrc = G.R_ota_from_hrc.T @ f_ota[j]
        from scipy.spatial.transform import Rotation
        E = Rotation.from_rotvec(5e-4 * axis_hrc).as_matrix()     # 103": large
        s = spots_uv(G, E) - G.reference_uv
        assert np.abs(s[j]).max() < 1e-8       # this path's spot does not move at all
        assert np.abs(s[1 - j]).max() > 5.0    # the other facet sees it


def _jacobian(g, facets=None):
    x0 = loop_trace(g, None, 0.0, facet_normals=facets).ravel()
    J = []
    h = 1e-7
    for k in range(4):
        p = np.zeros(4)
        p[k] = h
        J.append((loop_trace(g, rotation_xyz(*p[1:]), p[0], facet_normals=facets).ravel() - x0) / h)
    return np.array(J).T


def _independence(J):
    J = J / np.maximum(np.linalg.norm(J, axis=0), 1e-300)   # unit columns: units of df and angles drop out
    return np.linalg.svd(J, compute_uv=False)[-1]


def test_gamma_is_observable_only_because_the_two_facets_differ():
    # four unknowns (df, alpha, beta, gamma), four spot coordinates: full rank. The weakest
    # direction is gamma against beta/df (lever arm L vs F): ~0.05 with Table 2
    assert _independence(_jacobian(G)) > 0.01
    # one common facet for both paths (normal to the field centre, Z_HRC): the rotation about it
    # moves nothing and the rank drops to 3
    n = G.R_ota_from_hrc @ [0, 0, -1.0]
    assert _independence(_jacobian(G, np.array([n, n]))) < 1e-6
