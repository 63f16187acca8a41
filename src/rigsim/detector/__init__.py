"""EMVA 1288-style detector model (pure numpy): photons per pixel -> uint16 digital numbers."""

from rigsim.detector import emva
from rigsim.detector.config import DetectorConfig
from rigsim.detector.model import DetectorFrame, apply_detector, fixed_pattern

__all__ = ["DetectorConfig", "DetectorFrame", "apply_detector", "emva", "fixed_pattern"]
