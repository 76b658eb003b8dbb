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

from dataclasses import dataclass

import numpy as np

MAX_ROUNDS = 3  # past this many chains on one bone, one np.add.at call is quicker


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
        self.levels = [_Level.of(lo, hi, first, last, row_chain, parent, self.position)
                       for lo, hi, first, last, row_chain, parent in levels]

    # The sums gather with ndarray.take, not fancy indexing (x[:, idx]): the
    # same values, two to four times faster on the few hundred bones of a
    # tree or a chunk, where each call's overhead is most of its cost.

    def prefix(self, x: np.ndarray) -> np.ndarray:
        """(k, n): each bone's value plus those of every bone below it."""
        src = x.take(self.order, axis=1)
        out = np.empty_like(src)
        for lev in self.levels:
            block = src[:, lev.rows]
            run = block.cumsum(axis=1)
            before = run.take(lev.first, axis=1)  # the run up to each chain's start
            before -= block.take(lev.first, axis=1)
            if lev.hangs:  # plus what its parent bone hangs on
                before -= out.take(lev.parent, axis=1)
            run -= before.take(lev.row_chain, axis=1)
            out[:, lev.rows] = run
        return out.take(self.position, axis=1)

    def suffix(self, x: np.ndarray) -> np.ndarray:
        """(k, n): each bone's value plus those of every bone it carries."""
        acc = x.take(self.order, axis=1)
        out = np.empty_like(acc)
        for lev in reversed(self.levels):
            tail = lev.to_chain_end(acc[:, lev.rows])
            out[:, lev.rows] = tail
            if lev.hangs:  # each chain's total onto the bone it hangs on
                total = tail.take(lev.first, axis=1)
                if lev.rounds is None:
                    np.add.at(acc.T, lev.parent, total.T)
                    continue
                # in rounds of distinct bones, in the chains' order: the
                # additions np.add.at makes, in its order, in fewer calls
                for pick, bones in lev.rounds:
                    acc[:, bones] += total if pick is None else total.take(pick, axis=1)
        return out.take(self.position, axis=1)

    def chain_suffix(self, x: np.ndarray) -> np.ndarray:
        """(k, n): each bone's value plus those of the bones after it in its
        own chain (not what hangs on them)."""
        src = x.take(self.order, axis=1)
        out = np.empty_like(src)
        for lev in self.levels:
            out[:, lev.rows] = lev.to_chain_end(src[:, lev.rows])
        return out.take(self.position, axis=1)


@dataclass(frozen=True)
class _Level:
    """One chain level laid end to end in the sums' order: its rows, each
    chain's first and last row within them and each row's chain; whether
    its chains hang on bones (all of them do but a root level's), the
    positions of those bones, and `rounds` of (which chains (None: all),
    their bones' positions) with no bone twice in a round (None: more than
    MAX_ROUNDS rounds, np.add.at instead)."""

    rows: slice
    first: np.ndarray
    last: np.ndarray
    row_chain: np.ndarray
    hangs: bool
    parent: np.ndarray
    rounds: tuple | None

    def to_chain_end(self, block: np.ndarray) -> np.ndarray:
        """(k, rows): each row's value plus those after it in its chain: the
        run at the chain's end less the run before the row."""
        run = block.cumsum(axis=1)
        tail = run.take(self.last, axis=1).take(self.row_chain, axis=1)
        tail -= run
        tail += block
        return tail

    @classmethod
    def of(cls, lo: int, hi: int, first: np.ndarray, last: np.ndarray, row_chain: np.ndarray,
           parent: np.ndarray, position: np.ndarray) -> _Level:
        hangs = bool((parent >= 0).any())
        if hangs and not (parent >= 0).all():
            raise ValueError("a chain level mixes chains that hang on a bone and chains "
                             "that hang on nothing")
        at = position[parent] if hangs else np.zeros(0, dtype=np.int64)
        seen: dict[int, int] = {}
        nth = np.zeros(len(at), dtype=np.int64)  # how many chains before hang on its bone
        for k, b in enumerate(at.tolist()):
            nth[k] = seen.get(b, 0)
            seen[b] = nth[k] + 1
        rounds = []
        for r in range(int(nth.max()) + 1 if len(nth) else 0):
            pick = np.nonzero(nth == r)[0]
            rounds.append((None if len(pick) == len(at) else pick, at[pick]))
        return cls(slice(lo, hi), first - lo, last - lo, row_chain, hangs, at,
                   tuple(rounds) if len(rounds) <= MAX_ROUNDS else None)
