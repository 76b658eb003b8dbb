"""Statics of a rig in its rest pose: the bending moments of loads at the
bones' centres of mass, gravity's and a steady wind's, and the small
deflection they cause, with gravity's geometric stiffness (a hanging twig
swings back like a pendulum, an upright stem is softened: P-delta). No
simulation; an independent check of what the solvers do in the linear
range (species.py uses it). SI units: m, N, N m, rad.
"""

from __future__ import annotations

import math

import numpy as np

from .forces import drag
from .rig import GRAVITY, Rig, depth_levels, subtree_sums

SHEAR = 0.14  # power-law exponent of the mean wind profile (forces.Wind's default)
REFERENCE_HEIGHT = 10.0  # m, where a wind speed is given


def joint_moments(rig: Rig, forces: np.ndarray, levels: list[np.ndarray] | None = None
                  ) -> np.ndarray:
    """Bending moment (B, ..., 3) N m at each bone's joint of forces
    (B, ..., 3) N applied at the bones' centres of mass (rest pose)."""
    levels = depth_levels(rig.bone_depth) if levels is None else levels
    extra = (slice(None),) + (None,) * (forces.ndim - 2) + (slice(None),)
    total = subtree_sums(rig.bone_parent, levels, forces)
    turning = subtree_sums(rig.bone_parent, levels, np.cross(rig.com[extra], forces))
    return turning - np.cross(rig.pivot[extra], total)


def gravity_forces(rig: Rig) -> np.ndarray:
    """Weight (B, 3) N of each bone."""
    out = np.zeros((rig.n_bones, 3))
    out[:, 2] = -GRAVITY * rig.mass
    return out


def wind_forces(rig: Rig, speeds: np.ndarray, azimuth: float, ground: float = 0.0) -> np.ndarray:
    """Drag (B, K, 3) N on each bone at rest in a steady wind of each of
    `speeds` (K,) m/s at REFERENCE_HEIGHT above `ground`, blowing toward
    `azimuth` degrees (from +X toward +Y): forces.drag's law, shear SHEAR."""
    speeds = np.atleast_1d(np.asarray(speeds, dtype=float))
    a = math.radians(azimuth)
    direction = np.array([math.cos(a), math.sin(a), 0.0])
    z = np.maximum(rig.com[:, 2] - ground, 0.5)
    profile = (z / REFERENCE_HEIGHT) ** SHEAR  # (B,)
    n, k = rig.n_bones, len(speeds)
    air = (profile[:, None] * speeds[None, :])[..., None] * direction  # (B, K, 3)
    rep = lambda v: np.repeat(v, k, axis=0)  # noqa: E731
    force = drag(air.reshape(-1, 3), np.zeros((n * k, 3)), rep(rig.axis), rep(rig.wood_area),
                 rep(rig.leaf_area), rig.drag, rig.leaf_drag)
    return force.reshape(n, k, 3)


def hinge_frame(rig: Rig) -> np.ndarray:
    """(B, 3, 2): each joint's two hinge axes, perpendicular to the bone and
    to each other (swing without twist; the first horizontal when it can
    be: z x axis, else x x axis), the convention of both solvers."""
    axis = rig.axis
    e1 = np.cross(np.array([0.0, 0.0, 1.0]), axis)
    flat = np.linalg.norm(e1, axis=1) <= 0.1
    e1[flat] = np.cross(np.array([1.0, 0.0, 0.0]), axis[flat])
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return np.stack([e1, np.cross(axis, e1)], axis=2)


