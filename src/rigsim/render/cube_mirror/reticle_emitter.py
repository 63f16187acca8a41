"""A Mitsuba Python emitter: the autocollimator's illuminated reticle.

``rigsim_reticle`` emits ``flux`` (photons per exposure) from the transparent lines of a reticle
drawing (:class:`rigsim.optics.reticle.ReticleDrawing`) in the plane z = ``z_mm`` (the objective's
focal plane, A frame). Every point of the lines radiates uniformly into a cone of half-angle
``cutoff_rad`` aimed at the centre of the objective's stop (``z_stop_mm`` on the axis): a reticle
lit by a condenser that fills the stop (Köhler illumination), the extended counterpart of the
``spot`` emitter that stands for the pinhole. Positions are sampled uniformly over the lines'
area (a line is chosen in proportion to its area), directions uniformly over the cone, so each
light path carries ``flux``: the same radiometric scale as the ``spot`` with intensity
flux / (2π(1 − cos cutoff)). Only ``sample_ray`` is implemented: the ``ptracer`` with
``hide_emitters`` never looks at the emitter itself.

``fold_plane`` ("px,py,pz,nx,ny,nz", optional): the reticle sits on a folded arm, mirrored in that
plane (the beam splitter's first surface): every sampled position and direction is reflected in
it (p → p − 2((p − c)·n)n, d → d − 2(d·n)n), so the light reaches the plane exactly where the
unfolded reticle's would have come from.
"""

from __future__ import annotations

import math

from rigsim.render.backend import ensure_variant

__all__ = ["RETICLE_PLUGIN", "register_reticle_emitter"]

RETICLE_PLUGIN = "rigsim_reticle"

_registered: set[str] = set()


def register_reticle_emitter() -> None:
    """Register ``rigsim_reticle`` for the current variant (idempotent)."""
    variant = ensure_variant()
    if variant in _registered:
        return
    import mitsuba as mi

    cls = _make_class()
    mi.register_emitter(RETICLE_PLUGIN, lambda props: cls(props))
    _registered.add(variant)


def _parse(drawing: str):
    rects_s, _, ring_s = drawing.partition("|")
    rects = [tuple(float(v) for v in r.split(",")) for r in rects_s.split(";") if r]
    ring = tuple(float(v) for v in ring_s.split(",")) if ring_s else None
    return rects, ring


def _make_class():
    import drjit as dr
    import mitsuba as mi

    class ReticleEmitter(mi.Emitter):
        def __init__(self, props):
            mi.Emitter.__init__(self, props)
            self.flux = float(props["flux"])
            self.z = float(props["z_mm"])
            self.z_stop = float(props["z_stop_mm"])
            self.cos_cutoff = math.cos(float(props["cutoff_rad"]))
            self.rects, self.ring = _parse(props["drawing"])
            areas = [4.0 * hw * hh for _, _, hw, hh in self.rects]
            if self.ring is not None:
                areas.append(math.pi * (self.ring[1] ** 2 - self.ring[0] ** 2))
            total = sum(areas)
            acc, self.cdf = 0.0, []
            for a in areas:
                acc += a / total
                self.cdf.append(acc)
            self.extent = max(max(abs(cx) + hw, abs(cy) + hh) for cx, cy, hw, hh in self.rects)
            if self.ring is not None:
                self.extent = max(self.extent, self.ring[1])
            self.fold = None
            if "fold_plane" in props:
                v = [float(x) for x in props["fold_plane"].split(",")]
                c, n = v[:3], v[3:]
                self.fold = (mi.ScalarVector3f(n), 2.0 * sum(a * b for a, b in zip(c, n)))
            self.m_flags = mi.EmitterFlags.DeltaPosition
            self.m_needs_sample_2 = True
            self.m_needs_sample_3 = True

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            # sample1 (the wavelength sample, unused by the mono variants) picks the line
            x, y = mi.Float(0.0), mi.Float(0.0)
            lo = 0.0
            n = len(self.cdf)
            for k, (cx, cy, hw, hh) in enumerate(self.rects):
                hi = self.cdf[k]
                m = (sample1 >= lo) if k == n - 1 else (sample1 >= lo) & (sample1 < hi)
                x = dr.select(m, cx + (2.0 * sample2.x - 1.0) * hw, x)
                y = dr.select(m, cy + (2.0 * sample2.y - 1.0) * hh, y)
                lo = hi
            if self.ring is not None:
                r0, r1 = self.ring
                m = sample1 >= lo
                r = dr.sqrt(dr.fma(sample2.x, r1 * r1 - r0 * r0, r0 * r0))
                phi = 2.0 * math.pi * sample2.y
                x = dr.select(m, r * dr.cos(phi), x)
                y = dr.select(m, r * dr.sin(phi), y)
            p = mi.Point3f(x, y, self.z)
            axis = dr.normalize(mi.Vector3f(-x, -y, self.z_stop - self.z))
            d = mi.Frame3f(axis).to_world(mi.warp.square_to_uniform_cone(sample3, self.cos_cutoff))
            if self.fold is not None:
                n, two_cn = self.fold
                p = p - (2.0 * dr.dot(p, n) - two_cn) * mi.Vector3f(n)
                d = d - 2.0 * dr.dot(d, n) * mi.Vector3f(n)
            return mi.Ray3f(p, d, time, mi.Color0f()), mi.Spectrum(self.flux)

        def sample_wavelengths(self, si, sample, active=True):
            return mi.Color0f(), mi.Spectrum(1.0)

        # The reticle is seen by light tracing only (sample_ray). A scene's vcalls over emitters
        # trace every live emitter instance, this one included, even from another scene in the same
        # process (a path tracer's MIS asks every emitter for pdf_direction): without these methods
        # that trace calls a pure virtual function. None of them ever contributes light.
        def sample_direction(self, it, sample, active=True):
            return dr.zeros(mi.DirectionSample3f), mi.Spectrum(0.0)

        def pdf_direction(self, it, ds, active=True):
            return mi.Float(0.0)

        def eval_direction(self, it, ds, active=True):
            return mi.Spectrum(0.0)

        def eval(self, si, active=True):
            return mi.Spectrum(0.0)

        def sample_position(self, time, sample, active=True):
            return dr.zeros(mi.PositionSample3f), mi.Float(0.0)

        def pdf_position(self, ps, active=True):
            return mi.Float(0.0)

        def bbox(self):
            e = self.extent
            if self.fold is None:
                return mi.ScalarBoundingBox3f([-e, -e, self.z], [e, e, self.z])
            n, two_cn = self.fold
            bb = mi.ScalarBoundingBox3f()
            for x in (-e, e):
                for y in (-e, e):
                    q = mi.ScalarPoint3f(x, y, self.z)
                    bb.expand(q - (2.0 * dr.dot(q, n) - two_cn) * n)
            return bb

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"ReticleEmitter[flux={self.flux}, z={self.z}, {len(self.rects)} bars, ring={self.ring}]"

    return ReticleEmitter
