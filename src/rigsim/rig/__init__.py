"""Rig descriptions: typed schemas per family (cube mirror, boresight, star), TOML loading, turntable
kinematics and the turntable's reading types."""

from rigsim.rig.load import (
    default_rigs,
    load_any_rig,
    load_boresight_rig,
    load_rig,
    load_star_rig,
    parse_rig,
    resolve_rig_path,
)

__all__ = ["load_rig", "load_any_rig", "load_boresight_rig", "load_star_rig", "parse_rig", "default_rigs",
           "resolve_rig_path"]
