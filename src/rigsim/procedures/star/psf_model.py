"""The star image model of the pipeline's forward-model centroider (``[calibration] centroid_method =
"model"``), from the nominal rig only: the traced lens's PSF table when the rig's frames come through
the traced lens (``NominalSensor.traced_lens``, the lens design), else the ``[sensor.psf]`` Gaussian.

The table is built the way the renderer builds its own (``rigsim.optics.star_lens.StarLens`` at the
nominal focal length, :func:`rigsim.optics.star_psf.psf_table` over the nominal camera's field 2 %
wider than the detector), once per process and lens. docs/effects-star.md ("The forward-model
centroider") gives what the model holds and what it leaves out.
"""

from __future__ import annotations

import numpy as np

from rigsim.optics.star_image_model import GaussianStarImage, TracedStarImage
from rigsim.optics.star_lens import StarLens
from rigsim.optics.star_psf import PSFTable, field_tangents, psf_table
from rigsim.rig.star import NominalSensor, NominalStarRig

__all__ = ["REFERENCE_BV", "nominal_psf_table", "star_image_model"]

REFERENCE_BV = 0.65
"""The colour every star's model is drawn for (a G star; the renderer's colour for a star without B−V)."""

_TABLES: dict = {}


def nominal_psf_table(sensor: NominalSensor) -> PSFTable:
    """The traced lens's PSF table as the nominal sensor predicts it (``sensor.traced_lens`` must be set)."""
    spec = sensor.traced_lens
    t = field_tangents(sensor.camera(), sensor.resolution_px)
    key = (spec.model_dump_json(), float(sensor.focal_length_mm), float(sensor.pixel_pitch_um),
           round(float(t[0]), 6), round(float(t[1]), 6))
    if key not in _TABLES:
        lens = StarLens(focal_length_mm=sensor.focal_length_mm, epd_mm=spec.aperture_diameter_mm,
                        ref_nm=spec.reference_wavelength_nm, defocus_mm=-spec.defocus_um * 1e-3)
        _TABLES[key] = psf_table(lens, tan_max_x=float(t[0]), tan_max_y=float(t[1]),
                                 wavelengths_nm=np.linspace(spec.band_min_nm, spec.band_max_nm, spec.wavelengths),
                                 pixel_pitch_um=sensor.pixel_pitch_um, nodes=spec.field_nodes,
                                 pupil_rays=spec.pupil_rays, oversample=spec.oversample)
    return _TABLES[key]


def star_image_model(nominal: NominalStarRig):
    """The star image model the nominal rig predicts: :class:`TracedStarImage` (nominal camera, B−V
    :data:`REFERENCE_BV`) with a traced lens, else :class:`GaussianStarImage` of ``psf_sigma_px``."""
    s = nominal.sensor
    if s.traced_lens is None:
        return GaussianStarImage(float(s.psf_sigma_px))
    return TracedStarImage(nominal_psf_table(s), s.camera(), REFERENCE_BV)
