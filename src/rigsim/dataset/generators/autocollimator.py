"""Dataset generator of autocollimator rigs (seed 001): the autocollimator's frames of the cube faces."""

from __future__ import annotations

import math

import numpy as np

from rigsim.dataset.generators.base import parse_sweep
from rigsim.errors import DatasetError


class AutocollimatorGenerator:
    """Seed-001 autocollimator frames: a cube face's return spot at drawn turntable poses.

    Frame i looks at face ``faces[i % n]``. Its pose is the face's reference pose (the face's true
    normal on the autocollimator's nominal axis, the rig file's true errors) plus a change of every
    turntable axis drawn uniformly, kept when the exact reading puts the spot's centre within 80 %
    of the detector's half size (f·tan 2θ, derived from the autocollimator's focal length, pitch
    and detector); ``--sweep dX=..,dY=..,dZ=..`` (arcsec from the reference pose) sets them instead.
    Truth: the exact reading (θx, θy) in arcsec (the face normal's true tilt), the instrument's reading
    (what its calibration makes of the exact spot: it differs from the exact one by the objective's
    distortion, about 0.1 % of the angle), the spot's exact pixel centroid and its paraxial position.
    """

    kind = "autocollimator"
    seeds = ("001",)
    image_format = "png"
    default_spp = 256
    description = "seed-001 autocollimator frames of the cube faces at drawn poses near each null"

    detector_field = "autocollimator.resolution_px"  # the rig field that sets pixels_per_frame

    @property
    def pixels_per_frame(self) -> int:
        w, h = self.rig.autocollimator.resolution_px
        return int(w) * int(h)

    def __init__(self, rig_text: str, rig_source: str = "<rig>", *, spp: int = 256, threads: int | None = None):
        import tomllib

        from rigsim.rig.load import parse_rig
        from rigsim.truth.cube_mirror.realization import realization_from_rig

        self.rig = parse_rig(tomllib.loads(rig_text), rig_source)
        if self.rig.autocollimator is None or self.rig.procedure.method != "autocollimator":
            raise DatasetError(f"{rig_source}: generator autocollimator needs an autocollimator rig (procedure.method "
                               f"= 'autocollimator', seed 001); this rig's procedure uses the {self.rig.procedure.method}")
        self.spp = int(spp)
        self.threads = threads
        self.real = realization_from_rig(self.rig)
        self._renderers: dict = {}
        self._layouts: dict = {}

    # -- planning (numpy only) ---------------------------------------------------------------
    def sweepable(self) -> list[str]:
        return [f"d{a.label}" for a in self.rig.turntable.axes]

    def _layout(self, face: str):
        if face not in self._layouts:
            from rigsim.truth.cube_mirror.autocollimator import autocollimator_layout

            self._layouts[face] = autocollimator_layout(self.rig, self.real, "face", face)
        return self._layouts[face]

    def half_range_arcsec(self) -> np.ndarray:
        """(θx, θy) whose spot centre lies at 80 % of the detector's half size: f·tan(2θ) = 0.8·(W/2)·pitch."""
        ac = self.rig.autocollimator
        half_mm = 0.5 * np.asarray(ac.resolution_px, float) * ac.pixel_pitch_um * 1e-3
        return np.degrees(0.5 * np.arctan(0.8 * half_mm / ac.focal_length_mm)) * 3600.0

    def exact_reading_arcsec(self, face: str, pose: dict) -> np.ndarray:
        from rigsim.optics.autocollimator import a_frame_basis, exact_reading_rad

        lay = self._layout(face)
        n = self.real.turntable.R_rot_from_mount(pose) @ self.real.face_normals_mount[face]
        return np.degrees(exact_reading_rad(a_frame_basis(np.asarray(lay.axis_rot, float)), n / np.linalg.norm(n))) * 3600.0

    def _pose(self, face: str, d_arcsec: dict) -> dict:
        pose = dict(self._layout(face).reference_pose_rad)
        for a, v in d_arcsec.items():
            pose[a] = pose.get(a, 0.0) + math.radians(v / 3600.0)
        return pose

    def plan(self, n_frames, sweep, seed) -> list[dict]:
        faces = list(self.rig.procedure.faces)
        labels = [a.label for a in self.rig.turntable.axes]
        draws = []
        if sweep:
            grid = parse_sweep(sweep, self.sweepable())
            names = list(grid)
            mesh = np.meshgrid(*[grid[k] for k in names], indexing="ij")
            for fi in range(len(faces)):
                for row in np.stack([m.ravel() for m in mesh], axis=1):
                    draws.append((faces[fi], {k[1:]: float(v) for k, v in zip(names, row)}))
        else:
            if n_frames is None or n_frames < 1:
                raise DatasetError("give --frames N (N ≥ 1) or --sweep SPEC")
            h = self.half_range_arcsec()
            for i in range(n_frames):
                rng = np.random.default_rng(np.random.SeedSequence([seed, 0xAC, i]))
                face = faces[i % len(faces)]
                for _ in range(1000):
                    d = {a: float(x) for a, x in zip(labels, rng.uniform(-h.min(), h.min(), len(labels)))}
                    if np.all(np.abs(self.exact_reading_arcsec(face, self._pose(face, d))) < h):
                        break
                draws.append((face, d))
        frames = []
        for i, (face, d) in enumerate(draws):
            pose = self._pose(face, d)
            frames.append({"face": face, "change_from_reference_arcsec": d,
                           "pose_true_deg": {a: math.degrees(v) for a, v in pose.items()},
                           "seed": int(np.random.SeedSequence([seed, 0xF7A3, i]).generate_state(1)[0] & 0x7FFFFFFF)})
        return frames

    # -- rendering (worker side) ---------------------------------------------------------------
    def render(self, index: int, params: dict):
        import warnings

        face = params["face"]
        if face not in self._renderers:
            if self.threads:
                from rigsim.render.backend import set_thread_count

                set_thread_count(int(self.threads))
            from rigsim.render.cube_mirror.autocollimator import AutocollimatorRenderer

            # one Dr.Jit thread per render: a dataset's frames are byte-identical for any worker count
            self._renderers[face] = AutocollimatorRenderer(self.rig, self.real, "face", face, spp=self.spp,
                                                           layout=self._layout(face), deterministic=True)
        pose = {a: math.radians(v) for a, v in params["pose_true_deg"].items()}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fr = self._renderers[face].render_frame(pose, seed=int(params["seed"]))
        sc = dict(fr.sidecar)
        sc["dataset"] = {"params": params, "warnings": [str(w.message) for w in caught]}
        t, flags = sc["truth"], sc.get("flags", {})
        th = t.get("true_tilt_arcsec") or [float("nan")] * 2
        ins = t.get("reading_arcsec") or [float("nan")] * 2
        c = t.get("spot_pixel_centroid_uv") or [float("nan")] * 2
        p = t.get("paraxial_uv") or [float("nan")] * 2
        row = {"frame": int(index), "seed": int(params["seed"]), "face": face}
        for a, v in sorted(params["pose_true_deg"].items()):
            row[f"pose_{a}_true_deg"] = float(v)
        row.update({"reading_x_arcsec": float(th[0]), "reading_y_arcsec": float(th[1]),
                    "instrument_reading_x_arcsec": float(ins[0]), "instrument_reading_y_arcsec": float(ins[1]),
                    "spot_u_px": float(c[0]), "spot_v_px": float(c[1]),
                    "paraxial_u_px": float(p[0]), "paraxial_v_px": float(p[1])})
        keys = ("beam_misses_face", "spot_off_detector", "spot_cut_by_edge", "spot_exceeds_window", "saturated")
        for k in keys:
            row[k] = bool(flags.get(k, False))
        row["valid"] = bool(t.get("valid", True)) and not any(row[k] for k in keys)
        return fr.dn, sc, row

    def settings(self) -> dict:
        return {"spp": self.spp, "half_range_arcsec": self.half_range_arcsec().tolist(),
                "axis": "the autocollimator's nominal axis"}
