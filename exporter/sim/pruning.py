"""A tree that lost parts, back in the linear tier: its rig without them
(`pruned_tree`), and its motion put back on every bone of the grown tree,
the parts that broke off lying where they came to rest (`BoneMap`).

A nonlinear engine hands a broken tree back once what broke off lies still
(handoff.BrokenOff). From then on the tree's runs hold only its standing
bones, with the prestress their springs had (the wood keeps its set); the
parts on the ground keep their last pose and their energy (J) stays in the
tree's audit as a constant."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..rig import Rig, RigLimb, bone_depths
from .common import SimTree, TreeMotion
from .handoff import BrokenOff, HandOff


def pruned_rig(rig: Rig, standing: np.ndarray) -> Rig:
    """`rig` with only its `standing` bones (B,) bool, renumbered in order
    (parents still first); segments of the others map to bone -1. The
    limbs' frequencies and the trunk's stay the grown tree's (they set
    the damping rates, which the standing wood keeps)."""
    keep = np.nonzero(standing)[0]
    new = np.full(rig.n_bones + 1, -1, dtype=np.int64)  # old bone (or -1) -> new bone
    new[keep] = np.arange(len(keep))
    parent = new[rig.bone_parent[keep]]
    limbs, limb_new = [], np.full(len(rig.limbs), -1, dtype=np.int64)
    for li, limb in enumerate(rig.limbs):
        bones = [int(new[b]) for b in limb.bones if standing[b]]
        if bones:
            limb_new[li] = len(limbs)
            limbs.append(RigLimb(int(new[limb.parent_bone]), bones, limb.path))
    kept_limbs = np.nonzero(limb_new >= 0)[0]
    return replace(
        rig, seg_bone=new[rig.seg_bone], bone_limb=limb_new[rig.bone_limb[keep]],
        bone_parent=parent, bone_depth=bone_depths(parent), pivot=rig.pivot[keep],
        tip=rig.tip[keep], mass=rig.mass[keep], com=rig.com[keep], inertia=rig.inertia[keep],
        radius=rig.radius[keep], wood_area=rig.wood_area[keep], leaf_area=rig.leaf_area[keep],
        k=rig.k[keep], zeta=rig.zeta[keep], alpha=rig.alpha[keep], cone=rig.cone[keep],
        strength=rig.strength[keep], limbs=limbs, limb_omega=rig.limb_omega[kept_limbs])


def pruned_tree(tree: SimTree, broken: BrokenOff) -> SimTree:
    """The standing part of `tree` (its bones numbered as the tree's
    runs number them now), keeping its springs' prestress."""
    standing = broken.standing
    hinges = np.repeat(standing, 2)
    return replace(tree, rig=pruned_rig(tree.rig, standing), hold=broken.hold[hinges])


def standing_start(ho: HandOff) -> HandOff:
    """A hand-back with its state on the standing bones only."""
    hinges = np.repeat(ho.broken.standing, 2)
    return replace(ho, q=ho.q[hinges], v=ho.v[hinges])


@dataclass
class BoneMap:
    """Where the bones of a tree's runs sit among the grown tree's `bones`:
    `index` (the runs' bone -> grown bone), the pose (x y z w, m) the
    fallen bones rest in, and their energy (J)."""

    bones: int
    index: np.ndarray
    quaternions: np.ndarray
    pivots: np.ndarray
    energy: float = 0.0

    @classmethod
    def whole(cls, bones: int) -> BoneMap:
        return cls(bones, np.arange(bones), np.zeros((bones, 4)), np.zeros((bones, 3)))

    @property
    def pruned(self) -> bool:
        return len(self.index) < self.bones

    def lose(self, broken: BrokenOff) -> None:
        """The runs' tree lost the bones that are not `broken.standing`."""
        gone = self.index[~broken.standing]
        self.quaternions[gone] = broken.quaternions[~broken.standing]
        self.pivots[gone] = broken.pivots[~broken.standing]
        self.energy += broken.energy
        self.index = self.index[broken.standing]

    def grown(self, m: TreeMotion, start: int) -> TreeMotion:
        """`m` (frames from `start` on) on every grown bone: the fallen ones
        at rest, their energy added to the tree's."""
        if not self.pruned:
            return m
        frames = m.quaternions.shape[0]
        fallen = np.setdiff1d(np.arange(self.bones), self.index)

        def spread(values: np.ndarray, rest: np.ndarray) -> np.ndarray:
            out = np.empty((values.shape[0], self.bones, values.shape[2]))
            out[:, self.index] = values
            out[:, fallen] = rest[fallen]
            return out

        quats, pivots = spread(m.quaternions, self.quaternions), spread(m.pivots, self.pivots)
        quats[:start], pivots[:start] = 0.0, 0.0  # (frames before the run are not its own)
        energy = None if m.energy is None else m.energy + np.where(
            np.arange(frames) >= start, self.energy, 0.0)
        extra = {}
        if m.extra_quaternions is not None:
            extra = {"extra_quaternions": spread(m.extra_quaternions, self.quaternions),
                     "extra_pivots": spread(m.extra_pivots, self.pivots)}
        return replace(m, quaternions=quats, pivots=pivots, energy=energy, **extra)
