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

    class AberratedLens(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.f = mi.Float(float(props["focal_length"]))
            self.C = _vec(props, "centre", (0.0, 0.0, 0.0))
            self.e1 = mi.Vector3f(1.0, 0.0, 0.0)
            self.e2 = mi.Vector3f(0.0, 1.0, 0.0)
            self.e3 = mi.Vector3f(0.0, 0.0, 1.0)
            self.t = _vec(props, "tangential", (0.0, 1.0, 0.0))
            self.s = dr.cross(self.e3, self.t)
            self.coma = float(props["coma_mm"])
            self.astig = float(props["astig_mm"])
            self.inv_a = 1.0 / float(props["pupil_radius_mm"])
            self.fill = float(props["fill"])
            fl = mi.BSDFFlags.DeltaTransmission | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            self.m_components = [fl]
            self.m_flags = fl
            dr.make_opaque(self.f, self.C)

        def sample(self, ctx, si, sample1, sample2, active=True):
            p = -si.to_world(si.wi)
            px, py, pz = dr.dot(p, self.e1), dr.dot(p, self.e2), dr.dot(p, self.e3)
            r = si.p - self.C
            x, y = dr.dot(r, self.e1), dr.dot(r, self.e2)
            az = dr.abs(pz)
            qx = px / az - x / self.f
            qy = py / az - y / self.f
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
            sz = dr.select(pz >= 0, 1.0, -1.0)
            d = dr.normalize(qx * self.e1 + qy * self.e2 + sz * self.e3)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = si.to_local(d)
            bs.pdf = mi.Float(1.0)
            bs.eta = mi.Float(1.0)
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DeltaTransmission)
            bs.sampled_component = mi.UInt32(0)
            return bs, dr.select(active, mi.Spectrum(1.0), mi.Spectrum(0.0))

        def eval(self, ctx, si, wo, active=True):
            return mi.Spectrum(0.0)

        def pdf(self, ctx, si, wo, active=True):
            return mi.Float(0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return mi.Spectrum(0.0), mi.Float(0.0)

        def traverse(self, cb):
            cb.put("focal_length", self.f, mi.ParamFlags.NonDifferentiable)
            cb.put("centre", self.C, mi.ParamFlags.NonDifferentiable)

        def parameters_changed(self, keys=None):
            dr.make_opaque(self.f, self.C)

        def to_string(self):
            return f"AberratedLens[f={self.f}, coma={self.coma}, astig={self.astig}]"

    mi.register_bsdf(ABERRATED_LENS_PLUGIN, lambda props: AberratedLens(props))
    _registered.add(variant)
