"""Seed 003: boresight measurement of a dual line-array camera with a central prism.

Subpackage layout (docs/boresight.md):

* :mod:`.schema`, :mod:`.load` — the rig file (scenes/dual_line_array_prism.toml) and its loader;
* :mod:`.geometry` — camera frames, pixels ↔ focal plane, the exact forward model (truth);
* :mod:`.estimation` — the simplified method (eqs 1–4) and DVAD (eqs 7–15), two readings;
* :mod:`.render` — the Mitsuba scene of one camera's laser loop and its CMOS ROI frames;
* :mod:`.pipeline` — frames → centroids → estimates (imaging and estimation kept apart);
* :mod:`.studies` — the paper's analyses (Figs 4–8, rotation order, orbit scenario) and claims;
* :mod:`.report` — Markdown + PNG report.

Importing this package does not import Mitsuba.
"""

from .estimation import BoresightEstimate, dvad, estimate, relative_rotation, simplified
from .geometry import CameraGeometry, euler_xyz, loop_trace, rotation_xyz, spots_uv
from .load import DEFAULT_RIG, load_boresight_rig, parse_boresight_rig
from .schema import BoresightRig, LineCamera

__all__ = ["BoresightRig", "LineCamera", "load_boresight_rig", "parse_boresight_rig", "DEFAULT_RIG",
           "CameraGeometry", "spots_uv", "loop_trace", "rotation_xyz", "euler_xyz",
           "BoresightEstimate", "dvad", "simplified", "estimate", "relative_rotation"]
