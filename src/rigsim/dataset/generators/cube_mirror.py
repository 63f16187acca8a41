"""Dataset generator of cube-mirror rigs (seeds 000/001): sun-sensor frames at drawn turntable poses."""

from __future__ import annotations

import math

import numpy as np

from rigsim.dataset.generators.base import parse_sweep
from rigsim.errors import DatasetError


class SunSensorGenerator:
    kind = "sun-sensor"
    seeds = ("000", "001")
    image_format = "png"
    default_spp = 1024
    description = "full sun-sensor frames at random (or swept) turntable poses, rig errors drawn per frame"

    detector_field = "sun_sensor.resolution_px"  # the rig field that sets pixels_per_frame

    @property
    def pixels_per_frame(self) -> int:
        w, h = self.rig.sun_sensor.resolution_px
        return int(w) * int(h)

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
        from rigsim.truth.cube_mirror.realization import realization_from_rig

        if not hasattr(self, "_plan_real"):
            self._plan_real = realization_from_rig(self.rig, ideal=True)
            self._plan_cam = self.rig.sun_sensor.camera()
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
        labels = self.sweepable()
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
        from rigsim.truth.cube_mirror.realization import perpendicularity_perturbed, realization_from_rig

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
            fr = self._scene.render(pose, seed=int(params["seed"]), full_frame=True, truth_points=200_000,
                                     tight=True)
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
