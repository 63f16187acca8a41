"""Step 1/B on rendered frames: centroids vs exact truth, and the fit against the true R(sun←rot)."""

import numpy as np

from rigsim.frames import ARCSEC_PER_RAD, small_angle_error
from rigsim.procedures.cube_mirror.sweep import calibrate_from_sweep, render_sweep
from rigsim.rig import load_rig
from rigsim.truth.cube_mirror.realization import Noise, realization_from_rig


def test_coarse_rendered_sweep_recovers_the_sensor():
    rig = load_rig("sun_sensor_2axis_diaphragm")
    rig = rig.model_copy(update={"procedure": rig.procedure.model_copy(update={"sweep_step_deg": 12.0})})
    real = realization_from_rig(rig, ideal=True)
    sw, truth = render_sweep(rig, real, Noise(), seed=4, spp=256)
    assert len(sw.uv) >= 60
    err = sw.uv - truth.uv_pixel_centroid
    # thresholded CoM on a 2.7-px disk: rendering noise + detector noise + CoM phase bias ≈ 0.01 px
    assert np.sqrt(np.mean(err**2)) < 0.02
    cal = calibrate_from_sweep(rig, sw)
    e = small_angle_error(cal.R_sun_from_rot, real.R_sun_from_mount) * ARCSEC_PER_RAD
    sig = np.sqrt(np.diag(cal.covariance))[-3:] * ARCSEC_PER_RAD
    assert np.all(np.abs(e) < 4 * sig + 0.1), (e, sig)
    assert np.all(sig < 10.0)
