"""Sums along a tree of chains: down the tree (each bone plus all it hangs
on) and up it (each bone plus all it carries), in a few vectorised steps.

The joint-space products of the linear tier are such sums: a bone's
velocity adds up the turns of every joint below it (prefix), and a joint's
torque adds up the forces of everything it carries (suffix). Walking the
tree bone by bone takes as many steps as it is deep; here each chain level
(trunks, branches, twigs, ...) is one padded cumulative sum along its
chains.
"""

from __future__ import annotations

import numpy as np


class ChainSums:
    """`chains`: bones of each chain, base first (every bone in exactly one);
    `chain_parent`: the bone a chain hangs on (-1: none); `chain_level`:
    0 for chains that hang on nothing, a parent chain's level + 1 otherwise;
    `n`: bone count."""

    def __init__(self, chains: list[np.ndarray], chain_parent: np.ndarray,
                 chain_level: np.ndarray, n: int):
        self.n = n
        self.levels = []
        for lev in range(int(chain_level.max()) + 1 if len(chains) else 0):
            members = np.nonzero(chain_level == lev)[0]
            length = max(len(chains[c]) for c in members)
            grid = np.full((len(members), length), n, dtype=np.int64)  # n: scratch row
            for i, c in enumerate(members):
                grid[i, :len(chains[c])] = chains[c]
            frame = np.where(chain_parent[members] >= 0, chain_parent[members], n)
            self.levels.append((grid, frame))

    def prefix(self, x: np.ndarray) -> np.ndarray:
        """(n, k): each bone's value plus those of every bone below it."""
        out = np.zeros((self.n + 1,) + x.shape[1:])
        src = np.concatenate([x, np.zeros((1,) + x.shape[1:])])
        for grid, frame in self.levels:
            run = np.cumsum(src[grid], axis=1)
            run += out[frame][:, None]
            out[grid] = run
            out[self.n] = 0.0
        return out[:self.n]

    def suffix(self, x: np.ndarray) -> np.ndarray:
        """(n, k): each bone's value plus those of every bone it carries."""
        acc = np.concatenate([x, np.zeros((1,) + x.shape[1:])])
        out = np.zeros_like(acc)
        for grid, frame in reversed(self.levels):
            run = np.cumsum(acc[grid][:, ::-1], axis=1)[:, ::-1]
            out[grid] = run
            np.add.at(acc, frame, run[:, 0])  # each chain's total onto its parent bone
            acc[self.n] = 0.0
        return out[:self.n]

    def chain_suffix(self, x: np.ndarray) -> np.ndarray:
        """(n, k): each bone's value plus those of the bones after it in its
        own chain (not what hangs on them)."""
        src = np.concatenate([x, np.zeros((1,) + x.shape[1:])])
        out = np.zeros_like(src)
        for grid, _frame in self.levels:
            out[grid] = np.cumsum(src[grid][:, ::-1], axis=1)[:, ::-1]
        return out[:self.n]
