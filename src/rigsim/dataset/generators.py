"""Frame generators: one per kind of frame a rig produces.

A generator is built from the rig file's *text* (so a worker on another machine rebuilds exactly
the same rig) and turns (frame index, frame parameters, seed) into (uint16 image, sidecar, one
row of the truth table). :meth:`plan` draws every frame's parameters up front from the dataset
seed (``SeedSequence([seed, index])``), so the dataset does not depend on worker count, order or
restarts.

Registered generators (``GENERATORS``; ``--generator``):

* ``sun-sensor`` (cube-mirror rigs, seeds 000/001; default): full 1024² sun-sensor frames at
  turntable poses drawn uniformly over the sweep range (only poses whose sun lands on the
  detector), each with its own draw of the rig's errors — turntable non-perpendicularity
  (``turntable.perpendicularity_sigma_arcsec``) and encoder noise (each axis'
  ``encoder_sigma_arcsec``; the *reading* is recorded next to the true angle).

Other rigs register theirs with :func:`register`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from rigsim.errors import DatasetError

GENERATORS: dict[str, type] = {}


def register(cls):
    GENERATORS[cls.kind] = cls
    return cls


def parse_sweep(spec: str, allowed: list[str]) -> dict[str, np.ndarray]:
    """``"X=-60:60:5 Y=0,10,20"`` → {axis: values (deg)}; ranges are inclusive of both ends."""
    out: dict[str, np.ndarray] = {}
    for part in spec.replace(";", " ").split():
        if "=" not in part:
            raise DatasetError(f"--sweep {spec!r}: '{part}' is not NAME=VALUES (e.g. X=-60:60:5 or Y=0,10,20)")
        name, vals = part.split("=", 1)
        if name not in allowed:
            raise DatasetError(f"--sweep {spec!r}: '{name}' is not sweepable; allowed: {', '.join(allowed)}")
        try:
            if ":" in vals:
                a, b, s = (float(x) for x in vals.split(":"))
                if s <= 0 or b < a:
                    raise ValueError
                n = int(math.floor((b - a) / s + 1e-9)) + 1
                if n > 100000:
                    raise DatasetError(f"--sweep {spec!r}: {name} has {n} values (max 100000)")
                v = a + s * np.arange(n)
            else:
                v = np.array([float(x) for x in vals.split(",")])
        except ValueError:
            raise DatasetError(f"--sweep {spec!r}: '{vals}' must be START:STOP:STEP (STEP > 0, STOP ≥ START) "
                               "or a comma list of numbers") from None
        out[name] = v
    if not out:
        raise DatasetError(f"--sweep {spec!r}: empty")
    return out


@register
class SunSensorGenerator:
    kind = "sun-sensor"
    image_format = "png"
    description = "full sun-sensor frames at random (or swept) turntable poses, rig errors drawn per frame"

    def __init__(self, rig_text: str, rig_source: str = "<rig>", *, spp: int = 1024, threads: int | None = None):
        import tomllib

        from rigsim.rig.load import parse_rig

        self.rig = parse_rig(tomllib.loads(rig_text), rig_source)
        self.spp = int(spp)
        self.threads = threads
        self._scene = None

    # -- planning (numpy only) ---------------------------------------------------------------
    def sweepable(self) -> list[str]:
        return [a.label for a in self.rig.turntable.axes]

    def _on_detector(self, pose_deg: dict) -> bool:
        from rigsim.optics.camera import PinholeBrown
        from rigsim.truth.cube_mirror.realization import realization_from_rig

        if not hasattr(self, "_plan_real"):
            self._plan_real = realization_from_rig(self.rig, ideal=True)
            self._plan_cam = PinholeBrown.from_sun_sensor(self.rig.sun_sensor)
        real = self._plan_real
        pose = {k: math.radians(v) for k, v in pose_deg.items()}
        s = real.R_sun_from_mount @ (real.turntable.R_rot_from_mount(pose).T @ real.d_sun_rot)
        if s[2] <= 0.05:
            return False
        uv = self._plan_cam.project(s[None, :])
        return bool(self._plan_cam.on_detector(uv, margin_px=8.0)[0])

    def _draws(self, rng: np.random.Generator) -> dict:
        tt = self.rig.turntable
        perp = rng.normal(0.0, tt.perpendicularity_sigma_arcsec, max(len(tt.axes) - 1, 0)).tolist()
        enc = {a.label: float(rng.normal(0.0, a.encoder_sigma_arcsec)) for a in tt.axes}
        return {"perpendicularity_arcsec": perp, "encoder_error_arcsec": enc}

    def plan(self, n_frames: int | None, sweep: str | None, seed: int) -> list[dict]:
        labels = [a.label for a in self.rig.turntable.axes]
        rng_range = self.rig.procedure.sweep_range_deg
        frames = []
        if sweep:
            grid = parse_sweep(sweep, labels)
            names = list(grid)
            mesh = np.meshgrid(*[grid[k] for k in names], indexing="ij")
            combos = np.stack([m.ravel() for m in mesh], axis=1)
            for row in combos:
                pose = {lab: 0.0 for lab in labels}
                pose.update({k: float(v) for k, v in zip(names, row)})
                if self._on_detector(pose):
                    frames.append({"pose_true_deg": pose})
        else:
            if n_frames is None or n_frames < 1:
                raise DatasetError("give --frames N (N ≥ 1) or --sweep SPEC")
            for i in range(n_frames):
                rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5E17, i]))
                for _ in range(1000):
                    pose = {lab: 0.0 for lab in labels}
                    for k in self.rig.procedure.sweep_axes:
                        pose[k] = float(rng.uniform(-rng_range, rng_range))
                    if self._on_detector(pose):
                        break
                frames.append({"pose_true_deg": pose})
        for i, f in enumerate(frames):
            rng = np.random.default_rng(np.random.SeedSequence([seed, 0xD7A5, i]))
            f["draws"] = self._draws(rng)
            f["seed"] = int(np.random.SeedSequence([seed, 0xF7A3, i]).generate_state(1)[0] & 0x7FFFFFFF)
        return frames

    # -- rendering (worker side) ---------------------------------------------------------------
    def _real(self, draws: dict):
        from rigsim.frames import RAD_PER_ARCSEC
        from rigsim.truth.cube_mirror.realization import (
            perpendicularity_perturbed,
            realization_from_rig,
        )

        real = realization_from_rig(self.rig, ideal=True)
        real.turntable = perpendicularity_perturbed(
            real.turntable, [e * RAD_PER_ARCSEC for e in draws["perpendicularity_arcsec"]])
        return real

    def render(self, index: int, params: dict):
        import warnings

        if self._scene is None:
            if self.threads:
                from rigsim.render.backend import set_thread_count

                set_thread_count(int(self.threads))
            from rigsim.render.cube_mirror.sun_sensor import SunSensorScene

            self._scene = SunSensorScene(self.rig, spp=self.spp)
        real = self._real(params["draws"])
        self._scene.real = real
        pose_deg = params["pose_true_deg"]
        pose = {k: math.radians(v) for k, v in pose_deg.items()}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fr = self._scene.render(pose, seed=int(params["seed"]), full_frame=True, truth_points=200_000)
        sc = dict(fr.sidecar)
        enc = params["draws"]["encoder_error_arcsec"]
        reading = {k: v + enc.get(k, 0.0) / 3600.0 for k, v in pose_deg.items()}
        sc["dataset"] = {"params": params, "reading_deg": reading, "warnings": [str(w.message) for w in caught]}
        spot = sc["truth"]["spot"] if isinstance(sc["truth"].get("spot"), dict) else {}
        valid = bool(spot.get("valid", True)) and "center_uv" in spot
        s = sc["truth"]["sun_dir_cam"]
        flags = sc.get("flags", {})
        row = {"frame": int(index), "seed": int(params["seed"])}
        for k in sorted(pose_deg):
            row[f"pose_{k}_true_deg"] = float(pose_deg[k])
            row[f"pose_{k}_read_deg"] = float(reading[k])
        row.update({"sun_x": s[0], "sun_y": s[1], "sun_z": s[2]})
        for name, key in (("spot", "center_uv"), ("spot_centroid", "pixel_centroid_uv"), ("spot_mean", "mean_uv")):
            uv = spot.get(key) if valid else None
            row[f"{name}_u"] = float(uv[0]) if uv else float("nan")
            row[f"{name}_v"] = float(uv[1]) if uv else float("nan")
        row["valid"] = valid and not flags.get("spot_cut_by_edge", False) and not flags.get("saturated", False)
        for k in ("spot_off_detector", "spot_cut_by_edge", "saturated"):
            row[k] = bool(flags.get(k, False))
        for j, e in enumerate(params["draws"]["perpendicularity_arcsec"]):
            row[f"draw_perpendicularity_{j}_arcsec"] = float(e)
        for k in sorted(enc):
            row[f"draw_encoder_{k}_arcsec"] = float(enc[k])
        return fr.dn, sc, row

    def settings(self) -> dict:
        return {"spp": self.spp, "frame": "full detector", "sun_full_angle_arcmin": self.rig.sun_simulator.collimation_full_angle_arcmin}


@register
class StarFieldGenerator:
    """Star-sensor frames (seed 004 rigs): FITS images at random (or swept) inertial attitudes.

    The true sensor (f, principal point, distortion, PSF, detector) is the rig file's and fixed for
    the dataset, as on orbit; what is drawn per frame is the attitude (uniform over the sphere) and
    the detector noise. The truth table has **one row per star** imaged on the detector (the frame's
    attitude repeated on each row), so a star pipeline can be scored star by star.
    """

    kind = "star-field"
    image_format = "fits"
    description = "star-sensor frames (FITS) at random or swept attitudes; one truth row per star"
    rig_family = "004"

    def __init__(self, rig_text: str, rig_source: str = "<rig>", *, spp: int = 1024, threads: int | None = None):
        import tomllib

        from rigsim.rig.load import parse_star_rig

        self.rig = parse_star_rig(tomllib.loads(rig_text), rig_source)
        self.spp = int(spp)  # the analytic renderer has no samples; kept for a uniform interface
        self._sky = None

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
        from rigsim.optics.sky import pointing

        return pointing(att["ra_deg"], att["dec_deg"], att["roll_deg"])

    def render(self, index: int, params: dict):
        from scipy.spatial.transform import Rotation

        from rigsim.optics.sky import boresight_radec
        from rigsim.render.star import render_frame

        if self._sky is None:
            from rigsim.truth.star import StarSky

            self._sky = StarSky(self.rig)
        R = self.attitude_matrix(params["attitude"])
        fr = render_frame(self._sky, R, seed=int(params["seed"]), index=int(index), renderer="analytic")
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
                                       and not np.any(fr.saturated[max(int(v) - 2, 0):int(v) + 3,
                                                                   max(int(u) - 2, 0):int(u) + 3]))})
        if not rows:  # a frame with no star still has a row (its attitude)
            rows.append({**base, "star": -1, "hip": -1, "mag": float("nan"), "photons": 0.0, "u": float("nan"),
                         "v": float("nan"), "dir_x": float("nan"), "dir_y": float("nan"), "dir_z": float("nan"),
                         "valid": False})
        sc = {"format": "rigsim.frame/1", "truth": {"rig": self.rig.name, "R_cam_from_icrs": R.tolist(),
                                                   "stars": len(tr)},
              "render": fr.settings, "detector": fr.detector_meta, "seed": int(params["seed"]),
              "dataset": {"params": params}}
        return fr.dn, sc, rows

    def settings(self) -> dict:
        return {"renderer": "analytic pixel-integrated PSF"}


@register
class BoresightRoiGenerator:
    """Seed-003 CMOS ROIs: one laser spot per frame, cycling over (camera, M1/M2).

    Each frame draws a camera state — rotations α, β, γ (uniform within ±``--range`` arcsec,
    default 60″) and a focal-length change Δf (uniform within ±20 µm) — and renders the ROI that
    follows the spot (``rig.orbit.window_px`` square, ``rig.orbit.spp``). Truth: the state, the
    exact spot centre in detector pixels, the ROI origin.
    """

    kind = "boresight-roi"
    image_format = "png"
    description = "seed-003 CMOS ROIs of the laser spots at random camera states"
    rig_family = "003"
    RANGE_ARCSEC = 60.0
    DF_RANGE_UM = 20.0

    def __init__(self, rig_text: str, rig_source: str = "<rig>", *, spp: int = 1024, threads: int | None = None):
        import tomllib

        from rigsim.rig.load import parse_boresight_rig

        self.rig = parse_boresight_rig(tomllib.loads(rig_text), rig_source)
        self.spp = int(spp)
        self._renderers: dict = {}

    def sweepable(self) -> list[str]:
        return ["alpha", "beta", "gamma", "df"]

    def plan(self, n_frames, sweep, seed) -> list[dict]:
        combos = [(c, j) for c in range(len(self.rig.cameras)) for j in (0, 1)]
        frames = []
        if sweep:
            grid = parse_sweep(sweep, self.sweepable())
            names = list(grid)
            mesh = np.meshgrid(*[grid[k] for k in names], indexing="ij")
            states = []
            for row in np.stack([m.ravel() for m in mesh], axis=1):
                st = {"alpha": 0.0, "beta": 0.0, "gamma": 0.0, "df": 0.0}
                st.update({k: float(v) for k, v in zip(names, row)})
                states.append(st)
            for st in states:
                for c, j in combos:
                    frames.append({"camera": c, "detector": j, "alpha_arcsec": st["alpha"], "beta_arcsec": st["beta"],
                                   "gamma_arcsec": st["gamma"], "df_um": st["df"]})
        else:
            if n_frames is None or n_frames < 1:
                raise DatasetError("give --frames N (N ≥ 1) or --sweep SPEC")
            for i in range(n_frames):
                rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5E17, i]))
                a, b, g = rng.uniform(-self.RANGE_ARCSEC, self.RANGE_ARCSEC, 3)
                c, j = combos[i % len(combos)]
                frames.append({"camera": c, "detector": j, "alpha_arcsec": float(a), "beta_arcsec": float(b),
                               "gamma_arcsec": float(g), "df_um": float(rng.uniform(-self.DF_RANGE_UM, self.DF_RANGE_UM))})
        for i, f in enumerate(frames):
            f["seed"] = int(np.random.SeedSequence([seed, 0xF7A3, i]).generate_state(1)[0] & 0x7FFFFFFF)
        return frames

    def render(self, index: int, params: dict):
        import warnings

        from rigsim.optics.line_camera import rotation_xyz
        from rigsim.render.boresight import LoopRenderer

        key = (params["camera"], params["detector"])
        if key not in self._renderers:
            self._renderers[key] = LoopRenderer(self.rig, params["camera"], params["detector"], follow=True)
        r = self._renderers[key]
        E = rotation_xyz(*(math.radians(params[k] / 3600.0) for k in ("alpha_arcsec", "beta_arcsec", "gamma_arcsec")))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fr = r.render(E, params["df_um"] * 1e-3, seed=int(params["seed"]))
        sc = dict(fr.sidecar)
        sc["dataset"] = {"params": params, "warnings": [str(w.message) for w in caught]}
        uv = fr.truth.get("spot_uv", [float("nan")] * 2)
        flags = dict(fr.flags)
        row = {"frame": int(index), "seed": int(params["seed"]), "camera": r.geom.name, "detector": f"M{params['detector'] + 1}",
               "alpha_arcsec": params["alpha_arcsec"], "beta_arcsec": params["beta_arcsec"],
               "gamma_arcsec": params["gamma_arcsec"], "df_um": params["df_um"],
               "spot_u": float(uv[0]), "spot_v": float(uv[1]),
               "roi_u0": int(fr.origin_uv[0]), "roi_v0": int(fr.origin_uv[1]),
               "valid": not (flags.get("spot_off_detector") or flags.get("spot_exceeds_window") or flags.get("saturated"))}
        return fr.dn, sc, row

    def settings(self) -> dict:
        return {"window_px": self.rig.orbit.window_px, "spp": self.rig.orbit.spp}


def generator_for_rig(rig_text: str) -> str:
    """The default generator of a rig file (by its seed_document)."""
    import tomllib

    sd = str(tomllib.loads(rig_text).get("seed_document", ""))
    for kind, cls in GENERATORS.items():
        if getattr(cls, "rig_family", None) == sd:
            return kind
    return "sun-sensor"


def make_generator(kind: str, rig_text: str, rig_source: str, **opts):
    if kind not in GENERATORS:
        raise DatasetError(f"--generator {kind!r}: allowed {', '.join(sorted(GENERATORS))}")
    return GENERATORS[kind](rig_text, rig_source, **opts)


_WORKER_CACHE: dict[tuple, object] = {}


def worker_generator(kind: str, rig_text: str, rig_source: str, opts: dict):
    """The generator of this worker process (built once per process: its Mitsuba state)."""
    import hashlib
    import json

    key = (kind, hashlib.sha256(rig_text.encode()).hexdigest(), json.dumps(opts, sort_keys=True))
    g = _WORKER_CACHE.get(key)
    if g is None:
        g = _WORKER_CACHE[key] = make_generator(kind, rig_text, rig_source, **opts)
    return g


TruthRow = dict
RenderFn = Callable[[int, dict], tuple]
