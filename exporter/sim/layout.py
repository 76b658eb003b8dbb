"""The planar model's chain layout, shared by its tiers (linear and pymunk).

A chain is a rig limb (a limb and its sympodial continuations). It bends in
two perpendicular planes through its chord d: plane 0 contains the
direction e of the tree's dominant horizontal load (wind, pull, felling or
blast direction; else gravity, else a world axis), plane 1 is turned 90
degrees about d. A bone's rotation relative to the frame its chain moves in
(the bone it hangs on; the world for a root chain) is the rotation vector
a0 n0 + a1 n1, with n0 = e x d, n1 = (e x d) x d = -e the planes' normals and
a0, a1 the sums of the chain's joint angles up to that bone in each plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rotations import cross
from .common import SimTree


def plane_direction(d: np.ndarray, load: np.ndarray | None) -> np.ndarray:
    """In-plane bending direction e (unit, perpendicular to the chord d)."""
    for cand in (load, np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0]),
                 np.array([0.0, 1.0, 0.0])):
        if cand is None:
            continue
        e = cand - (cand @ d) * d
        n = np.linalg.norm(e)
        if n > 0.25:
            return e / n
    raise AssertionError("no perpendicular found")  # pragma: no cover


@dataclass
class ChainLayout:
    """Chains of a set of trees (global bone numbering, trees in order)."""

    chain_bones: list[np.ndarray]  # bones of each chain, base first
    chain_parent: np.ndarray  # (C,) the bone a chain hangs on, -1 = ground
    chain_tree: np.ndarray  # (C,)
    chain_e: np.ndarray  # (C, 3) plane 0's bending direction
    chain_d: np.ndarray  # (C, 3) the chord
    chain_depth: np.ndarray  # (C,) 0 for root chains
    bone_chain: np.ndarray  # (B,)
    bone_frame: np.ndarray  # (B,) the bone whose frame a bone's chain moves in, -1 = world

    @classmethod
    def of(cls, trees: list[SimTree], offsets: np.ndarray, pivot0: np.ndarray,
           tip0: np.ndarray) -> ChainLayout:
        n = int(offsets[-1])
        chain_bones, chain_parent, chain_tree, es, ds = [], [], [], [], []
        bone_chain = np.zeros(n, dtype=np.int64)
        for ti, t in enumerate(trees):
            o = int(offsets[ti])
            for limb in t.rig.limbs:
                bones = np.asarray(limb.bones, dtype=np.int64) + o
                bone_chain[bones] = len(chain_bones)
                chain_bones.append(bones)
                chain_parent.append(limb.parent_bone + o if limb.parent_bone >= 0 else -1)
                chain_tree.append(ti)
                chord = tip0[bones[-1]] - pivot0[bones[0]]
                if np.linalg.norm(chord) < 1e-6:
                    chord = tip0[bones[0]] - pivot0[bones[0]]
                norm = np.linalg.norm(chord)
                d = chord / norm if norm > 1e-9 else np.array([0.0, 0.0, 1.0])
                es.append(plane_direction(d, t.load_direction))
                ds.append(d)
        parent = np.asarray(chain_parent, dtype=np.int64)
        depth = np.zeros(len(parent), dtype=np.int64)
        for ci, p in enumerate(parent.tolist()):  # parent chains come first
            depth[ci] = 0 if p < 0 else depth[bone_chain[p]] + 1
        frame = parent[bone_chain] if n else np.zeros(0, dtype=np.int64)
        return cls(chain_bones, parent, np.asarray(chain_tree, dtype=np.int64),
                   np.asarray(es).reshape(-1, 3), np.asarray(ds).reshape(-1, 3), depth,
                   bone_chain, frame)

    @property
    def chain_first(self) -> np.ndarray:
        return np.asarray([b[0] for b in self.chain_bones], dtype=np.int64)

    def normals(self) -> np.ndarray:
        """(B, 2, 3): each bone's two bending-plane normals n0 = e x d, n1 = -e."""
        e = self.chain_e[self.bone_chain]
        d = self.chain_d[self.bone_chain]
        return np.stack([cross(e, d), -e], axis=1)
