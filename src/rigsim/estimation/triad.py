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
