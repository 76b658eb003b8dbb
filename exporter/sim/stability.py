"""The planar LOD's stability rule and its diagnostics (docs/physics.md,
"Stability"). Chipmunk applies a spring's torque explicitly, so a joint
between bodies a and b, ringing at omega^2 = k (1/I_a + 1/I_b), is stable
only while omega h < 2: the rule raises light, stiff bodies' rotary inertia
(masses unchanged) until every joint has omega h <= s."""

from __future__ import annotations

import numpy as np


def inertia_floor(k_max: np.ndarray, h: float, s: float) -> np.ndarray:
    """Smallest stable rotary inertia (kg m^2) for bodies whose stiffest
    joint is `k_max` (N m/rad), at substep `h` (s) and omega*h limit `s`
    (a chain's zig-zag mode then has sqrt(2) s < 2)."""
    return 2.0 * k_max * (h / s) ** 2


def turned(angle: np.ndarray, arm: np.ndarray) -> np.ndarray:
    """2D vectors `arm` (N, 2) turned by `angle` (N,) rad."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * arm[:, 0] - s * arm[:, 1], s * arm[:, 0] + c * arm[:, 1]], 1)


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
    expect[has] = state[j, 0:2] + turned(state[j, 2], rest_pivot[has] - rest_pivot[j])
    return np.linalg.norm(state[:, 0:2] - expect, axis=1) / np.maximum(length, 1e-9)
