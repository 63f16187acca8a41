"""Mitsuba XML export of rigsim scene dicts (``rigsim scene export RIG --xml DIR``).

The exported scenes use only built-in plugins, so the plain ``mitsuba`` command renders them.
Where rigsim renders with a Python plugin (the distorted pinhole ``rigsim_pinhole``), the export
substitutes the built-in ``perspective`` sensor with the same focal length and principal point
and *no distortion*, and says so in an XML comment: the plain command cannot load Python plugins.
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

_TAG_BY_TYPE = {
    # shapes
    "ply": "shape", "obj": "shape", "serialized": "shape", "disk": "shape", "rectangle": "shape",
    "sphere": "shape", "cube": "shape", "cylinder": "shape",
    # bsdfs
    "diffuse": "bsdf", "conductor": "bsdf", "roughconductor": "bsdf", "dielectric": "bsdf",
    "thindielectric": "bsdf", "roughdielectric": "bsdf", "twosided": "bsdf", "null": "bsdf", "mask": "bsdf",
    # emitters
    "area": "emitter", "point": "emitter", "spot": "emitter", "directional": "emitter",
    "directionalarea": "emitter", "constant": "emitter", "envmap": "emitter",
    # sensors, films, samplers, filters, integrators
    "perspective": "sensor", "orthographic": "sensor", "thinlens": "sensor", "irradiancemeter": "sensor",
    "hdrfilm": "film", "specfilm": "film",
    "independent": "sampler", "ldsampler": "sampler", "stratified": "sampler", "multijitter": "sampler",
    "box": "rfilter", "gaussian": "rfilter", "tent": "rfilter",
    "path": "integrator", "ptracer": "integrator", "direct": "integrator", "volpath": "integrator",
    # spectra and textures
    "uniform": "spectrum", "regular": "spectrum", "d65": "spectrum", "blackbody": "spectrum",
    "bitmap": "texture", "checkerboard": "texture",
}


class ExportError(ValueError):
    pass


def _matrix(m) -> np.ndarray | None:
    if isinstance(m, np.ndarray) and m.shape == (4, 4):
        return m
    if hasattr(m, "matrix"):  # mi.ScalarTransform4f
        return np.array(m.matrix, dtype=float).reshape(4, 4)
    return None


def _value_xml(name: str, v, indent: str) -> str:
    q = quoteattr(name)
    M = _matrix(v)
    if M is not None:
        vals = " ".join(f"{x:.17g}" for x in M.ravel())
        return f"{indent}<transform name={q}>\n{indent}    <matrix value=\"{vals}\"/>\n{indent}</transform>\n"
    if isinstance(v, bool):
        return f"{indent}<boolean name={q} value=\"{str(v).lower()}\"/>\n"
    if isinstance(v, (int, np.integer)):
        return f"{indent}<integer name={q} value=\"{int(v)}\"/>\n"
    if isinstance(v, (float, np.floating)):
        return f"{indent}<float name={q} value=\"{float(v):.17g}\"/>\n"
    if isinstance(v, (str, Path)):
        return f"{indent}<string name={q} value={quoteattr(str(v))}/>\n"
    if isinstance(v, (list, tuple, np.ndarray)) and len(v) == 3:
        return f"{indent}<point name={q} value=\"{', '.join(f'{float(x):.17g}' for x in v)}\"/>\n"
    raise ExportError(f"cannot export property {name!r} = {v!r} to Mitsuba XML")


def _object_xml(name: str | None, d: dict, indent: str, comments: list[str]) -> str:
    t = d.get("type")
    if t not in _TAG_BY_TYPE:
        raise ExportError(f"plugin type {t!r} (entry {name!r}) has no built-in Mitsuba equivalent; "
                          "the plain mitsuba command cannot load rigsim's Python plugins")
    tag = _TAG_BY_TYPE[t]
    attrs = f" type={quoteattr(t)}"
    if name is not None and tag in ("bsdf", "spectrum", "texture", "rfilter", "film", "sampler") and not name.startswith("_"):
        attrs += f" name={quoteattr(name)}"
    elif name is not None and tag in ("shape", "emitter", "sensor", "integrator") and indent == "    ":
        attrs += f" id={quoteattr(name)}"  # ids only at the top level: nested keys need not be unique
    body = ""
    for k, v in d.items():
        if k == "type":
            continue
        body += _object_xml(k, v, indent + "    ", comments) if isinstance(v, dict) else _value_xml(k, v, indent + "    ")
    return f"{indent}<{tag}{attrs}>\n{body}{indent}</{tag}>\n"


def scene_dict_to_xml(scene: dict, comments: list[str] | None = None) -> str:
    """Serialise a Mitsuba scene dict (built-in plugins only) as Mitsuba 3 XML."""
    if scene.get("type") != "scene":
        raise ExportError("the top-level dict must have type 'scene'")
    comments = list(comments or [])
    body = "".join(
        _object_xml(k, v, "    ", comments) if isinstance(v, dict) else _value_xml(k, v, "    ")
        for k, v in scene.items() if k != "type"
    )
    head = "".join(f"<!-- {c.replace('--', '—')} -->\n" for c in comments)
    return f"<?xml version=\"1.0\" encoding=\"utf-8\"?>\n{head}<scene version=\"3.0.0\">\n{body}</scene>\n"


def cv_to_mitsuba_camera(R_world_from_cv: np.ndarray, position) -> np.ndarray:
    """4×4 to_world of a built-in Mitsuba camera looking like an OpenCV camera.

    Mitsuba's camera frame has +x left and +y up (z forward); OpenCV's has +x right, +y down.
    """
    M = np.eye(4)
    M[:3, :3] = np.asarray(R_world_from_cv, float) @ np.diag([-1.0, -1.0, 1.0])
    M[:3, 3] = np.asarray(position, float)
    return M


def perspective_from_intrinsics(fx: float, fy: float, cx: float, cy: float, width: int, height: int) -> dict:
    """Built-in ``perspective`` properties for OpenCV intrinsics (square pixels: uses fx).

    Mitsuba puts pixel i's centre at i + 0.5 of the film; OpenCV at i. The principal point offsets
    are fractions of the film size relative to its centre.
    """
    return {
        "type": "perspective",
        "fov_axis": "x",
        "fov": math.degrees(2 * math.atan(width / (2 * fx))),
        # Mitsuba's offsets are along its own camera axes (x left, y up): opposite signs to u, v
        "principal_point_offset_x": -(cx + 0.5 - width / 2) / width,
        "principal_point_offset_y": -(cy + 0.5 - height / 2) / height,
    }


def write_xml(path: Path, scene: dict, comments: list[str] | None = None) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(scene_dict_to_xml(scene, comments))
    return path


def localise_files(scene: dict, out_dir: Path) -> dict:
    """Copy every file a scene refers to (``filename`` entries: meshes, bitmaps) next to the XML
    under ``meshes/`` and point the scene at the copies (relative paths)."""
    import shutil

    out_dir = Path(out_dir)

    def walk(d):
        res = {}
        for k, v in d.items():
            if isinstance(v, dict):
                res[k] = walk(v)
            elif k == "filename" and isinstance(v, (str, Path)) and Path(v).is_file():
                dst = out_dir / "meshes" / Path(v).name
                dst.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(v, dst)
                res[k] = f"meshes/{dst.name}"
            else:
                res[k] = v
        return res

    return walk(scene)


def export_rig(rig, out_dir: Path, pose_deg: dict | None = None, spp: int = 64) -> list[Path]:
    """Write every scene rigsim can build for ``rig`` as Mitsuba XML (plus meshes) into ``out_dir``."""
    from rigsim.render.scenes.sun_sensor import SunSensorScene, sun_sensor_export_dict
    from rigsim.truth import realization_from_rig

    out_dir = Path(out_dir)
    real = realization_from_rig(rig)
    pose_rad = {k: math.radians(v) for k, v in (pose_deg or {}).items()}
    written = []
    sc = SunSensorScene(rig, real, spp=64)
    d, notes = sun_sensor_export_dict(sc, pose_rad, spp=spp)
    written.append(write_xml(out_dir / "sun_sensor.xml", d, notes))
    for builder_name, module_name, fname in (
        ("export_diaphragm", "rigsim.render.scenes.diaphragm", "diaphragm_screen.xml"),
        ("export_autocollimator", "rigsim.render.scenes.autocollimator", "autocollimator.xml"),
    ):
        try:
            mod = __import__(module_name, fromlist=[builder_name])
        except ImportError:
            continue
        builder = getattr(mod, builder_name, None)
        if builder is None:
            continue
        res = builder(rig, real, pose_rad or None, spp=spp)
        if res is None:  # not applicable to this rig
            continue
        d, notes = res
        written.append(write_xml(out_dir / fname, localise_files(d, out_dir), notes))
    return written
