"""Penalty contact with the ground plane z = 0, for explicit solvers.

A contact point at depth d > 0 below its radius gets a normal force
k d - c v_z (never pulling) and Coulomb friction against its sliding
velocity. The spring-damper is tuned to the point's effective mass m_eff so
that an update held for `dt` stays stable: omega = 0.5 / dt (omega dt = 0.5)
and damping ratio 0.7, i.e. k = m_eff omega^2, c = 1.4 m_eff omega.
"""

from __future__ import annotations

import numpy as np

FRICTION = 0.6  # Coulomb coefficient, wood on soil
DAMPING_RATIO = 0.7


def ground_forces(points: np.ndarray, velocity: np.ndarray, radius: np.ndarray,
                  mass: np.ndarray, dt: float) -> np.ndarray:
    """Contact forces (N, 3) N at `points` (N, 3) m moving at `velocity`
    (N, 3) m/s, each a sphere of `radius` m with effective mass `mass` kg,
    for an explicit update held `dt` s. Zero rows for points off the ground."""
    depth = radius - points[:, 2]
    out = np.zeros_like(points)
    hit = depth > 0
    if not hit.any():
        return out
    m = mass[hit]
    omega = 0.5 / dt
    k = m * omega**2
    c = 2 * DAMPING_RATIO * m * omega
    v = velocity[hit]
    normal = np.maximum(k * depth[hit] - c * v[:, 2], 0.0)
    slide = v[:, :2]
    speed = np.linalg.norm(slide, axis=1)
    # friction never more than what stops the slide within the update
    friction = np.minimum(FRICTION * normal, c * speed)
    out[hit, :2] = -slide / np.maximum(speed, 1e-9)[:, None] * friction[:, None]
    out[hit, 2] = normal
    return out


def effective_mass(mass: np.ndarray, inertia: np.ndarray, arm: np.ndarray) -> np.ndarray:
    """A lower bound on the mass a point `arm` (N, 3) m from a body's centre
    of mass presents: 1 / (1/m + |arm|^2 / I) with I the body's smallest
    moment of inertia (kg m^2) — the free-body value, below the pinned one."""
    return 1.0 / (1.0 / mass + (arm * arm).sum(1) / np.maximum(inertia, 1e-12))
