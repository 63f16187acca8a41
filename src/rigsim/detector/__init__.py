"""EMVA 1288-style detector model (pure numpy): photons per pixel -> uint16 digital numbers."""

from rigsim.detector.config import DetectorConfig
from rigsim.detector.model import DetectorFrame, apply_detector, fixed_pattern
from rigsim.detector import emva

__all__ = ["DetectorConfig", "DetectorFrame", "apply_detector", "fixed_pattern", "emva"]
