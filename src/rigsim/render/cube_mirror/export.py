"""``rigsim scene export`` for cube-mirror rigs: every scene rigsim renders for the rig, as Mitsuba XML."""

from __future__ import annotations

import math
from pathlib import Path

from rigsim.render.cube_mirror.autocollimator import export_autocollimator
from rigsim.render.cube_mirror.diaphragm import export_diaphragm
from rigsim.render.cube_mirror.sun_sensor import SunSensorScene, sun_sensor_export_dict
from rigsim.render.export import localise_files, write_xml
from rigsim.truth.cube_mirror.realization import realization_from_rig


def export_rig(rig, out_dir: Path, pose_deg: dict | None = None, spp: int = 64, beam: str = "divergent") -> list[Path]:
    """Write every scene rigsim can build for ``rig`` as Mitsuba XML (plus meshes) into ``out_dir``;
    ``beam`` is the diaphragm screen's sun-simulator beam (divergent: what the campaign renders)."""
    out_dir = Path(out_dir)
    real = realization_from_rig(rig)
    pose_rad = {k: math.radians(v) for k, v in (pose_deg or {}).items()}
    written = []
    sc = SunSensorScene(rig, real, spp=64)
    d, notes = sun_sensor_export_dict(sc, pose_rad, spp=spp)
    written.append(write_xml(out_dir / "sun_sensor.xml", d, notes))
    for builder, fname, opts in ((export_diaphragm, "diaphragm_screen.xml", {"beam": beam}),
                                 (export_autocollimator, "autocollimator.xml", {})):
        res = builder(rig, real, pose_rad or None, spp=spp, **opts)
        if res is None:  # not applicable to this rig
            continue
        d, notes = res
        written.append(write_xml(out_dir / fname, localise_files(d, out_dir), notes))
    return written
