"""Rig descriptions: typed models, TOML loading, turntable kinematics."""

from rigsim.rig.load import RigError, default_rigs, load_rig, parse_rig, resolve_rig_path
from rigsim.rig.schema import Rig

__all__ = ["Rig", "RigError", "load_rig", "parse_rig", "default_rigs", "resolve_rig_path"]
