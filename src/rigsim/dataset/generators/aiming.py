"""Dataset generator of diaphragm rigs (seed 000): the aiming camera's hole and spot frames."""

from __future__ import annotations

import math

import numpy as np

from rigsim.dataset.generators.base import parse_sweep
from rigsim.errors import DatasetError

_IMAGES = ("hole", "spot")
_HOLE_FLAGS = ("hole_off_detector", "hole_cut_by_edge")
_SPOT_FLAGS = ("beam_misses_face", "spot_not_returned", "spot_off_detector", "spot_cut_by_edge")


class AimingCameraGenerator:
    """Seed-000 aiming-camera frames: pairs (hole frame, spot frame) at drawn turntable poses.

    A pair is two consecutive frames of one pose: frame 2k the lit hole with the return blocked,
    frame 2k+1 the returned spot beside it (with the hole's glow, as on the real screen). Poses are
    each face's exact null pose (the rig file's true errors) plus a tilt drawn uniformly within the
    range that keeps the returned spot whole on the aiming camera's detector (derived from the screen
    distance, the spot's size and the camera's field; draws that cut it are drawn again); ``--sweep dX=..,dY=..`` (arcsec from the null) sets
    them instead. The beam is the sun simulator's divergent one, as the campaign renders it.
    Truth: the exact hole and spot centres (px) and their offset on the screen (px and µm).
    """

    kind = "aiming-camera"
    seeds = ("000",)
    image_format = "png"
    default_spp = 4
    description = "seed-000 aiming-camera frames (hole, spot) of the diaphragm screen at drawn poses near each null"

    detector_field = "aiming_camera.resolution_px"  # the rig field that sets pixels_per_frame

    @property
    def pixels_per_frame(self) -> int:
        w, h = self.rig.aiming_camera.resolution_px
        return int(w) * int(h)

    def __init__(self, rig_text: str, rig_source: str = "<rig>", *, spp: int = 4, threads: int | None = None):
        import tomllib

        from rigsim.rig.load import parse_rig
        from rigsim.truth.cube_mirror.realization import realization_from_rig

        self.rig = parse_rig(tomllib.loads(rig_text), rig_source)
        if self.rig.diaphragm_screen is None or self.rig.aiming_camera is None:
            raise DatasetError(f"{rig_source}: generator aiming-camera needs a diaphragm rig (procedure.method = "
                               f"'diaphragm', seed 000); this rig's procedure uses the {self.rig.procedure.method}")
        self.spp = int(spp)
        self.threads = threads
        self.real = realization_from_rig(self.rig)
        self._renderers: dict = {}
        self._geometry: dict = {}

    # -- planning (numpy only) ---------------------------------------------------------------
    def sweepable(self) -> list[str]:
        return ["dX", "dY"]

    def _geom(self, fi: int):
        if fi not in self._geometry:
            from rigsim.truth.cube_mirror.diaphragm import diaphragm_geometry

            self._geometry[fi] = diaphragm_geometry(self.rig, self.real, fi, beam="divergent",
                                                    return_into_hole="absorb")
        return self._geometry[fi]

    def tilt_range_arcsec(self) -> float:
        """Half range of the drawn axis changes. A face tilt θ moves the returned spot by
        L·tan 2θ on the screen (L = face → screen path, ≈ the screen distance); the spot (radius R,
        divergence included) stays whole on the camera's field (half size h, narrower side) while the
        offset is below h − R; when the spot is larger than the field, a quarter of h."""
        ac, d = self.rig.aiming_camera, self.rig.diaphragm_screen.distance_to_cube_mm
        h = 0.5 * min(ac.resolution_px) * ac.object_pixel_mm
        g = self._geom(0)
        R = g.trace(dict(g.layout.null_pose_rad)).spot_radius_mm
        room = max(h - R, 0.25 * h)
        return math.degrees(0.5 * math.atan(room / d)) * 3600.0

    def _pose(self, fi: int, d_arcsec) -> dict:
        g = self._geom(fi)
        pose = dict(g.layout.null_pose_rad)
        axes = list(pose)[:2]
        for ax, a in zip(axes, d_arcsec):
            pose[ax] += math.radians(a / 3600.0)
        return pose

    def _usable(self, fi: int, pose: dict) -> bool:
        f = self._geom(fi).trace(pose).flags
        return not any(f.get(k) for k in _HOLE_FLAGS + _SPOT_FLAGS)

    def plan(self, n_frames, sweep, seed) -> list[dict]:
        faces = list(self.rig.procedure.faces)
        tilts = []
        if sweep:
            grid = parse_sweep(sweep, self.sweepable())
            dx, dy = grid.get("dX", np.zeros(1)), grid.get("dY", np.zeros(1))
            for fi in range(len(faces)):
                tilts += [(fi, (float(a), float(b))) for a in dx for b in dy]
        else:
            if n_frames is None or n_frames < 1:
                raise DatasetError("give --frames N (N ≥ 1: N frames, N/2 hole-spot pairs rounded up) or --sweep SPEC")
            r = self.tilt_range_arcsec()
            for k in range((n_frames + 1) // 2):
                rng = np.random.default_rng(np.random.SeedSequence([seed, 0xA1, k]))
                fi = k % len(faces)
                for _ in range(1000):
                    d = tuple(float(x) for x in rng.uniform(-r, r, 2))
                    if self._usable(fi, self._pose(fi, d)):
                        break
                tilts.append((fi, d))
        frames = []
        for k, (fi, d) in enumerate(tilts):
            pseed = int(np.random.SeedSequence([seed, 0xF7A3, k]).generate_state(1)[0] & 0x7FFFFFFF)
            pose = self._pose(fi, d)
            for image in _IMAGES:
                frames.append({"pair": k, "image": image, "face": faces[fi], "face_index": fi,
                               "tilt_from_null_arcsec": list(d),
                               "pose_true_deg": {a: math.degrees(v) for a, v in pose.items()}, "seed": pseed})
        return frames[:n_frames] if n_frames and not sweep else frames

    # -- rendering (worker side) ---------------------------------------------------------------
    def render(self, index: int, params: dict):
        import warnings

        fi = int(params["face_index"])
        if fi not in self._renderers:
            if self.threads:
                from rigsim.render.backend import set_thread_count

                set_thread_count(int(self.threads))
            from rigsim.render.cube_mirror.aiming import ConcentricityRenderer

            self._renderers[fi] = ConcentricityRenderer(self.rig, self.real, fi, spp=self.spp)
        pose = {a: math.radians(v) for a, v in params["pose_true_deg"].items()}
        image = params["image"]
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fr = self._renderers[fi].render(pose, seed=int(params["seed"]), hole_seed=int(params["seed"]),
                                            spot=image == "spot", warn=False)
        frame = fr.hole if image == "hole" else fr.spot
        sc = dict(frame.sidecar)
        sc["dataset"] = {"params": params, "warnings": [str(w.message) for w in caught]}
        tr, flags = fr.truth, fr.flags
        pix = self.rig.aiming_camera.object_pixel_mm
        off = np.full(2, np.nan) if tr.offset_mm is None else np.asarray(tr.offset_mm, float)
        spot_uv = np.full(2, np.nan) if tr.spot_uv is None else np.asarray(tr.spot_uv, float)
        row = {"frame": int(index), "seed": int(params["seed"]), "pair": int(params["pair"]), "image": image,
               "face": params["face"]}
        for a, v in sorted(params["pose_true_deg"].items()):
            row[f"pose_{a}_true_deg"] = float(v)
        row.update({"tilt_arcsec": math.degrees(tr.tilt_rad) * 3600.0,
                    "hole_u_px": float(tr.hole_uv[0]), "hole_v_px": float(tr.hole_uv[1]),
                    "spot_u_px": float(spot_uv[0]), "spot_v_px": float(spot_uv[1]),
                    "offset_x_px": float(off[0] / pix), "offset_y_px": float(off[1] / pix),
                    "offset_x_um": float(1e3 * off[0]), "offset_y_um": float(1e3 * off[1]),
                    "spot_radius_px": float(tr.spot_radius_mm / pix)})
        for k in _HOLE_FLAGS + _SPOT_FLAGS + ("spot_overlaps_hole",):
            row[k] = bool(flags.get(k, False))
        row["saturated"] = bool(flags.get("saturated_pixels", {}).get(image, 0))
        bad = _HOLE_FLAGS if image == "hole" else _HOLE_FLAGS + _SPOT_FLAGS
        row["valid"] = not any(row[k] for k in bad) and not row["saturated"]
        return frame.dn, sc, row

    def settings(self) -> dict:
        return {"spp": self.spp, "beam": "divergent", "frames": "pairs: hole (return blocked), spot",
                "tilt_range_arcsec": self.tilt_range_arcsec()}
