"""The planar model's linear tier: joint-space equations of whole trees,
linearised about the grown shape and stepped implicitly.

Coordinates: every bone has two joint angles at its base, one per bending
plane of its chain (layout.py), so a bone turns relative to its frame by the
rotation vector of its chain's summed angles, as in the pymunk tier. About
the grown shape (the equilibrium under gravity with the prestress) a tree is

    M q'' + C q' + (K_s + K_g) q = J^T F(t) (+ f0),

with M the joint-space mass matrix of the whole tree at rest (every bone's
mass and inertia, both ways coupled: children push back on their parents),
K_s the joint springs (the rig's k on each plane's hinge), K_g gravity's
geometric stiffness (a hanging twig's pendulum stiffness, a stem's P-delta
softening), C the rig's structural damping (each limb's rows of M times its
alpha, the reference's form) and J^T F the external loads (air, blasts,
attractors, pulls) mapped from the bones' centres of mass. Gravity's own
load is balanced by the prestress (f0 = 0), or, without prestress, acts as
the constant f0 at rest. All of M, C, K have an entry only between a dof
and its ancestors, so they factor without fill-in (treefactor.py).

Stepping: Newmark's average-acceleration rule (trapezoidal: unconditionally
stable, no numerical damping, period error (omega h)^2 / 12), at the
quality's load rate; the loads are evaluated once per step at the predicted
state. Poses at frames come from the joint angles through the same exact
(nonlinear) kinematics as the pymunk tier.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..rotations import cross, matrices_from_rotvec, quaternions_from_matrices
from ..scene import Scene
from .common import Bones, SimTree, TreeMotion, cap_loads, locate
from .layout import ChainLayout
from .loads import SceneLoads
from .quality import Quality
from .treefactor import TreeFactor, ancestor_table, depths

BETA, GAMMA = 0.25, 0.5  # Newmark's average acceleration


@dataclass
class LinearStats:
    steps: int = 0
    dofs: int = 0
    limited: int = 0
    first_limit: tuple | None = None
    factor_seconds: float = 0.0
    step_seconds: float = 0.0
    update_seconds: float = 0.0
    frame_seconds: list[float] = field(default_factory=list)


class LinearModel:
    """The linearised joint-space system of some bones (whole trees, parents
    first): dof 2b + k is bone b's hinge in plane k."""

    def __init__(self, bones: Bones, layout: ChainLayout, gravity: np.ndarray, h: float,
                 prestress: bool):
        self.bones, self.layout = bones, layout
        nb = bones.n
        n = self.n = 2 * nb
        self.h = h
        normals = layout.normals()  # (B, 2, 3)
        self.axis = normals.reshape(n, 3)
        dof_bone = np.repeat(np.arange(nb), 2)
        self.dof_bone = dof_bone
        parent = np.empty(n, dtype=np.int64)
        parent[0::2] = np.where(bones.parent >= 0, 2 * bones.parent + 1, -1)
        parent[1::2] = np.arange(0, n, 2)
        self.parent = parent
        self.depth = depths(parent)
        self.anc = ancestor_table(parent, self.depth)
        # subtree moments of every bone (itself and all it carries)
        m, c = bones.mass, bones.com0
        s0 = _subtree(bones.parent, m)
        s1 = _subtree(bones.parent, m[:, None] * c)
        s2 = _subtree(bones.parent, m[:, None, None] * c[:, :, None] * c[:, None, :])
        si = _subtree(bones.parent, bones.inertia)
        # pairs (i upstream of j, j): i = anc[j, t]
        jj, tt = np.nonzero(np.arange(self.anc.shape[1])[None, :] < self.depth[:, None])
        ii = self.anc[jj, tt]
        self.pair_j, self.pair_t, self.pair_i = jj, tt, ii
        p = bones.pivot0[dof_bone]
        b_of = dof_bone

        def mass_entry(i, j):
            bj = b_of[j]
            S0, S1, S2, SI = s0[bj], s1[bj], s2[bj], si[bj]
            pi, pj = p[i], p[j]
            ni, nj = self.axis[i], self.axis[j]
            scal = (np.trace(S2, axis1=1, axis2=2) - (S1 * (pi + pj)).sum(1)
                    + S0 * (pi * pj).sum(1))
            P = (S2 - S1[:, :, None] * pi[:, None, :] - pj[:, :, None] * S1[:, None, :]
                 + S0[:, None, None] * pj[:, :, None] * pi[:, None, :])
            return ((ni * nj).sum(1) * scal - np.einsum("ni,nij,nj->n", ni, P, nj)
                    + np.einsum("ni,nij,nj->n", ni, SI, nj))

        def gravity_entry(i, j):
            lever = s1[b_of[j]] - s0[b_of[j]][:, None] * p[j]  # sum m (c - p_j)
            ni, nj = self.axis[i], self.axis[j]
            # -g . (n_i x (n_j x R)) with n_i x (n_j x R) = n_j (n_i.R) - R (n_i.n_j)
            return -((gravity * nj).sum(1) * (ni * lever).sum(1)
                     - (gravity * lever).sum(1) * (ni * nj).sum(1))

        diag_idx = np.arange(n)
        self.m_diag = mass_entry(diag_idx, diag_idx)
        self.m_low = mass_entry(ii, jj)
        kg_diag = gravity_entry(diag_idx, diag_idx)
        kg_low = gravity_entry(ii, jj)
        self.k_spring = np.repeat(bones.k, 2)
        self.k_diag = self.k_spring + kg_diag
        self.k_low = kg_low
        # structural damping: each limb's block of M times its alpha
        limb = layout.bone_chain[dof_bone]
        alpha = bones.alpha[dof_bone]
        same = limb[ii] == limb[jj]
        self.c_diag = alpha * self.m_diag
        self.c_low = np.where(same, alpha[jj] * self.m_low, 0.0)
        # gravity's generalized force at rest (balanced by the prestress)
        lever = s1[dof_bone] - s0[dof_bone][:, None] * p
        self.tau_g0 = (self.axis * cross(lever, np.broadcast_to(gravity, lever.shape))).sum(1)
        self.f0 = np.zeros(n) if prestress else self.tau_g0.copy()
        self.spring_ref = -self.tau_g0 / self.k_spring if prestress else np.zeros(n)
        # chains of dofs for the chain-wise solve: a bone chain's dofs in order
        chains = [np.stack([2 * b, 2 * b + 1], 1).ravel() for b in layout.chain_bones]
        level = layout.chain_depth
        a_diag = self.m_diag + GAMMA * h * self.c_diag + BETA * h * h * self.k_diag
        a_low = self.m_low + GAMMA * h * self.c_low + BETA * h * h * self.k_low
        self.factor = TreeFactor(parent, a_diag, self._rows(a_low), chains, level)
        self.mass_factor = TreeFactor(parent, self.m_diag.copy(), self._rows(self.m_low),
                                      chains, level)
        # kinematics: per bone, its dofs and all its ancestors' (pairs b <- dof)
        last = 2 * np.arange(nb) + 1
        kb, kt = np.nonzero(np.arange(self.anc.shape[1] + 1)[None, :]
                            <= self.depth[last][:, None])
        kd = np.where(kt < self.depth[last][kb], self.anc[last[kb], np.minimum(
            kt, self.anc.shape[1] - 1)], last[kb])
        order = np.argsort(kb, kind="stable")
        self.kin_bone, self.kin_dof = kb[order], kd[order]
        self.kin_start = np.searchsorted(self.kin_bone, np.arange(nb))
        # loads: per bone, the bones of its subtree (pairs ancestor bone <- bone)
        anc_bone = self.kin_dof[self.kin_dof % 2 == 1] // 2  # bones on each path, self too
        desc = self.kin_bone[self.kin_dof % 2 == 1]
        order = np.argsort(anc_bone, kind="stable")
        self.sub_anc, self.sub_desc = anc_bone[order], desc[order]
        self.sub_start = np.searchsorted(self.sub_anc, np.arange(nb))
        self.cross_pivot = cross(self.axis, p)  # n_j x p_j
        self._csr()

    def _rows(self, low: np.ndarray) -> np.ndarray:
        rows = np.zeros(self.anc.shape)
        rows[self.pair_j, self.pair_t] = low
        return rows

    def _csr(self) -> None:
        """Both triangles and the diagonal of the symmetric matrices, by row,
        for one reduceat per product."""
        n = self.n
        row = np.concatenate([np.arange(n), self.pair_j, self.pair_i])
        col = np.concatenate([np.arange(n), self.pair_i, self.pair_j])
        order = np.lexsort((col, row))
        self.csr_col = col[order]
        self.csr_start = np.searchsorted(row[order], np.arange(n))

        def vals(diag, low):
            return np.concatenate([diag, low, low])[order]

        self.csr_c = vals(self.c_diag, self.c_low)
        self.csr_k = vals(self.k_diag, self.k_low)

    def damping_stiffness(self, v: np.ndarray, q: np.ndarray) -> np.ndarray:
        """C v + K q (the dofs' internal forces), N m."""
        col = self.csr_col
        return np.add.reduceat(self.csr_c * v[col] + self.csr_k * q[col], self.csr_start)

    def kinematics(self, q: np.ndarray, v: np.ndarray):
        """Linearised COM positions, velocities (B, 3) and small rotation
        vectors (B, 3) of the bones from joint angles q and rates v."""
        per_dof = np.empty((self.n, 12))
        per_dof[:, 0:3] = q[:, None] * self.axis
        per_dof[:, 3:6] = q[:, None] * self.cross_pivot
        per_dof[:, 6:9] = v[:, None] * self.axis
        per_dof[:, 9:12] = v[:, None] * self.cross_pivot
        s = np.add.reduceat(per_dof[self.kin_dof], self.kin_start, axis=0)
        c0 = self.bones.com0
        com = c0 + cross(s[:, 0:3], c0) - s[:, 3:6]
        vel = cross(s[:, 6:9], c0) - s[:, 9:12]
        return com, vel, s[:, 0:3]

    def generalized(self, force: np.ndarray) -> np.ndarray:
        """J^T F: each dof's torque from forces (B, 3) N at the bones' COMs
        (rest geometry, as the linearisation): n_j . (sum c x F - p_j x sum F)
        over the bone's subtree."""
        per_bone = np.empty((len(force), 6))
        per_bone[:, 0:3] = force
        per_bone[:, 3:6] = cross(self.bones.com0, force)
        s = np.add.reduceat(per_bone[self.sub_desc], self.sub_start, axis=0)[self.dof_bone]
        return (self.axis * s[:, 3:6]).sum(1) - (self.cross_pivot * s[:, 0:3]).sum(1)

    def bending_moment(self, q: np.ndarray) -> np.ndarray:
        """Magnitude (B,) N m of the spring moment at each bone's base joint."""
        mom = (self.k_spring * (q - self.spring_ref)).reshape(-1, 2)
        return np.sqrt((mom * mom).sum(1))


