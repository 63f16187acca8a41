"""Lost-in-space identification on rendered frames at random attitudes anywhere on the sky: every
frame identified with no wrong star (against the rendered truth), the same stars as the
commanded-prior identification, and the focal length within 0.02 % of the true one (the nominal is
0.1 % off)."""

import numpy as np
from scipy.spatial.transform import Rotation

from rigsim.estimation.star_id import identify
from rigsim.estimation.star_lis import identify_lost_in_space
from rigsim.imaging.stars import extract_stars


def test_lost_in_space_on_random_attitudes(star_rig, star_sky):
    from rigsim.render.star import render_frame

    nom = star_rig.nominal_rig()
    cam = nom.sensor.camera()
    idc = nom.identification
    kw = idc.lost_in_space_settings()
    kw_prior = {"search_radius_px": idc.search_radius_px, "match_tolerance_px": idc.match_tolerance_px,
                "min_matches": idc.min_matches}
    rots = Rotation.random(8, random_state=7).as_matrix()
    ok = wrong = 0
    for k, R in enumerate(rots):
        fr = render_frame(star_sky, R, seed=100 + k, index=k)
        found = extract_stars(fr.dn, nom.sensor.detector, nom.sensor.psf_sigma_px)
        u = found.subset(np.flatnonzero(found.usable))
        order = np.argsort(-u.flux, kind="stable")
        r = identify_lost_in_space(u.uv[order], star_sky.sky, cam, **kw)
        if not r.ok:
            continue
        ok += 1
        truth = fr.truth
        pos = {int(h): i for i, h in enumerate(truth.hip)}
        uv = u.uv[order]
        wrong += sum(1 for oi, h in zip(r.obs_index, r.hip)
                     if int(h) not in pos or np.linalg.norm(truth.uv[pos[int(h)]] - uv[oi]) > 1.5)
        c = identify(uv, star_sky.sky, R, cam, **kw_prior)  # the prior-based identification of the same stars
        assert set(zip(r.obs_index.tolist(), r.hip.tolist())) == set(zip(c.obs_index.tolist(), c.hip.tolist()))
        # the nominal f is 3 px (0.1 %) long: the fit recovers the true one, and its attitude stays within a
        # fifth of a pixel of the prior-based identification's (which keeps the nominal f)
        d = Rotation.from_matrix(r.R_cam_from_icrs @ c.R_cam_from_icrs.T).magnitude()
        assert np.degrees(d) * 3600 < 0.2 * 206265 / star_rig.sensor.f_px
        assert abs(r.f_px / star_rig.sensor.f_px - 1.0) < 2e-4 < abs(cam.fx / star_rig.sensor.f_px - 1.0)
        assert r.residual_rms_px < 0.3
    assert ok >= 7 and wrong == 0