class StaticSolver:
    """Small static deflections of a tree from its rest pose under loads at
    the bones' centres of mass: (K_s + K_g) q = J^T F, q (2B,) the hinge
    angles (two per joint), K_s the joint springs (k on both hinges), K_g
    gravity's geometric stiffness at rest (a hanging twig swings back like
    a pendulum, an upright stem is softened, P-delta):

        K_g[i, j] = -((n_j . g)(n_i . R_j) - (R_j . g)(n_i . n_j))

    for hinge i an ancestor of (or equal to) hinge j, n their axes, g the
    gravity vector, R_j the mass moment sum m (c - p_j) of everything hinge
    j carries. The matrix has entries only between a hinge and its
    ancestors, so it factors as L^T D L without fill-in (Featherstone 2005).
    The prestress holds the rest pose against gravity, so loads other than
    gravity are what move it. Linear: a swing is not capped at the
    streaming angle, so pendulous twigs come out on the safe side."""

    def __init__(self, rig: Rig, levels: list[np.ndarray] | None = None):
        self.rig = rig
        levels = depth_levels(rig.bone_depth) if levels is None else levels
        nb = rig.n_bones
        n = 2 * nb
        self.frame = frame = hinge_frame(rig)
        axes = frame.transpose(0, 2, 1).reshape(n, 3)  # dof 2b + h: bone b's hinge h
        bone = np.repeat(np.arange(nb), 2)
        parent = np.empty(n, dtype=np.int64)
        parent[0::2] = np.where(rig.bone_parent >= 0, 2 * rig.bone_parent + 1, -1)
        parent[1::2] = np.arange(0, n, 2)
        depth = np.zeros(n, dtype=np.int64)
        for j in range(n):
            if parent[j] >= 0:
                depth[j] = depth[parent[j]] + 1
        width = int(depth.max()) + 1
        anc = np.full((n, width), -1, dtype=np.int64)  # root-aligned ancestors, self last
        for j in range(n):
            p = parent[j]
            if p >= 0:
                anc[j, :depth[j]] = anc[p, :depth[j]]
            anc[j, depth[j]] = j
        msum = subtree_sums(rig.bone_parent, levels, rig.mass)
        mcsum = subtree_sums(rig.bone_parent, levels, rig.mass[:, None] * rig.com)
        lever = (mcsum - msum[:, None] * rig.pivot)[bone]  # R_j, kg m
        g = np.array([0.0, 0.0, -GRAVITY])
        valid = anc >= 0
        ai = np.where(valid, anc, 0)
        ni = axes[ai]  # (n, width, 3)
        nj = axes[:, None, :]
        rj = lever[:, None, :]
        rows = -((axes @ g)[:, None] * (ni * rj).sum(2) - (lever @ g)[:, None] * (ni * nj).sum(2))
        rows = np.where(valid, rows, 0.0)
        rows[np.arange(n), depth] += np.repeat(rig.k, 2)
        # L^T D L in place, deepest dofs first (a dof's row is final once its
        # descendants are done); rows[k, :depth[k]] become L, the diagonal D
        tri = np.tril(np.ones((width, width)))
        order = np.argsort(-depth, kind="stable")
        self.stable = True
        for k in order:
            d = depth[k]
            pivot = rows[k, d]
            if not pivot > 0:
                self.stable = False
                pivot = math.inf
            if d:
                a = rows[k, :d] / pivot
                up = anc[k, :d]
                rows[up, :d] -= a[:, None] * rows[k, None, :d] * tri[:d, :d]
                rows[k, :d] = a
        self.rows, self.anc, self.depth, self.axes = rows, anc, depth, axes
        self.diag = rows[np.arange(n), depth].copy()
        self.hold = np.einsum("bia,bi->ba", frame,
                              joint_moments(rig, gravity_forces(rig), levels))  # (B, 2) N m

    def solve(self, torque: np.ndarray) -> np.ndarray:
        """Hinge angles (2B, K) rad for hinge torques (2B, K) N m."""
        rows, anc, depth = self.rows, self.anc, self.depth
        x = np.array(torque, dtype=float, copy=True)
        n = len(depth)
        for k in range(n - 1, -1, -1):  # L^T
            d = depth[k]
            if d:
                x[anc[k, :d]] -= rows[k, :d, None] * x[k]
        with np.errstate(invalid="ignore", divide="ignore"):
            x /= self.diag[:, None]
        for k in range(n):  # L
            d = depth[k]
            if d:
                x[k] -= (rows[k, :d, None] * x[anc[k, :d]]).sum(0)
        return x

    def hinge_torques(self, moments: np.ndarray) -> np.ndarray:
        """(2B, K) N m: joint moment vectors (B, K, 3) on each joint's hinges."""
        t = np.einsum("bia,bki->bak", self.frame, moments)
        return t.reshape(-1, t.shape[-1])

    def turns(self, q: np.ndarray, levels: list[np.ndarray]) -> np.ndarray:
        """(B, K) rad: how far each bone turns from its rest pose (the
        rotation vectors of the joints below it added, first order)."""
        nb = self.rig.n_bones
        own = (q.reshape(nb, 2, -1)[:, :, :, None]
               * self.frame.transpose(0, 2, 1)[:, :, None, :]).sum(1)  # (B, K, 3)
        total = own.copy()
        parent = self.rig.bone_parent
        for idx in reversed(levels):  # shallowest first
            total[idx] += total[parent[idx]]
        return np.linalg.norm(total, axis=2)


