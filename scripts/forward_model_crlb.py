"""The sun sensor's forward-model centroider against the image's Cramér–Rao bound, per field angle
and per modelled effect (docs/forward-model.md prints this table).

    .venv/bin/python scripts/forward_model_crlb.py [--draws 300] [--seed 1]

For each case the expected image comes from a second method (the disk's equal-solid-angle directions
through the rig's camera, histogrammed on 1/8 px, weighted by the effect, convolved with the pinhole's
PSF on 1/8 px, summed to pixels); frames are drawn from it with the rig's detector model (Poisson
electrons, Gaussian read noise, the gain); each is fitted from a start 0.03 px off by the model built
there; the error is against the disk centre's exact projection. The S-curve moment centroider
(the previous default) is run on the same frames for comparison.
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.signal import fftconvolve

from rigsim.imaging import NoiseModel
from rigsim.imaging.forward_model import fit_spot_model, model_crlb
from rigsim.imaging.frame_spots import measure_frame
from rigsim.optics.sun_disk import disk_directions
from rigsim.optics.sun_spot_model import SunSpotModel
from rigsim.rig import load_rig


def second_method(cam, s, A, origin, W, psf=None, pinhole=None, m=8):
    d = disk_directions(s, A, 400_000)
    uv, _ = cam.project_valid(d)
    w = d[:, 2] * (1.0 if pinhole is None else pinhole.direction_weight(d.T))
    x, y = (uv[:, 0] - origin[0] + 0.5) * m, (uv[:, 1] - origin[1] + 0.5) * m
    img, _, _ = np.histogram2d(y, x, bins=[W * m, W * m], range=[[0, W * m], [0, W * m]], weights=w / w.sum())
    if psf is not None:
        img = fftconvolve(img, psf.kernel(s, cam.fx, cam.fy, W / 2, 1.0 / m), mode="same")
    return img.reshape(W, m, W, m).sum(axis=(1, 3))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--draws", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    rig = load_rig("sun_sensor_3axis_autocollimator")
    cam = rig.sun_sensor.camera()
    A = math.radians(rig.sun_simulator.collimation_full_angle_arcmin / 60.0)
    det = rig.sun_sensor.detector
    noise = NoiseModel.from_detector(det)
    on = rig.effects.model_copy(update={n: getattr(rig.effects, n).model_copy(update={"enabled": True})
                                        for n in ("pinhole_diffraction", "vignetting")})
    psf, pin = on.pinhole_psf(rig.sun_sensor.focal_length_mm), on.thick_pinhole()
    from rigsim.render.cube_mirror.sun_sensor import default_spot_photons

    photons = default_spot_photons(rig)
    rng = np.random.default_rng(a.seed)
    W = 30  # the fit's window; the readout window is 32
    print(f"{a.draws} frames per case; the rig's detector (gain {noise.gain_dn_per_e:g} DN/e-, read noise "
          f"{noise.read_noise_e:g} e-), the spot's photons as the rig's renderer sets them ({photons:.3g} on axis × cos⁴θ)")
    print(f"{'case':<28}{'θ':>5}  {'CRLB u, v (px)':>18}  {'model rms u, v (px)':>20}  {'ratio':>11}  "
          f"{'model bias (px)':>17}  {'scurve rms u, v (px)':>20}  {'scurve kept':>11}")
    for label, kw in (("point pinhole", {}), ("vignetting", {"pinhole": pin}), ("pinhole diffraction", {"psf": psf}),
                      ("diffraction + vignetting", {"psf": psf, "pinhole": pin})):
        for th in (0.5, 20.0, 40.0, 55.0):
            t, p = math.radians(th), math.radians(30.0)
            s = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
            c = cam.project_valid(s[None, :])[0][0]
            # the sensor's readout window is W + 2 px (the renderer keeps its light to ± its half width);
            # the fit takes the W px around the spot, as the sweep does
            origin = np.floor(c + 0.5).astype(int) - W // 2
            ref = second_method(cam, s, A, origin - 1, W + 2, **kw)[1:-1, 1:-1]
            flux_e = photons * det.quantum_efficiency * math.cos(t) ** 4 * ref.sum()
            mu_e = flux_e * ref / ref.sum()
            n = a.draws
            e_ = rng.poisson(mu_e, size=(n, W, W)) + rng.normal(0.0, det.read_noise_e, (n, W, W))
            dn = np.minimum(np.round(e_ * noise.gain_dn_per_e + noise.offset_dn), det.saturation_dn)
            start = c + 0.03
            model = SunSpotModel(cam, A, cam.unproject(start[None, :])[0], origin, (W, W), psf=kw.get("psf"),
                                 pinhole=kw.get("pinhole"))
            fits = [fit_spot_model(d, model, noise, *start) for d in dn]
            e = np.array([[f.u, f.v] for f in fits if f.ok]) - c
            bound = np.sqrt(np.diag(model_crlb(model, *c, flux_e * noise.gain_dn_per_e, noise.offset_dn, noise))[:2])
            rms = np.sqrt(np.mean(e**2, axis=0))
            sc = []
            for d in dn:
                sp = measure_frame(d, noise, method="scurve", saturation_dn=det.saturation_dn, origin_uv=origin)
                if len(sp) and not sp.flags[0] & 259:  # INVALID | SATURATED | EDGE
                    sc.append([sp.u[0], sp.v[0]])
            sc = np.array(sc).reshape(-1, 2) - c
            src = np.sqrt(np.mean(sc**2, axis=0)) if len(sc) else [math.nan, math.nan]
            print(f"{label:<28}{th:>5.1f}  {bound[0]:>8.4f}, {bound[1]:.4f}  {rms[0]:>10.4f}, {rms[1]:.4f}  "
                  f"{rms[0] / bound[0]:>5.2f}, {rms[1] / bound[1]:.2f}  {e.mean(0)[0]:>+8.4f}, {e.mean(0)[1]:+.4f}  "
                  f"{src[0]:>10.4f}, {src[1]:.4f}  {len(sc):>5} / {n}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
