"""rigsim.imaging: detection and centroiding on plain numpy arrays (no rig, no Mitsuba).

Pixel convention: pixel (0, 0)'s centre is at (u, v) = (0.0, 0.0); +u along columns (right),
+v along rows (down); arrays are indexed img[v, u]; positions are (u, v) in px. This is OpenCV's
convention (integer coordinates are pixel centres). See docs/imaging.md.
"""

from .centroid import (
    METHODS,
    centroid,
    centroid_gauss,
    centroid_gauss_lsq,
    centroid_gauss_multi,
    centroid_tcom,
    centroid_tcom_peak,
    centroid_wcom,
)
from .crlb import CRLB, crlb_gaussian, crlb_psf, fisher_information
from .detect import (
    Background,
    Detections,
    Rois,
    detect,
    estimate_background,
    extract_rois,
    find_spots,
)
from .edges import (
    CircleFit,
    Concentricity,
    EdgePoints,
    EllipseFit,
    concentricity,
    edge_points,
    fit_circle,
    fit_circle_points,
    fit_ellipse,
    fit_ellipse_points,
)
from .result import Centroid, CentroidBatch, Flag, NoiseModel

__all__ = [
    "Flag",
    "NoiseModel",
    "Centroid",
    "CentroidBatch",
    "centroid",
    "centroid_tcom",
    "centroid_tcom_peak",
    "centroid_wcom",
    "centroid_gauss",
    "centroid_gauss_lsq",
    "centroid_gauss_multi",
    "METHODS",
    "CRLB",
    "crlb_gaussian",
    "crlb_psf",
    "fisher_information",
    "Background",
    "Detections",
    "Rois",
    "estimate_background",
    "detect",
    "extract_rois",
    "find_spots",
    "EdgePoints",
    "CircleFit",
    "EllipseFit",
    "Concentricity",
    "edge_points",
    "fit_circle",
    "fit_circle_points",
    "fit_ellipse",
    "fit_ellipse_points",
    "concentricity",
]
