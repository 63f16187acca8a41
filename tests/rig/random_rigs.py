"""Random valid cube-mirror rigs across the documented ranges (docs/custom-rig.md), built from the
default rig files' dictionaries: hypothesis draws the geometry, the rest follows from it."""

from __future__ import annotations

import copy
import math
import tomllib

from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st

from rigsim.rig.load import SCENES_DIR, parse_rig

_BASE = {m: tomllib.loads((SCENES_DIR / f"{name}.toml").read_text())
         for m, name in (("diaphragm", "sun_sensor_2axis_diaphragm"), ("autocollimator", "sun_sensor_3axis_autocollimator"))}

RANGES = {
    "sun_sensor.resolution_px": (512, 2048),
    "sun_sensor.pixel_pitch_um": (3.45, 15.0),
    "sun sensor half field (deg, narrower side)": (20.0, 65.0),
    "sun_sensor.distortion.k1": (-0.025, 0.0),
    "sun_simulator.collimation_full_angle_arcmin": (16.0, 40.0),
    "cube.edge_mm": (8.0, 40.0),
    "diaphragm_screen.hole_diameter_mm": (0.8, 4.0),
    "diaphragm_screen.distance_to_cube_mm": (300.0, 1200.0),
    "aiming camera object pixel (µm)": (8.0, 25.0),
    "autocollimator.focal_length_mm": (150.0, 600.0),
    "autocollimator.pixel_pitch_um": (3.45, 9.0),
    "autocollimator.aperture_mm": (15.0, 60.0),
    "autocollimator.distance_mm": (300.0, 1000.0),
}


def _u(draw, key, log=False):
    lo, hi = RANGES[key]
    if log:
        return math.exp(draw(st.floats(math.log(lo), math.log(hi))))
    return draw(st.floats(lo, hi))


@st.composite
def rig_dicts(draw, method: str | None = None) -> dict:
    """A rig file's dictionary (the TOML's content) with drawn geometry."""
    method = method or draw(st.sampled_from(["diaphragm", "autocollimator"]))
    d = copy.deepcopy(_BASE[method])
    ss = d["sun_sensor"]
    w = 64 * draw(st.integers(RANGES["sun_sensor.resolution_px"][0] // 64, RANGES["sun_sensor.resolution_px"][1] // 64))
    h = 64 * draw(st.integers(RANGES["sun_sensor.resolution_px"][0] // 64, w // 64))
    pitch = _u(draw, "sun_sensor.pixel_pitch_um")
    full = _u(draw, "sun_simulator.collimation_full_angle_arcmin")
    # the half field, up to where the sun image is still 2.2 px across (rig check refuses < 2 px)
    lo, hi = RANGES["sun sensor half field (deg, narrower side)"]
    widest = math.degrees(math.atan(math.tan(math.radians(full / 60.0) / 2) * min(w, h) / 2.2))
    half = math.radians(draw(st.floats(lo, min(hi, widest))))
    ss["resolution_px"] = [w, h]
    ss["pixel_pitch_um"] = round(pitch, 3)
    ss["focal_length_mm"] = round(0.5 * min(w, h) * pitch * 1e-3 / math.tan(half), 4)
    ss["principal_point_px"] = [round((w - 1) / 2 + draw(st.floats(-0.01, 0.01)) * w, 2),
                                round((h - 1) / 2 + draw(st.floats(-0.01, 0.01)) * h, 2)]
    k1 = _u(draw, "sun_sensor.distortion.k1")
    ss["distortion"] = {"k1": round(k1, 5), "k2": round(-0.05 * k1, 6), "p1": 0.0001, "p2": -0.0001, "k3": 0.0}
    # the sweep: within 85 % of the half field, 8 to 24 steps each way
    rng_deg = max(5.0, round(0.85 * math.degrees(half)))
    n_steps = draw(st.integers(4, 12))
    d["procedure"]["sweep_range_deg"] = float(rng_deg)
    d["procedure"]["sweep_step_deg"] = round(rng_deg / n_steps, 3)
    d["sun_simulator"]["collimation_full_angle_arcmin"] = round(full, 2)
    edge = _u(draw, "cube.edge_mm")
    d["cube"]["edge_mm"] = round(edge, 2)
    if method == "diaphragm":
        ds, ac = d["diaphragm_screen"], d["aiming_camera"]
        hole = min(_u(draw, "diaphragm_screen.hole_diameter_mm"), 0.6 * edge)
        dist = _u(draw, "diaphragm_screen.distance_to_cube_mm")
        ds["hole_diameter_mm"] = round(hole, 3)
        ds["distance_to_cube_mm"] = round(dist, 1)
        d["sun_simulator"]["distance_mm"] = round(dist + ds["distance_from_simulator_mm"], 1)
        ret = hole + 4.0 * dist * math.tan(math.radians(full / 60.0) / 2)  # the divergent return's diameter (mm)
        px = _u(draw, "aiming camera object pixel (µm)") * 1e-3
        px = max(px, 1.25 * ret / 2400)  # at most 2400 px across
        n = math.ceil(1.25 * ret / px)
        ac["resolution_px"] = [math.ceil(1.3 * n / 2) * 2, n + n % 2]
        ac["pixel_pitch_um"] = round(px * 1e3 * ac["focal_length_mm"] / ac["working_distance_mm"], 3)
    else:
        a = d["autocollimator"]
        f = _u(draw, "autocollimator.focal_length_mm", log=True)
        p = _u(draw, "autocollimator.pixel_pitch_um")
        # the detector holds face tilts of ±0.3° (the procedure's search starts 0.2° from the nulls)
        n = max(640, math.ceil(2 * f * math.tan(math.radians(0.62)) / (p * 1e-3) / 64) * 64)
        a["focal_length_mm"], a["pixel_pitch_um"] = round(f, 2), round(p, 3)
        a["resolution_px"] = [n + 256, n]
        # autocollimators are slow objectives (f/8 to f/12 commercially): f/6 or slower here; a fast singlet's
        # aberrated, asymmetric spot is not what their calibration assumes
        a["aperture_mm"] = round(min(_u(draw, "autocollimator.aperture_mm"), f / 6.0), 1)
        a["distance_mm"] = round(_u(draw, "autocollimator.distance_mm"), 1)
        d["plane_mirror"]["diameter_mm"] = a["aperture_mm"]
    d["name"] = f"random-{method}"
    return d


def draw(n: int):
    """Deterministic draws (same rigs every run), no shrinking: a failure prints the rig's dictionary."""
    return settings(max_examples=n, deadline=None, derandomize=True, database=None, phases=[Phase.generate],
                    suppress_health_check=list(HealthCheck))


def build(d: dict):
    return parse_rig(copy.deepcopy(d), "<random rig>")
