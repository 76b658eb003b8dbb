"""Sparse factorization of a tree's joint-space matrices, without fill-in.

A joint-space matrix of a branched mechanism (mass, damping, stiffness of a
tree, or any combination) has an entry (i, j) only where one degree of
freedom is an ancestor of the other. Factored as A = L^T D L (Featherstone,
"Efficient factorization of the joint-space inertia matrix for branched
kinematic trees", IJRR 2005), L keeps that pattern exactly: no fill-in, so
the factor costs what the matrix does, O(n x depth).

Storage is root-aligned: row j of L holds its entries to the ancestors of j
at depths 0 .. depth(j) - 1 (`rows[j, t]`, `ancestor[j, t]`). The
factorization runs level by level from the deepest dofs up, vectorised over
each level.

Solving runs chain by chain instead of dof by dof: a chain (a limb's dofs,
each the parent of the next) has a dense unit-triangular diagonal block of L
whose inverse is kept, and every dof in it shares the ancestors above the
chain. A solve is then a few batched matrix products per chain level
(trunk, branches, twigs, ...: a handful), not one step per dof depth (tens).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def depths(parent: np.ndarray) -> np.ndarray:
    """Depth of each node (roots 0); parents come before their children."""
    out = np.zeros(len(parent), dtype=np.int64)
    for j, p in enumerate(parent.tolist()):
        if p >= 0:
            out[j] = out[p] + 1
    return out


def ancestor_table(parent: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(n, max depth) table: entry (j, t) is j's ancestor at depth t (t <
    depth[j]), else -1. Parents come before their children."""
    n = len(parent)
    width = int(depth.max()) if n else 0
    table = np.full((n, max(width, 1)), -1, dtype=np.int64)
    for j, p in enumerate(parent.tolist()):
        if p >= 0:
            d = depth[p]
            table[j, :d] = table[p, :d]
            table[j, d] = p
    return table


@dataclass
class Level:
    """The chains of one chain level, padded to a common length: dof grid
    (c, length), their shared ancestors (c, q), L's block to those
    ancestors (c, length, q) and the inverse of L's diagonal block (c,
    length, length). Padding points at the scratch slot n."""

    dofs: np.ndarray
    above: np.ndarray
    to_above: np.ndarray
    inverse: np.ndarray


class TreeFactor:
    """A = L^T D L of a symmetric positive definite matrix with tree
    sparsity, and solves with it.

    `parent` (n,): each dof's parent dof (-1: a root; parents first).
    `diagonal` (n,) and `lower` (n, max depth): A's entries, root-aligned
    (lower[j, t] = A[j, ancestor at depth t]). `chains`: lists of dofs, each
    dof the parent of the next, covering every dof once; `chain_level`: the
    chain's level (a chain's parent chains have lower levels)."""

    def __init__(self, parent: np.ndarray, diagonal: np.ndarray, lower: np.ndarray,
                 chains: list[np.ndarray], chain_level: np.ndarray):
        self.n = len(parent)
        self.depth = depths(parent)
        self.ancestor = ancestor_table(parent, self.depth)
        rows, diag = self._factor(diagonal.astype(float), lower.astype(float))
        if not np.all(diag > 0):
            bad = int(np.argmin(diag))
            raise np.linalg.LinAlgError(f"matrix not positive definite (pivot {bad}: "
                                        f"{diag[bad]:.3g})")
        self.inv_diag = np.append(1.0 / diag, 0.0)  # scratch slot n
        self.levels = self._levels(rows, chains, np.asarray(chain_level))

    def _factor(self, diag: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Featherstone's LTDL, one depth level at a time from the deepest:
        a dof's row is final once all its descendants are eliminated."""
        n, depth, anc = self.n, self.depth, self.ancestor
        width = rows.shape[1]
        flat = rows.reshape(-1)
        for d in range(int(depth.max()) if n else 0, 0, -1):
            k = np.nonzero(depth == d)[0]
            r = rows[k, :d]
            a = r / diag[k, None]
            # ancestors at depth t lose a_t * (row of k) in their columns s < t
            up = anc[k, :d]
            t_idx, s_idx = np.tril_indices(d, -1)
            target = up[:, t_idx] * width + s_idx[None, :]
            # subtract in place at the targets (ufunc.at: cheaper than a
            # bincount over the whole matrix per depth level)
            np.subtract.at(flat, target.ravel(), (a[:, t_idx] * r[:, s_idx]).ravel())
            np.subtract.at(diag, up.ravel(), (a * r).ravel())
            rows[k, :d] = a
        return rows, diag

    def _levels(self, rows: np.ndarray, chains: list[np.ndarray],
                chain_level: np.ndarray) -> list[Level]:
        n, depth, anc = self.n, self.depth, self.ancestor
        out = []
        for lev in np.unique(chain_level):
            members = [np.asarray(chains[c], dtype=np.int64)
                       for c in np.nonzero(chain_level == lev)[0]]
            length = max(len(m) for m in members)
            q = max(int(depth[m[0]]) for m in members)
            c = len(members)
            grid = np.full((c, length), n, dtype=np.int64)
            above = np.full((c, max(q, 1)), n, dtype=np.int64)
            to_above = np.zeros((c, length, max(q, 1)))
            block = np.broadcast_to(np.eye(length), (c, length, length)).copy()
            for ci, m in enumerate(members):
                d0 = int(depth[m[0]])
                grid[ci, :len(m)] = m
                if d0:
                    above[ci, :d0] = anc[m[0], :d0]
                    to_above[ci, :len(m), :d0] = rows[m, :d0]
                for r in range(1, len(m)):
                    block[ci, r, :r] = rows[m[r], d0:d0 + r]
            out.append(Level(grid, above, to_above, np.linalg.inv(block)))
        return out

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x with A x = b, for b (n,)."""
        n = self.n
        work = np.zeros(n + 1)
        work[:n] = b
        y = np.zeros(n + 1)
        for lev in reversed(self.levels):  # L^T y = b, deepest chains first
            part = np.matmul(work[lev.dofs][:, None, :], lev.inverse)[:, 0, :]
            y[lev.dofs] = part
            push = np.matmul(part[:, None, :], lev.to_above)[:, 0, :]
            work -= np.bincount(lev.above.ravel(), push.ravel(), minlength=n + 1)
            work[n] = 0.0
        y[n] = 0.0
        z = y * self.inv_diag
        x = np.zeros(n + 1)
        for lev in self.levels:  # L x = z, trunks first
            rhs = z[lev.dofs] - np.matmul(lev.to_above, x[lev.above][:, :, None])[:, :, 0]
            x[lev.dofs] = np.matmul(lev.inverse, rhs[:, :, None])[:, :, 0]
            x[n] = 0.0
        return x[:n]
