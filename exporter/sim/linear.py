"""The planar LOD's linear tier: whole trees stepped implicitly in joint
space (joint_space.py) while they stay in the linear range.

Stepping: Newmark's average-acceleration rule (the trapezoidal rule:
unconditionally stable, no numerical damping, period error (omega h)^2/12),
at the quality's `linear_rate`; loads are evaluated once per step at the
predicted state, gravity's and the loads' dependence on the pose explicitly,
with gravity's tangent stiffness in the implicit matrix. Poses at frames
come from the hinge angles through the exact kinematics (two hinges per
joint, composed down the tree).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..rotations import matrices_from_rotvec, quaternions_from_matrices
from ..scene import Scene
from .common import Bones, SimTree, TreeMotion, cap_loads, locate
from .joint_space import JointSpace
from .layout import ChainLayout
from .loads import SceneLoads
from .quality import Quality
from .treefactor import depths

BETA, GAMMA = 0.25, 0.5  # Newmark's average acceleration


@dataclass
class LinearStats:
    steps: int = 0
    dofs: int = 0
    limited: int = 0
    first_limit: tuple | None = None
    build_seconds: float = 0.0
    step_seconds: float = 0.0
    update_seconds: float = 0.0
    frame_seconds: list[float] = field(default_factory=list)


class LinearSolver:
    """Simulate the active trees of a scene with the linear tier."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                 log=None):
        self.scene, self.quality, self.loads = scene, quality, loads
        self.log = log or (lambda msg: None)
        self.trees = [t for t in trees if t.active]
        self.stats = LinearStats()
        self.spf = max(1, math.ceil(quality.linear_rate / scene.fps - 1e-9))  # steps per frame
        self.h = 1.0 / (scene.fps * self.spf)
        t0 = time.perf_counter()
        self.bones = Bones.of(self.trees)
        layout = ChainLayout.of(self.trees, self.bones.offsets, self.bones.pivot0,
                                self.bones.tip0)
        hold = None if scene.prestress else np.zeros(2 * self.bones.n)
        self.model = JointSpace(self.bones, layout, loads.g, GAMMA * self.h,
                                BETA * self.h * self.h, hold)
        self.stats.build_seconds = time.perf_counter() - t0
        self.stats.dofs = self.model.n

    def locate(self, bone: int) -> tuple[str, int]:
        return locate(self.trees, self.bones.offsets, self.bones.bone_tree, bone)

    def rhs(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The equations' right-hand side at time t and state (q, v)."""
        model, b = self.model, self.bones
        kin = model.kinematics(q, v)
        pose = model.pose(kin, q)
        force = self.loads.forces(t, pose.com, pose.vcom, pose.axis, b.props,
                                  include_gravity=False, dt=self.h)
        pulls = b.pull_forces(t)
        if pulls is not None:
            force += pulls
        force = cap_loads(force, b.mass, t, self.stats, self.locate)
        force += b.mass[:, None] * self.loads.g
        return model.rhs(force, kin, pose, q)

    def run(self, progress=None) -> list[TreeMotion]:
        scene, model = self.scene, self.model
        frames = scene.frame_count
        n, h = model.n, self.h
        q = np.zeros(n)
        v = np.zeros(n)
        a = model.mass_factor.solve(self.rhs(0.0, q, v))
        qs = np.zeros((frames, n))
        step = 0
        for f in range(1, frames):
            t_frame = time.perf_counter()
            for _ in range(self.spf):
                t0 = time.perf_counter()
                q_pred = q + h * v + (0.5 - BETA) * h * h * a
                v_pred = v + (1 - GAMMA) * h * a
                step += 1
                rhs = self.rhs(step * h, q_pred, v_pred)
                t1 = time.perf_counter()
                a = model.factor.solve(rhs)
                q = q_pred + BETA * h * h * a
                v = v_pred + GAMMA * h * a
                self.stats.update_seconds += t1 - t0
                self.stats.step_seconds += time.perf_counter() - t1
            qs[f] = q
            self.stats.frame_seconds.append(time.perf_counter() - t_frame)
            if progress is not None:
                progress(f, frames - 1)
        self.stats.steps = step
        rot, piv = pose_frames(self.bones, qs)
        quats = quaternions_from_matrices(rot.reshape(-1, 3, 3)).reshape(frames, -1, 4)
        out = []
        for ti in range(len(self.trees)):
            lo, hi = self.bones.offsets[ti], self.bones.offsets[ti + 1]
            out.append(TreeMotion(quats[:, lo:hi], piv[:, lo:hi], []))
        return out


def pose_frames(bones: Bones, qs: np.ndarray):
    """World rotations (F, B, 3, 3) relative to rest and pivots (F, B, 3) of
    every bone from hinge angles (F, 2B): each joint turns its bone by its
    first hinge, then its second (about the axes as they sit in the parent's
    frame), composed down the tree, as MuJoCo composes two hinges."""
    frames = qs.shape[0]
    nb = bones.n
    axes = bones.hinges
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
        if d == 0:
            rot[:, b] = own
            piv[:, b] = bones.pivot0[b]
        else:
            p = parent[b]
            fr = rot[:, p]
            rot[:, b] = np.matmul(fr, own)
            piv[:, b] = piv[:, p] + np.einsum("fmij,mj->fmi", fr, bones.pivot0[b]
                                              - bones.pivot0[p])
    return rot, piv
