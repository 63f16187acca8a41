"""rigsim's public Python API: every stage of the pipeline on a user's own data, with no internal
module to import. The same functions run inside rigsim's campaigns, and each has a command
(``rigsim centroid``, ``rigsim calibrate sun-sensor``, ``rigsim triad``, ``rigsim compose``, …);
docs/user-data.md walks through them. Estimators here see observations and the nominal rig only
(an import contract enforces it); comparing with a simulated truth is the procedures' business.

Conventions: pixel (0, 0)'s centre at (u, v) = (0, 0), ``img[v, u]``; angles in radians inside
Python (degrees in files, ``x_deg``); rotations ``R_b_from_a`` with a covariance of the small
rotation δ in ``R_true ≈ exp([δ]×)·R`` about the target frame's axes.

>>> from rigsim import api
>>> rig = api.load_rig("sun_sensor_2axis_diaphragm")
>>> det = api.detector_settings(rig)                       # the sun sensor's offset, gain, noise
>>> spots = api.measure_frame(api.read_image("f.png"), det.noise, saturation_dn=det.saturation_dn)
"""

from __future__ import annotations

from rigsim.estimation.cube_attitude import AXIS_ORDERS_2AXIS, AXIS_ORDERS_3AXIS, cube_from_rot_triad
from rigsim.estimation.sun_calibration import SunCalibration, calibrate_sun_sensor
from rigsim.estimation.triad import triad
from rigsim.files import Column, covariance_block, read_image, read_json, read_table, write_image, write_json, write_table
from rigsim.imaging import Flag, NoiseModel
from rigsim.imaging.frame_spots import FRAME_METHODS, measure_frame, single_spot
from rigsim.optics.camera import PinholeBrown
from rigsim.optics.targets import (
    PlanarTarget,
    chessboard,
    circle_grid,
    image_target,
    parse_target,
    project_target,
    read_poses,
    spread_poses,
    target_to_camera,
    write_poses,
)
from rigsim.estimation.dvad import BoresightEstimate, DVADSolver
from rigsim.optics.line_camera import CameraGeometry
from rigsim.procedures.boresight.files import (
    camera_geometry,
    centroid_roi_files,
    estimate_columns,
    read_spot_rows,
    reference_spots,
    solve_rows,
    streaming_solver,
)
from rigsim.procedures.centroid import DetectorSettings, centroid_files, detector_settings
from rigsim.procedures.cube_mirror.input_causes import calibrate_sun_sensor_files
from rigsim.procedures.cube_mirror.files import (
    SunSensorInputs,
    compose_rotations,
    read_angle_log,
    read_nulls,
    read_spot_table,
    reading_sigma_rad,
    sun_calibration_json,
    sun_sensor_inputs,
    triad_with_covariance,
    write_opencv_camera,
)
from rigsim.procedures.cube_mirror.null_files import (
    autocollimator_optics,
    measure_concentricity,
    null_step,
    read_autocollimator,
)
from rigsim.procedures.cube_mirror.pipeline import CubeMirrorEstimate, estimate, fit_sun_sensor
from rigsim.procedures.star.files import (
    attitude_log_columns,
    calibrate_star_files,
    read_attitude_log,
    star_observations,
    star_result_json,
    stars_table,
)
from rigsim.procedures.star.pipeline import StarObservation, StarPipeline, calibrate_frames
from rigsim.rig.load import load_any_rig, load_boresight_rig, load_rig, load_star_rig
from rigsim.rig.turntable import TurntableModel, TurntableReading

__all__ = [
    # files
    "read_image", "write_image", "Column", "read_table", "write_table", "read_json", "write_json", "covariance_block",
    # rigs (nominal values)
    "load_rig", "load_any_rig", "load_boresight_rig", "load_star_rig", "TurntableReading", "TurntableModel",
    "PinholeBrown",
    # calibration targets (exact projection through a camera model)
    "PlanarTarget", "parse_target", "chessboard", "circle_grid", "image_target", "read_poses", "write_poses",
    "spread_poses", "project_target", "target_to_camera",
    # centroid
    "FRAME_METHODS", "measure_frame", "single_spot", "Flag", "NoiseModel", "DetectorSettings", "detector_settings",
    "centroid_files",
    # cube mirror (seeds 000/001)
    "read_angle_log", "read_spot_table", "SunSensorInputs", "sun_sensor_inputs", "calibrate_sun_sensor",
    "calibrate_sun_sensor_files", "fit_sun_sensor", "SunCalibration", "sun_calibration_json", "write_opencv_camera",
    "triad", "cube_from_rot_triad", "triad_with_covariance", "reading_sigma_rad", "read_nulls", "compose_rotations",
    "estimate", "CubeMirrorEstimate", "AXIS_ORDERS_2AXIS", "AXIS_ORDERS_3AXIS", "measure_concentricity", "null_step",
    "read_autocollimator", "autocollimator_optics",
    # boresight (seed 003)
    "CameraGeometry", "camera_geometry", "centroid_roi_files", "read_spot_rows", "reference_spots", "solve_rows",
    "estimate_columns", "streaming_solver", "DVADSolver", "BoresightEstimate",
    # star sensor (seed 004)
    "read_attitude_log", "attitude_log_columns", "star_observations", "calibrate_star_files", "calibrate_frames",
    "StarObservation", "StarPipeline", "star_result_json", "stars_table",
]
