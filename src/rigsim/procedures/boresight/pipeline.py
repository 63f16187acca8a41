"""Frames → centroids → (Δf, α, β, γ): the processing chain a real rig runs, on any ROIs.

Imaging (:mod:`rigsim.imaging`) and estimation (:mod:`rigsim.estimation.dvad`) stay separate:
:func:`centroid_rois` takes uint16/float ROIs and their origins and knows nothing of the rig;
:class:`CameraProcessor` holds one camera's nominal geometry and reference spots and turns a
pair of ROIs (M1, M2) into an estimate. Bring your own frames or centroids.
"""

from __future__ import annotations

import numpy as np

from rigsim.estimation.dvad import BoresightEstimate, estimate
from rigsim.imaging import NoiseModel
from rigsim.imaging.rois import RoiCentroids, centroid_rois, tcom_fast
from rigsim.optics.line_camera import CameraGeometry

__all__ = ["centroid_rois", "tcom_fast", "CameraProcessor", "RoiCentroids"]


class CameraProcessor:
    """One camera's real-time chain: two ROIs (M1, M2) → centroids → estimate.

    ``reference_uv`` (2, 2): the reference spots A1, B1 (measured at the reference state, e.g. the
    mean of many frames); default the design's."""

    def __init__(self, geom: CameraGeometry, reference_uv=None, *, method: str = "dvad",
                 reading: str = "consistent", centroider: str = "tcom", noise: NoiseModel | None = None):
        self.geom = geom
        self.method = method
        self.reading = reading
        self.centroider = centroider
        self.noise = noise
        self.reference_uv = geom.reference_uv if reference_uv is None else reference_uv

    @property
    def reference_uv(self) -> np.ndarray:
        return self._ref

    @reference_uv.setter
    def reference_uv(self, ref) -> None:
        from rigsim.estimation.dvad import DVADSolver

        self._ref = np.asarray(ref, float).reshape(2, 2)
        self._solver = DVADSolver(self.geom, self._ref) if (self.method, self.reading) == ("dvad", "consistent") else None

    def spots(self, roi_m1, roi_m2, origin_m1, origin_m2) -> RoiCentroids:
        return centroid_rois(np.stack([roi_m1, roi_m2]), [origin_m1, origin_m2], method=self.centroider,
                             noise=self.noise)

    def process(self, roi_m1, roi_m2, origin_m1, origin_m2) -> BoresightEstimate:
        """(Δf, α, β, γ) from one pair of ROIs (the real-time path: :func:`tcom_fast` and the cached
        DVAD solver; any other centroider goes through rigsim.imaging). Raises ValueError if a
        spot is not measurable, naming the detector and the imaging flags."""
        if self.centroider == "tcom":
            uv, ok = tcom_fast(np.stack([roi_m1, roi_m2]), [origin_m1, origin_m2], noise=self.noise)
        else:
            ok = np.zeros(2, bool)
        if not ok.all():
            m = self.spots(roi_m1, roi_m2, origin_m1, origin_m2)
            if not m.valid.all():
                from rigsim.imaging import Flag

                bad = [f"M{k + 1}: {Flag(int(f)).name}" for k, f in enumerate(m.flags) if not m.valid[k]]
                raise ValueError("no usable laser spot in " + ", ".join(bad))
            uv = m.uv
        return self.process_uv(uv.reshape(2, 2))

    def process_uv(self, meas_uv) -> BoresightEstimate:
        """From spot positions (…, 2, 2) a user measured with their own centroider."""
        if self._solver is not None:
            return self._solver.solve(meas_uv)
        return estimate(self.geom, self._ref, meas_uv, self.method, self.reading)
