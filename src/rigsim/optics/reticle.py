"""The autocollimator's reticle: its drawing in the source (focal) plane and where its image lands.

A reticle point (x, y) in the objective's focal plane leaves as a collimated beam of direction
(−x/f, −y/f); a flat mirror returns it and the same objective focuses it at (−x, −y) from the
image of the reticle centre (a point inversion, magnification −1). The image of the reticle
centre moves like a point source's: by ≈ 2·f·tilt (exactly: :class:`AutocollimatorOptics.spot`).

The drawing is a set of non-overlapping rectangles (the crossing of the two bars counted once,
so the radiance is uniform) plus an optional annulus.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ReticleDrawing", "reticle_drawing"]


@dataclass(frozen=True)
class ReticleDrawing:
    """Rectangles ``(cx, cy, half_w, half_h)`` and an optional annulus ``(r_in, r_out)``, in mm."""

    rects: tuple[tuple[float, float, float, float], ...]
    ring: tuple[float, float] | None = None
    line_width_mm: float = 0.0
    arm_length_mm: float = 0.0

    @property
    def areas(self) -> np.ndarray:
        a = [4.0 * hw * hh for _, _, hw, hh in self.rects]
        if self.ring is not None:
            a.append(math.pi * (self.ring[1] ** 2 - self.ring[0] ** 2))
        return np.array(a)

    @property
    def half_extent_mm(self) -> float:
        e = max(max(abs(cx) + hw, abs(cy) + hh) for cx, cy, hw, hh in self.rects)
        return max(e, self.ring[1]) if self.ring is not None else e

    def inside(self, x, y) -> np.ndarray:
        """True where (x, y) (mm, source plane) is on the reticle's transparent lines."""
        x, y = np.asarray(x, float), np.asarray(y, float)
        m = np.zeros(np.broadcast(x, y).shape, bool)
        for cx, cy, hw, hh in self.rects:
            m |= (np.abs(x - cx) <= hw) & (np.abs(y - cy) <= hh)
        if self.ring is not None:
            r = np.hypot(x, y)
            m |= (r >= self.ring[0]) & (r <= self.ring[1])
        return m

    def image_fraction(self, centre_uv, pitch_mm: float, window: tuple[int, int, int, int], oversample: int = 8) -> np.ndarray:
        """The nominal drawing imaged on the detector (point-inverted about ``centre_uv``, the
        image of the reticle centre), as the fraction of each pixel of ``window`` (u0, v0, w, h)
        covered by the lines (no blur). The bars' coverage is exact; the ring's is sampled
        ``oversample``² times per pixel."""
        u0, v0, w, h = window
        u = u0 + np.arange(w, dtype=float)
        v = v0 + np.arange(h, dtype=float)
        out = np.zeros((h, w))
        for cx, cy, hw, hh in self.rects:  # image of x ∈ [cx − hw, cx + hw] is u ∈ centre − (x/pitch)
            a, b = centre_uv[0] - (cx + hw) / pitch_mm, centre_uv[0] - (cx - hw) / pitch_mm
            c, d = centre_uv[1] - (cy + hh) / pitch_mm, centre_uv[1] - (cy - hh) / pitch_mm
            fu = np.clip(np.minimum(u + 0.5, b) - np.maximum(u - 0.5, a), 0.0, 1.0)
            fv = np.clip(np.minimum(v + 0.5, d) - np.maximum(v - 0.5, c), 0.0, 1.0)
            out += fv[:, None] * fu[None, :]
        if self.ring is not None:
            s = (np.arange(oversample) + 0.5) / oversample - 0.5
            x = -((u[:, None] + s[None, :]).ravel() - centre_uv[0]) * pitch_mm
            y = -((v[:, None] + s[None, :]).ravel() - centre_uv[1]) * pitch_mm
            r = np.hypot(x[None, :], y[:, None])
            m = (r >= self.ring[0]) & (r <= self.ring[1])
            out += m.reshape(h, oversample, w, oversample).mean(axis=(1, 3))
        return out

    def as_props(self) -> str:
        """The drawing as one string property of the Mitsuba emitter."""
        parts = [",".join(f"{v:.9g}" for v in r) for r in self.rects]
        ring = "" if self.ring is None else ",".join(f"{v:.9g}" for v in self.ring)
        return ";".join(parts) + "|" + ring

    def as_dict(self) -> dict:
        return {"rects_mm": [list(r) for r in self.rects], "ring_mm": None if self.ring is None else list(self.ring),
                "line_width_mm": self.line_width_mm, "arm_length_mm": self.arm_length_mm}


def reticle_drawing(pattern: str, line_width_mm: float, arm_length_mm: float, ring_radius_mm: float = 0.0) -> ReticleDrawing:
    """A cross of two bars (full length ``arm_length_mm``, width ``line_width_mm``) centred on the
    axis, plus for ``"cross_ring"`` a ring of mid-radius ``ring_radius_mm`` and the same width."""
    if pattern not in ("cross", "cross_ring"):
        raise ValueError(f"pattern = {pattern!r}: must be 'cross' or 'cross_ring'")
    hw, L = 0.5 * line_width_mm, 0.5 * arm_length_mm
    if not (0 < hw < L):
        raise ValueError(f"line_width_mm = {line_width_mm!r} must be > 0 and below arm_length_mm = {arm_length_mm!r}")
    arm = 0.5 * (L - hw)  # half length of each vertical half-bar (the crossing belongs to the horizontal bar)
    rects = ((0.0, 0.0, L, hw), (0.0, hw + arm, hw, arm), (0.0, -(hw + arm), hw, arm))
    ring = None
    if pattern == "cross_ring":
        r0, r1 = ring_radius_mm - hw, ring_radius_mm + hw
        if not (r0 > hw and r1 < L):
            raise ValueError(f"ring_radius_mm = {ring_radius_mm!r}: the ring must lie between the crossing and the "
                             f"ends of the bars ({2 * hw:g} to {L - hw:g} mm)")
        ring = (r0, r1)
        # the bars cross the ring: cut them there so that no area is counted twice
        rects = _cut_bars(rects, r0, r1)
    return ReticleDrawing(tuple(rects), ring, float(line_width_mm), float(arm_length_mm))


def _cut_bars(rects, r0, r1):
    """Remove the stretches of the bars that lie inside the annulus (approximately: the bars are
    thin, so |coordinate along the bar| ∈ [r0, r1] on the bar's axis)."""
    out = []
    for cx, cy, hw, hh in rects:
        horizontal = hw > hh
        c, h = (cx, hw) if horizontal else (cy, hh)
        lo, hi = c - h, c + h
        segs = [(lo, hi)]
        for a, b in ((-r1, -r0), (r0, r1)):
            new = []
            for s0, s1 in segs:
                if b <= s0 or a >= s1:
                    new.append((s0, s1))
                    continue
                if s0 < a:
                    new.append((s0, a))
                if b < s1:
                    new.append((b, s1))
            segs = new
        for s0, s1 in segs:
            m, h2 = 0.5 * (s0 + s1), 0.5 * (s1 - s0)
            out.append((m, cy, h2, hh) if horizontal else (cx, m, hw, h2))
    return out
