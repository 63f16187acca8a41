"""Star frames in FITS carry the true camera's WCS (TAN with SIP distortion) and the exposure keywords: astropy
places every catalogue star of the frame on its true pixel (0-based, rigsim's convention) to 0.05 px, and the
header's CRPIX is the principal point + 1 (FITS's 1-based pixels)."""

import numpy as np
import pytest
from astropy.coordinates import SkyCoord
from astropy.io import fits
from astropy.wcs import WCS
from scipy.spatial.transform import Rotation

from rigsim.optics.wcs import camera_wcs
from rigsim.rig.load import load_star_rig
from rigsim.truth.star import StarSky


@pytest.mark.parametrize("k", range(4))
def test_the_wcs_puts_every_catalogue_star_on_its_true_pixel(k):
    import astropy.units as u

    rig = load_star_rig()
    sky = StarSky(rig)
    R = Rotation.random(random_state=k).as_matrix()
    f = sky.field(R)
    w = camera_wcs(rig.sensor.camera(), R)
    d = f.dirs_icrs
    c = SkyCoord(np.degrees(np.arctan2(d[:, 1], d[:, 0])) * u.deg, np.degrees(np.arcsin(d[:, 2])) * u.deg, frame="icrs")
    x, y = w.world_to_pixel(c)
    err = np.hypot(x - f.uv[:, 0], y - f.uv[:, 1])
    assert len(err) > 20 and err.max() < 0.05, err.max()  # measured 6e-6 px
    assert w.wcs.crpix[0] == pytest.approx(rig.sensor.principal_point_px[0] + 1)


def test_a_dataset_star_frame_has_the_header(tmp_path):
    import astropy.units as u

    from rigsim.dataset.reader import open_dataset
    from rigsim.dataset.runner import generate

    generate("star_sensor", tmp_path, frames=1, seed=4, progress=False, workers=1)
    with fits.open(tmp_path / "frames" / "frame_000000.fits") as h:
        hdr = h[0].header
        w = WCS(hdr)
    rig = load_star_rig()
    assert hdr["CTYPE1"] == "RA---TAN-SIP" and hdr["BUNIT"] == "adu" and hdr["PIXCONV"] == "FITS 1-based"
    assert hdr["EXPTIME"] == rig.sensor.detector.exposure_s
    assert hdr["GAIN"] == pytest.approx(1 / rig.sensor.detector.gain_dn_per_e)
    from astropy.time import Time

    assert abs((Time(hdr["DATE-OBS"], scale="utc") - Time("J2025.0")).sec) < 1.0  # the rig's epoch (a Julian year)
    assert "A_ORDER" in hdr and "AP_ORDER" in hdr
    t = open_dataset(tmp_path).truth_numpy()
    sel = t["star"] >= 0
    d = np.stack([t["dir_x"][sel], t["dir_y"][sel], t["dir_z"][sel]], axis=1)
    R = np.array(__import__("json").loads((tmp_path / "frames" / "frame_000000.json").read_text())["truth"]["R_cam_from_icrs"])
    di = d @ R  # camera → ICRS
    c = SkyCoord(np.degrees(np.arctan2(di[:, 1], di[:, 0])) * u.deg, np.degrees(np.arcsin(di[:, 2])) * u.deg, frame="icrs")
    x, y = w.world_to_pixel(c)
    assert np.max(np.hypot(x - t["u"][sel], y - t["v"][sel])) < 0.05
