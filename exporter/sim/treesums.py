"""Sums along a tree of chains: down the tree (each bone plus all it hangs
on) and up it (each bone plus all it carries), in a few vectorised steps.

The joint-space products of the linear tier are such sums: a bone's
velocity adds up the turns of every joint below it (prefix), and a joint's
torque adds up the forces of everything it carries (suffix). Walking the
tree bone by bone takes as many steps as it is deep; here each chain level
(trunks, branches, twigs, ...) is one cumulative sum over its chains laid
end to end, corrected at chain starts.

Values are (k, n) arrays, one row per quantity (structure of arrays): the
sums run along contiguous rows, which numpy does several times faster than
down the columns of an (n, k) array.
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
        order, levels = [], []
        for lev in range(int(chain_level.max()) + 1 if len(chains) else 0):
            members = np.nonzero(chain_level == lev)[0]
            start = len(order)
            lengths = np.array([len(chains[c]) for c in members])
            for c in members:
                order.extend(int(b) for b in chains[c])
            first = start + np.concatenate([[0], np.cumsum(lengths)[:-1]])  # chain starts
            levels.append((start, len(order), first, first + lengths - 1,
                           np.repeat(np.arange(len(members)), lengths), chain_parent[members]))
        self.order = np.asarray(order, dtype=np.int64)  # bones, level by level, chain by chain
        self.position = np.empty(n, dtype=np.int64)
        self.position[self.order] = np.arange(n)
        self.levels = []
        for lo, hi, first, last, row_chain, parent in levels:
            held = parent >= 0
            self.levels.append((slice(lo, hi), first - lo, last - lo, row_chain, held,
                                self.position[parent[held]]))

    def prefix(self, x: np.ndarray) -> np.ndarray:
        """(k, n): each bone's value plus those of every bone below it."""
        src = x[:, self.order]
        out = np.empty_like(src)
        for rows, first, _last, row_chain, held, parent in self.levels:
            block = src[:, rows]
            run = np.cumsum(block, axis=1)
            before = run[:, first] - block[:, first]  # the run up to each chain's start
            if held.any():
                before[:, held] -= out[:, parent]  # plus what its parent bone hangs on
            run -= before[:, row_chain]
            out[:, rows] = run
        return out[:, self.position]

    def suffix(self, x: np.ndarray) -> np.ndarray:
        """(k, n): each bone's value plus those of every bone it carries."""
        acc = x[:, self.order]
        out = np.empty_like(acc)
        for rows, first, last, row_chain, held, parent in reversed(self.levels):
            block = acc[:, rows]
            run = np.cumsum(block, axis=1)
            # from a bone to its chain's end: the run at the end - the run before the bone
            out[:, rows] = run[:, last][:, row_chain] - run + block
            if held.any():  # each chain's total onto the bone it hangs on
                np.add.at(acc.T, parent, out[:, rows][:, first[held]].T)
        return out[:, self.position]

    def chain_suffix(self, x: np.ndarray) -> np.ndarray:
        """(k, n): each bone's value plus those of the bones after it in its
        own chain (not what hangs on them)."""
        src = x[:, self.order]
        out = np.empty_like(src)
        for rows, _first, last, row_chain, _held, _parent in self.levels:
            block = src[:, rows]
            run = np.cumsum(block, axis=1)
            out[:, rows] = run[:, last][:, row_chain] - run + block
        return out[:, self.position]
