"""Penalty contact with the ground plane z = 0, for explicit solvers
(docs/physics.md, "Ground").

A contact point at depth d > 0 below its radius gets a normal force
k d - c v_z (never pulling) and Coulomb friction against its sliding
velocity, tuned to the point's effective mass m_eff so that an update held
for `dt` stays stable: omega dt = 0.5, damping ratio 0.7. The energy audit
counts what the spring holds (`stored_energy`). A point that starts deep
(a sunk limb become debris) keeps that depth as an allowance (`Sunk`), so a
change of model never fires a spring that nothing compressed.
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
    k, c = _spring(m, dt)
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


def _spring(mass: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Penalty stiffness (N/m) and damping (N s/m) for effective masses (kg)
    and a hold of dt s."""
    omega = 0.5 / dt
    return mass * omega**2, 2 * DAMPING_RATIO * mass * omega


def stored_energy(points: np.ndarray, rise: np.ndarray, radius: np.ndarray,
                  mass: np.ndarray, dt: float) -> np.ndarray:
    """Elastic energy (J) per point of ground_forces' springs at depth
    d = radius - z > 0 (m), the point rising at `rise` (m/s; its velocity's
    z): 1/2 k d d', with d' = d + rise dt its depth an update `dt` s before
    (k as ground_forces sets it): what an explicit update's spring
    conserves. (1/2 k d^2 counts a point that fell in within one update as
    stored before any force did work on it: docs/physics.md, "Ground".)"""
    depth = np.maximum(radius - points[:, 2], 0.0)
    before = np.maximum(depth + rise * dt, 0.0)
    return 0.5 * _spring(mass, dt)[0] * depth * before


class Sunk:
    """Per contact point, the depth (m) it may keep without being pushed:
    set when the point first takes part at some depth, it only shrinks as
    the point rises (never a push the model did not compress)."""

    def __init__(self):
        self.depth = np.zeros(0)

    def extend(self, depth: np.ndarray) -> None:
        """New points at these depths (m; <= 0 above ground)."""
        self.depth = np.concatenate([self.depth, np.maximum(depth, 0.0)])

    def radius(self, radius: np.ndarray, points: np.ndarray) -> np.ndarray:
        """The contact radius (m) to use now, after shrinking each allowance
        to the point's present depth."""
        self.depth = np.minimum(self.depth, np.maximum(radius - points[:, 2], 0.0))
        return radius - self.depth
