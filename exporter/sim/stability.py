"""The planar LOD's stability rule and its diagnostics.

Chipmunk applies a DampedRotarySpring's torque once per step, explicitly,
from the two bodies' own moments of inertia: a joint between bodies a and b
rings at omega^2 = k (1/I_a + 1/I_b) and is stable only while omega h < 2.
A chain of N equal bones (the zig-zag mode) reaches omega^2 = 4 k / I, and a
realistic stem split into 30 bones is far beyond that at any affordable h
(design.md). The rule:

    I >= 2 k_max (h / s)^2     for every body,

with k_max the stiffest joint the body touches, h the substep and
s = quality.stability (default 1): every joint then has omega h <= s, the
zig-zag mode sqrt(2) s < 2. It raises the rotary inertia of light, stiff
bodies only (twigs, short bones); their mass is unchanged, so gravity, drag
and the sway modes, which are carried by translation, barely move
(tests/test_physics_analytic.py: the cantilever's f1 within 1 %). How many
bodies were raised, and by how much, is reported with every bake.
"""

from __future__ import annotations

import numpy as np


def inertia_floor(k_max: np.ndarray, h: float, s: float) -> np.ndarray:
    """Smallest stable rotary inertia (kg m^2) for bodies whose stiffest
    joint is `k_max` (N m/rad), at substep `h` (s) and omega*h limit `s`."""
    return 2.0 * k_max * (h / s) ** 2


def chain_gaps(state: np.ndarray, prev: np.ndarray, rest_pivot: np.ndarray,
               length: np.ndarray) -> np.ndarray:
    """How far each body's pivot is from where its joint says it should be,
    as a fraction of `length` (m). `state` rows are (x, y, angle, ...) of the
    bodies (x, y = the body's origin = its pivot), `prev` the previous body
    of each (-1 = a fixed anchor at its rest pivot), `rest_pivot` the rest
    pivots (N, 2)."""
    expect = rest_pivot.copy()
    has = prev >= 0
    j = prev[has]
    c, s = np.cos(state[j, 2]), np.sin(state[j, 2])
    arm = rest_pivot[has] - rest_pivot[j]
    expect[has] = state[j, 0:2] + np.stack([c * arm[:, 0] - s * arm[:, 1],
                                             s * arm[:, 0] + c * arm[:, 1]], 1)
    return np.linalg.norm(state[:, 0:2] - expect, axis=1) / np.maximum(length, 1e-9)
