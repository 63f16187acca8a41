"""Dataset generator of the star-sensor rig (seed 004): star-field frames at drawn attitudes."""

from __future__ import annotations

import numpy as np

from rigsim.dataset.generators.base import parse_sweep
from rigsim.errors import DatasetError


class StarFieldGenerator:
    """Star-sensor frames (seed 004 rigs): FITS images at random (or swept) inertial attitudes.

    The true sensor (f, principal point, distortion, PSF, detector) is the rig file's and fixed for
    the dataset, as on orbit; what is drawn per frame is the attitude (uniform over the sphere) and
    the detector noise. The truth table has **one row per star** imaged on the detector (the frame's
    attitude repeated on each row), so a star pipeline can be scored star by star.
    """

    kind = "star-field"
    seeds = ("004",)
    image_format = "fits"
    description = "star-sensor frames (FITS) at random or swept attitudes; one truth row per star"
    renderers = ("analytic", "mitsuba")
    default_spp = 256

    detector_field = "sensor.resolution_px"  # the rig field that sets pixels_per_frame

    @property
    def pixels_per_frame(self) -> int:
        w, h = self.rig.sensor.resolution_px
        return int(w) * int(h)

    def __init__(self, rig_text: str, rig_source: str = "<rig>", *, spp: int = 256, threads: int | None = None,
                 renderer: str = "analytic"):
        import tomllib

        from rigsim.rig.load import parse_star_rig

        if renderer not in self.renderers:
            raise DatasetError(f"--renderer = {renderer!r}: allowed {', '.join(self.renderers)}")
        self.rig = parse_star_rig(tomllib.loads(rig_text), rig_source)
        self.renderer = renderer
        self.spp = int(spp)  # Mitsuba's samples per pixel (a power of 4); the analytic PSF has none
        if renderer == "mitsuba" and (self.spp & (self.spp - 1) or (self.spp.bit_length() - 1) % 2):
            raise DatasetError(f"--spp = {spp}: the Mitsuba star renderer needs a power of 4 (16, 64, 256, 1024)")
        self.threads = threads
        self._sky = None
        self._mitsuba = None

    def sweepable(self) -> list[str]:
        return ["ra", "dec", "roll"]

    def plan(self, n_frames, sweep, seed) -> list[dict]:
        from scipy.spatial.transform import Rotation

        frames = []
        if sweep:
            grid = parse_sweep(sweep, self.sweepable())
            names = list(grid)
            mesh = np.meshgrid(*[grid[k] for k in names], indexing="ij")
            for row in np.stack([m.ravel() for m in mesh], axis=1):
                a = {"ra": 0.0, "dec": 0.0, "roll": 0.0}
                a.update({k: float(v) for k, v in zip(names, row)})
                if not (-90.0 <= a["dec"] <= 90.0):
                    raise DatasetError(f"--sweep {sweep!r}: dec = {a['dec']} outside [-90, 90]")
                frames.append({"attitude": {"ra_deg": a["ra"], "dec_deg": a["dec"], "roll_deg": a["roll"]}})
        else:
            if n_frames is None or n_frames < 1:
                raise DatasetError("give --frames N (N ≥ 1) or --sweep SPEC")
            for i in range(n_frames):
                rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5E17, i]))
                q = Rotation.random(random_state=rng).as_quat()
                frames.append({"attitude": {"quat_cam_from_icrs_xyzw": q.tolist()}})
        for i, f in enumerate(frames):
            f["seed"] = int(np.random.SeedSequence([seed, 0xF7A3, i]).generate_state(1)[0] & 0x7FFFFFFF)
        return frames

    @staticmethod
    def attitude_matrix(att: dict) -> np.ndarray:
        from scipy.spatial.transform import Rotation

        if "quat_cam_from_icrs_xyzw" in att:
            return Rotation.from_quat(att["quat_cam_from_icrs_xyzw"]).as_matrix()
        from rigsim.optics.attitude import pointing

        return pointing(att["ra_deg"], att["dec_deg"], att["roll_deg"])

    def render(self, index: int, params: dict):
        from scipy.spatial.transform import Rotation

        from rigsim.optics.attitude import boresight_radec
        from rigsim.render.star import render_frame

        if self._sky is None:
            from rigsim.truth.star import StarSky

            self._sky = StarSky(self.rig)
        if self.renderer == "mitsuba" and self._mitsuba is None:
            if self.threads:
                from rigsim.render.backend import set_thread_count

                set_thread_count(int(self.threads))
            from rigsim.render.star import MitsubaStarRenderer

            self._mitsuba = MitsubaStarRenderer(self.rig.sensor, spp=self.spp)
        R = self.attitude_matrix(params["attitude"])
        fr = render_frame(self._sky, R, seed=int(params["seed"]), index=int(index), renderer=self.renderer,
                          mitsuba=self._mitsuba)
        tr = fr.truth
        q = Rotation.from_matrix(R).as_quat()
        ra, dec = boresight_radec(R)
        W, H = self.rig.sensor.resolution_px
        edge = 3.0 * self.rig.sensor.psf_sigma_px
        base = {"frame": int(index), "seed": int(params["seed"]), "qx": q[0], "qy": q[1], "qz": q[2], "qw": q[3],
                "boresight_ra_deg": float(ra), "boresight_dec_deg": float(dec), "n_stars": int(len(tr))}
        rows = []
        for k in range(len(tr)):
            u, v = (float(x) for x in tr.uv[k])
            rows.append({**base, "star": k, "hip": int(tr.hip[k]), "mag": float(tr.mag[k]),
                         "photons": float(tr.photons[k]), "u": u, "v": v,
                         "dir_x": float(tr.dirs_cam[k, 0]), "dir_y": float(tr.dirs_cam[k, 1]),
                         "dir_z": float(tr.dirs_cam[k, 2]),
                         "valid": bool(edge <= u <= W - 1 - edge and edge <= v <= H - 1 - edge
                                       and not np.any(fr.detector.saturated[max(int(v) - 2, 0):int(v) + 3,
                                                                   max(int(u) - 2, 0):int(u) + 3]))})
        if not rows:  # a frame with no star still has a row (its attitude)
            rows.append({**base, "star": -1, "hip": -1, "mag": float("nan"), "photons": 0.0, "u": float("nan"),
                         "v": float("nan"), "dir_x": float("nan"), "dir_y": float("nan"), "dir_z": float("nan"),
                         "valid": False})
        sc = dict(fr.sidecar)  # the one sidecar format; the per-star truth is in the truth table
        sc["truth"] = {"rig": self.rig.name, "R_cam_from_icrs": R.tolist(), "stars": len(tr)}
        sc["fits_header"] = fr.extra["fits_header"]  # the FITS file's WCS and keywords, also here for readers
        sc["dataset"] = {"params": params}
        return fr.dn, sc, rows

    def settings(self) -> dict:
        if self.renderer == "mitsuba":
            return {"renderer": "mitsuba (distorted pinhole, PSF texture per star window)", "spp": self.spp}
        return {"renderer": "analytic pixel-integrated PSF"}