def _subtree(parent: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Sum of `values` over each bone and all bones outboard of it."""
    out = np.array(values, dtype=float, copy=True)
    for b in range(len(parent) - 1, -1, -1):
        p = parent[b]
        if p >= 0:
            out[p] += out[b]
    return out


class LinearSolver:
    """Simulate the active trees of a scene with the linear tier."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                 log=None):
        self.scene, self.quality, self.loads = scene, quality, loads
        self.log = log or (lambda msg: None)
        self.trees = [t for t in trees if t.active]
        self.stats = LinearStats()
        self.spf = max(1, round(quality.force_rate / scene.fps))  # steps per frame
        self.h = 1.0 / (scene.fps * self.spf)
        self.dt_update = self.h
        self.bones = Bones.of(self.trees)
        self.layout = ChainLayout.of(self.trees, self.bones.offsets, self.bones.pivot0,
                                     self.bones.tip0)
        t0 = time.perf_counter()
        self.model = LinearModel(self.bones, self.layout, loads.g, self.h, scene.prestress)
        self.stats.factor_seconds = time.perf_counter() - t0
        self.stats.dofs = self.model.n

    def locate(self, bone: int) -> tuple[str, int]:
        return locate(self.trees, self.bones.offsets, self.bones.bone_tree, bone)

    def loads_at(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Generalized external loads (dofs) at time t and state (q, v)."""
        model, b = self.model, self.bones
        com, vel, rot = model.kinematics(q, v)
        axis0 = (b.tip0 - b.pivot0) / np.maximum(b.length, 1e-12)[:, None]
        axis = axis0 + cross(rot, axis0)
        force = self.loads.forces(t, com, vel, axis, b.props, include_gravity=False,
                                  dt=self.h)
        pulls = b.pull_forces(t)
        if pulls is not None:
            force += pulls
        force = cap_loads(force, b.mass, t, self.stats, self.locate)
        return model.generalized(force) + model.f0

    def run(self, progress=None) -> list[TreeMotion]:
        scene, model = self.scene, self.model
        frames = scene.frame_count
        n, h = model.n, self.h
        q = np.zeros(n)
        v = np.zeros(n)
        a = model.mass_factor.solve(self.loads_at(0.0, q, v) - model.damping_stiffness(v, q))
        qs = np.zeros((frames, n))
        step = 0
        for f in range(1, frames):
            t_frame = time.perf_counter()
            for _ in range(self.spf):
                t0 = time.perf_counter()
                q_pred = q + h * v + (0.5 - BETA) * h * h * a
                v_pred = v + (1 - GAMMA) * h * a
                t = (step + 1) * h
                force = self.loads_at(t, q_pred, v_pred)
                t1 = time.perf_counter()
                rhs = force - model.damping_stiffness(v_pred, q_pred)
                a = model.factor.solve(rhs)
                q = q_pred + BETA * h * h * a
                v = v_pred + GAMMA * h * a
                step += 1
                t2 = time.perf_counter()
                self.stats.update_seconds += t1 - t0
                self.stats.step_seconds += t2 - t1
            qs[f] = q
            self.stats.frame_seconds.append(time.perf_counter() - t_frame)
            if progress is not None:
                progress(f, frames - 1)
        self.stats.steps = step
        rot, piv = pose_frames(self.layout, self.bones, qs)
        out = []
        for ti, tree in enumerate(self.trees):
            lo, hi = self.bones.offsets[ti], self.bones.offsets[ti + 1]
            out.append(TreeMotion(quaternions_from_matrices(rot.reshape(-1, 3, 3)).reshape(
                frames, -1, 4)[:, lo:hi], piv[:, lo:hi], []))
        return out


def pose_frames(layout: ChainLayout, bones: Bones, qs: np.ndarray):
    """World rotations (F, B, 3, 3) relative to rest and pivots (F, B, 3) of
    every bone from joint angles (F, 2B): each joint turns its bone by its
    plane-0 hinge, then its plane-1 hinge (about the axes as they sit in the
    parent's frame), composed down the tree, as MuJoCo composes two hinges."""
    frames = qs.shape[0]
    nb = bones.n
    axes = layout.normals()
    angles = qs.reshape(frames, nb, 2)
    rot = np.empty((frames, nb, 3, 3))
    piv = np.empty((frames, nb, 3))
    parent = bones.parent
    depth = depths(parent)
    for d in range(int(depth.max()) + 1 if nb else 0):
        b = np.nonzero(depth == d)[0]
        r0 = matrices_from_rotvec((angles[:, b, 0:1] * axes[b, 0]).reshape(-1, 3))
        r1 = matrices_from_rotvec((angles[:, b, 1:2] * axes[b, 1]).reshape(-1, 3))
        own = np.matmul(r0, r1).reshape(frames, len(b), 3, 3)
        p = parent[b]
        if d == 0:
            rot[:, b] = own
            piv[:, b] = bones.pivot0[b]
        else:
            fr = rot[:, p]
            rot[:, b] = np.matmul(fr, own)
            arm = bones.pivot0[b] - bones.pivot0[p]
            piv[:, b] = piv[:, p] + np.einsum("fmij,mj->fmi", fr, arm)
    return rot, piv
