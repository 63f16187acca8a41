"""Dual-vector (TRIAD) attitude, seed 000 eqs 1–5 / seed 001 eqs 2–6.

With observations n1, n2 in frame *b* and the same vectors r1, r2 in frame *a*:

    a = n1, b = n1×n2/|n1×n2|, c = a×b;   A = r1, B = r1×r2/|r1×r2|, C = A×B
    R_b_from_a = [a b c] · [A B C]ᵀ

The triads are used as *columns* (the documents print them as rows, eqs 2/4, which would
give the transpose; see docs/readings.md). Then R·r1 = n1 exactly, and r2 is used only
for the rotation about r1.
"""

from __future__ import annotations

import numpy as np


def triad(n1, n2, r1, r2) -> np.ndarray:
    """R_b_from_a with R @ r1 = n1 exactly. Broadcasts over leading dimensions."""

    def frame(v1, v2):
        v1 = np.asarray(v1, float)
        v1 = v1 / np.linalg.norm(v1, axis=-1, keepdims=True)
        b = np.cross(v1, np.asarray(v2, float))
        nb = np.linalg.norm(b, axis=-1, keepdims=True)
        if np.any(nb < 1e-9):
            raise ValueError("TRIAD: the two observation vectors are parallel (degenerate); check eq 8's reading")
        b = b / nb
        c = np.cross(v1, b)
        return np.stack([v1, b, c], axis=-1)  # columns

    M_b = frame(n1, n2)
    M_a = frame(r1, r2)
    return M_b @ np.swapaxes(M_a, -1, -2)


def triad_conditioning(n1, n2, r1, r2) -> dict:
    """How well two observed vectors r1, r2 determine a TRIAD attitude against the reference pair n1, n2:
    the angle between r1 and r2 and between n1 and n2 (deg), their difference (a rigid body keeps it: a large
    one means the observations cannot be of these two vectors), and the amplification 1/sin∠(r1, r2) of r2's
    direction error into the rotation about r1; ``degenerate`` when the angle is under 10° or the
    inconsistency over 1°."""
    from rigsim.frames import angle_between

    ar, an = (float(np.degrees(angle_between(a, b))) for a, b in ((r1, r2), (n1, n2)))
    s = np.sin(np.radians(ar))
    return {"angle_r_deg": ar, "angle_n_deg": an, "inconsistency_deg": ar - an,
            "amplification": float(1.0 / s) if s > 0 else float("inf"),
            "degenerate": bool(ar < 10.0 or abs(ar - an) > 1.0)}
