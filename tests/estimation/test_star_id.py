"""Identification near an approximate attitude: correct within its limits, a clear failure beyond."""

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.estimation.star_id import identify
from rigsim.imaging.stars import extract_stars
from rigsim.optics import attitude as att
from rigsim.render.star import render_frame


def test_identification_limits(star_rig, star_sky):
    s = star_rig.sensor
    seq = att.from_rig(star_rig.sequence)
    fr = render_frame(star_sky, seq.R_cam_from_icrs[0], seed=11, omega_cam_rad_s=seq.omega_cam_rad_s[0], substeps=4)
    obs = extract_stars(fr.dn, s.detector, s.psf_sigma_px)
    uv = obs.uv[obs.usable]
    nom = star_rig.nominal_rig().sensor
    nominal = nom.camera()  # f 3 px off, principal point at the detector centre
    truth = dict(zip(fr.truth.hip.tolist(), fr.truth.uv))
    rng = np.random.default_rng(2)
    for err_deg in (0.1, 0.5, 1.0):  # within the 60 px (≈1.2°) search radius: every star right
        ax = rng.normal(size=3)
        Rp = Rotation.from_rotvec(np.radians(err_deg) * ax / np.linalg.norm(ax)).as_matrix() @ fr.truth.R_cam_from_icrs
        r = identify(uv, star_sky.sky, Rp, nominal, search_radius_px=60.0)
        assert r.ok and len(r) >= 0.95 * len(uv)
        wrong = [h for h, o in zip(r.hip, r.obs_index) if h not in truth or np.linalg.norm(truth[h] - uv[o]) > 1.0]
        assert wrong == []
        # the fitted attitude absorbs the nominal camera's principal-point error (a shift of the
        # principal point by Δ is a rotation by |Δ|/f: 4.0 px / 2887 px = 289″); the rest (f off by
        # 3 px, centroid noise) stays below 30″
        ang = np.degrees(Rotation.from_matrix(r.R_cam_from_icrs @ fr.truth.R_cam_from_icrs.T).magnitude()) * 3600
        expected = np.degrees(np.hypot(*(np.subtract(s.principal_point_px, nom.principal_point_px))) / s.f_px) * 3600
        assert abs(ang - expected) < 30, (ang, expected)
    Rp = Rotation.from_rotvec([np.radians(4.0), 0, 0]).as_matrix() @ fr.truth.R_cam_from_icrs
    r = identify(uv, star_sky.sky, Rp, nominal, search_radius_px=60.0)
    assert not r.ok and r.reason  # 4° ≫ search radius: reported, not a wrong match


def test_identification_takes_the_catalogue_not_the_true_sky(star_rig, star_sky):
    """The true sky (StarSky) holds the true camera: identification refuses it."""
    import pytest

    with pytest.raises(TypeError, match="SkyCatalogue"):
        identify(np.zeros((5, 2)), star_sky, np.eye(3), star_rig.nominal_rig().sensor.camera())
