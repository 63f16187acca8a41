"""Mitsuba BSDF ``rigsim_aberrated_lens``: rigsim's ideal thin lens plus the camera objective's Seidel
aberrations on the laser loop's return crossing (:mod:`rigsim.optics.objective_aberrations`).

The laser's rays are telecentric pencils (the ideal model's emitting core), so which part of the
objective's pupil the real beam fills is not in their geometry: each returning ray draws its pupil
point (uniform on the disk of relative radius ``fill``) from the BSDF's 2-D sample and is deviated by
the loop's transverse ray aberration −(1/a)·∇(2W) at that point. The outgoing crossing is the ideal
lens. Properties: as ``rigsim_ideal_lens`` plus ``coma_mm``, ``astig_mm`` (W131, W222 at the
field point), ``pupil_radius_mm`` (a), ``fill``, and the field's tangential unit vector ``tangential``
(in the lens plane; the sagittal one is e3 × tangential).
"""

from __future__ import annotations

from rigsim.render.backend import ensure_variant
from rigsim.render.plugins import ideal_lens_class

__all__ = ["ABERRATED_LENS_PLUGIN", "register_aberrated_lens"]

ABERRATED_LENS_PLUGIN = "rigsim_aberrated_lens"
_registered: set = set()


def register_aberrated_lens() -> None:
    """Register the BSDF for the current variant (idempotent)."""
    variant = ensure_variant()
    if variant in _registered:
        return
    import drjit as dr
    import mitsuba as mi

    def _vec(props, name, default):
        v = props[name] if name in props else default  # noqa: SIM401 (mi.Properties has no get)
        return mi.Vector3f(*[float(x) for x in v])

    class AberratedLens(ideal_lens_class()):
        def __init__(self, props):
            super().__init__(props)
            self.t = _vec(props, "tangential", (0.0, 1.0, 0.0))
            self.s = dr.cross(self.e3, self.t)
            self.coma = float(props["coma_mm"])
            self.astig = float(props["astig_mm"])
            self.inv_a = 1.0 / float(props["pupil_radius_mm"])
            self.fill = float(props["fill"])

        def sample(self, ctx, si, sample1, sample2, active=True):
            qx, qy, pz = self._slopes(si)
            # the return crossing (towards the focal plane): the loop's transverse aberration as a slope
            rho = self.fill * dr.sqrt(sample2.x)
            phi = 2.0 * dr.pi * sample2.y
            xs, ys = rho * dr.cos(phi), rho * dr.sin(phi)        # sagittal, tangential pupil coordinates
            dwx = self.coma * 2.0 * xs * ys
            dwy = self.coma * (xs * xs + 3.0 * ys * ys) + self.astig * 2.0 * ys
            back = pz < 0
            ax = dr.select(back, -2.0 * self.inv_a * dwx, 0.0)   # slope change; × F on the focal plane
            ay = dr.select(back, -2.0 * self.inv_a * dwy, 0.0)
            qx += ax * dr.dot(self.s, self.e1) + ay * dr.dot(self.t, self.e1)
            qy += ax * dr.dot(self.s, self.e2) + ay * dr.dot(self.t, self.e2)
            return self._leave(si, qx, qy, pz, active)

        def to_string(self):
            return f"AberratedLens[f={self.f}, coma={self.coma}, astig={self.astig}]"

    mi.register_bsdf(ABERRATED_LENS_PLUGIN, lambda props: AberratedLens(props))
    _registered.add(variant)
