"""Dataset generator of the dual line-array camera (seed 003): CMOS ROIs at drawn camera states."""

from __future__ import annotations

import math

import numpy as np

from rigsim.dataset.generators.base import parse_sweep
from rigsim.errors import DatasetError


class BoresightRoiGenerator:
    """Seed-003 CMOS ROIs: one laser spot per frame, cycling over (camera, M1/M2).

    Each frame draws a camera state — rotations α, β, γ (uniform within ±``--range`` arcsec,
    default 60″) and a focal-length change Δf (uniform within ±20 µm) — and renders the ROI that
    follows the spot (``rig.orbit.window_px`` square, ``rig.orbit.spp``). Truth: the state, the
    exact spot centre in detector pixels, the ROI origin.
    """

    kind = "boresight-roi"
    seeds = ("003",)
    image_format = "png"
    default_spp = 1024
    description = "seed-003 CMOS ROIs of the laser spots at random camera states"
    RANGE_ARCSEC = 60.0
    DF_RANGE_UM = 20.0

    detector_field = "orbit.window_px"  # the rig field that sets pixels_per_frame

    @property
    def pixels_per_frame(self) -> int:
        return int(self.rig.orbit.window_px) ** 2

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
