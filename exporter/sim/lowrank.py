"""Factorization and solves of a tree's joint-space matrix in time linear
in its degrees of freedom, however deep the tree (a long chain).

A joint-space matrix of a branched mechanism (mass, damping, stiffness of a
tree, or any combination) has an entry (i, j) only where one dof is an
ancestor of the other, and that entry has low rank: i an ancestor of j,

    A_ij = u_i . (D_ij v_j),

u_i (r,) a function of dof i alone (its hinge's spatial axis), v_j (r,) of
dof j and all it carries (their composite inertia times j's axis), D_ij a
0/1 diagonal mask: the identity while i and j are in one limb, `keep` once
a limb start lies between them (the limb damping couples one limb only).
On a chain every dof is an ancestor of every later one: stored entry by
entry (treefactor.py), A and its factor are dense (O(n^2) to solve, O(n^3)
to factor); a 2,000-bone pole then took minutes to sway.

Kept in this form, A = L^T D L (eliminating from the leaves to the roots,
Featherstone's LTDL) has L_ji = u_i . (D_ij w_j) / d_j, w_j = v_j - Q_j u_j
with Q_j (r, r) the sum of w_k w_k^T / d_k over j's eliminated descendants
k (masked where a limb starts): the articulated-body inertia's recursion.
Factoring is one (r, r) update per dof, a solve one r-vector per dof.

A solve runs block by block: a limb's dofs are cut into blocks of at most
BLOCK, each with its dense unit-triangular part of L and that part's
inverse; blocks of one block level (their count from the root) go in one
batch, and what a block passes to its ancestors is one r-vector (forward:
the sum of D w y / d; back: the sum of D u x). A solve costs a few batched
products per block level: the chains' length / BLOCK levels, not one per
dof, and no product grows with the depth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .treefactor import depths

BLOCK = 64  # dofs per solve block: fewer levels against s^2 work per dof pair


@dataclass
class TreeMatrix:
    """A symmetric matrix with tree sparsity in low-rank form. `parent` (n,):
    each dof's parent (-1: a root; parents first); `diagonal` (n,); `u`,
    `v` (n, r): A_ij = u_i . (D_ij v_j) for i a strict ancestor of j;
    `cut` (n,) bool: the dof starts a limb (D becomes `keep` across it);
    `keep` (r,) bool: the components that couple across limbs; `chains`:
    each limb's dofs, base first, each the parent of the next, covering
    every dof once."""

    parent: np.ndarray
    diagonal: np.ndarray
    u: np.ndarray
    v: np.ndarray
    cut: np.ndarray
    keep: np.ndarray
    chains: list[np.ndarray]

    def dense(self) -> np.ndarray:
        """A as a dense (n, n) array (checks: O(n^2))."""
        n = len(self.parent)
        a = np.diag(self.diagonal.astype(float))
        for j in range(n):
            mask = np.ones(self.u.shape[1], dtype=bool)
            i, k = self.parent[j], j
            while i >= 0:
                if self.cut[k]:
                    mask &= self.keep
                a[i, j] = a[j, i] = self.u[i] @ np.where(mask, self.v[j], 0.0)
                i, k = self.parent[i], i
        return a


@dataclass
class Level:
    """The blocks of one block level, padded to a common length: dof grid
    (c, length), the dof each block hangs on (c,), 1 or 0 per generator
    component for what passes between the block and its parent dof (c, r),
    the generators u and w / d of its dofs (c, length, r) and the inverse of
    L's diagonal block (c, length, length). Padding points at the scratch
    slot n."""

    dofs: np.ndarray
    hang: np.ndarray
    mask: np.ndarray
    u: np.ndarray
    w_over_d: np.ndarray
    inverse: np.ndarray
    ones: np.ndarray  # (length, length): 1 on and below the diagonal (prefix sums)


class LowRankFactor:
    """A = L^T D L of a symmetric positive definite TreeMatrix, and solves
    with it, both O(n r^2 + n BLOCK)."""

    def __init__(self, matrix: TreeMatrix):
        self.n = len(matrix.parent)
        r = matrix.u.shape[1]
        self.drop = ~np.asarray(matrix.keep, dtype=bool)
        w, diag = self._factor(matrix)
        # scratch slot n: zero generators, so padding adds nothing
        self.u = np.concatenate([matrix.u.astype(float), np.zeros((1, r))])
        self.w_over_d = np.concatenate([w / diag[:, None], np.zeros((1, r))])
        self.inv_diag = np.append(1.0 / diag, 0.0)
        self.levels = self._levels(matrix)

    def _factor(self, m: TreeMatrix) -> tuple[np.ndarray, np.ndarray]:
        """w_j and the pivots d_j, depth by depth from the deepest (vectorised
        over each depth): a dof is final once all its descendants are."""
        n, r = self.n, m.u.shape[1]
        depth = depths(m.parent)
        order = np.argsort(depth, kind="stable")
        bounds = np.searchsorted(depth[order], np.arange(int(depth.max()) + 2 if n else 1))
        slot = np.empty(n, dtype=np.int64)  # a dof's row in its depth's Q
        for d in range(len(bounds) - 1):
            slot[order[bounds[d]:bounds[d + 1]]] = np.arange(bounds[d + 1] - bounds[d])
        w = np.empty((n, r))
        diag = np.empty(n)
        deepest = len(bounds) - 2
        qk = np.zeros((bounds[deepest + 1] - bounds[deepest], r, r))  # the leaves': nothing below
        for d in range(deepest, -1, -1):
            k = order[bounds[d]:bounds[d + 1]]
            u = m.u[k]
            qu = np.matmul(qk, u[:, :, None])[:, :, 0]
            wk = m.v[k] - qu
            dk = m.diagonal[k] - (u * qu).sum(1)
            if not np.all(dk > 0):
                bad = int(k[np.argmin(dk)])
                raise np.linalg.LinAlgError(f"matrix not positive definite (pivot {bad}: "
                                            f"{dk.min():.3g})")
            w[k], diag[k] = wk, dk
            if d == 0:
                break
            # Q of the parent gets Q + w w^T / d, masked where a limb starts
            pass_up = qk + wk[:, :, None] * (wk / dk[:, None])[:, None, :]
            cut = m.cut[k]
            if cut.any():
                pass_up[np.ix_(cut, self.drop, np.ones(r, dtype=bool))] = 0.0
                pass_up[np.ix_(cut, np.ones(r, dtype=bool), self.drop)] = 0.0
            qk = np.zeros((bounds[d] - bounds[d - 1], r, r))  # the next depth's
            np.add.at(qk, slot[m.parent[k]], pass_up)
        return w, diag

    def _levels(self, m: TreeMatrix) -> list[Level]:
        """The limbs cut into blocks of at most BLOCK dofs, grouped by block
        level; each block's dense part of L inverted."""
        n = self.n
        blocks, level_of, block_of = [], [], np.full(n, -1, dtype=np.int64)
        for chain in m.chains:  # parents' limbs come first
            chain = np.asarray(chain, dtype=np.int64)
            for s in range(0, len(chain), BLOCK):
                dofs = chain[s:s + BLOCK]
                p = m.parent[dofs[0]]
                level_of.append(0 if p < 0 else level_of[block_of[p]] + 1)
                block_of[dofs] = len(blocks)
                blocks.append(dofs)
        level_of = np.asarray(level_of, dtype=np.int64)
        out = []
        for lev in range(int(level_of.max()) + 1 if blocks else 0):
            members = [blocks[b] for b in np.nonzero(level_of == lev)[0]]
            length, c = max(len(b) for b in members), len(members)
            grid = np.full((c, length), n, dtype=np.int64)
            for ci, b in enumerate(members):
                grid[ci, :len(b)] = b
            first = grid[:, 0]
            hang = np.where(m.parent[first] >= 0, m.parent[first], n)
            # L within a block: L[row, col] = u_col . w_row / d_row (col < row)
            block = np.matmul(self.w_over_d[grid], self.u[grid].transpose(0, 2, 1))
            block = np.tril(block, -1) + np.eye(length)
            mask = np.where(m.cut[first][:, None] & self.drop[None, :], 0.0, 1.0)
            out.append(Level(grid, hang, mask, self.u[grid], self.w_over_d[grid],
                             np.linalg.inv(block), np.tril(np.ones((length, length)))))
        return out

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x with A x = b, for b (n,)."""
        n, r = self.n, self.u.shape[1]
        work = np.append(np.asarray(b, dtype=float), 0.0)
        side = np.zeros((n + 1, r))  # what the blocks hanging on a dof pass it
        y = np.zeros(n + 1)
        for lev in reversed(self.levels):  # L^T y = b, deepest blocks first
            g = lev.dofs
            # from each dof to its block's base: the sums the dof's descendants
            # outside the block pass up
            z = np.matmul(lev.ones.T, side[g])  # (a triangular matmul: 3x a cumsum's speed)
            rhs = work[g] - (lev.u * z).sum(2)
            part = np.matmul(rhs[:, None, :], lev.inverse)[:, 0, :]
            y[g] = part
            up = (z[:, 0] + np.matmul(part[:, None, :], lev.w_over_d)[:, 0, :]) * lev.mask
            np.add.at(side, lev.hang, up)
            side[n] = 0.0
        y[n] = 0.0
        zz = y * self.inv_diag
        x = np.zeros(n + 1)
        seen = np.zeros((n + 1, r))  # sum of D u x over a dof and its ancestors
        for lev in self.levels:  # L x = z, roots first
            g = lev.dofs
            above = seen[lev.hang] * lev.mask
            rhs = zz[g] - np.matmul(lev.w_over_d, above[:, :, None])[:, :, 0]
            part = np.matmul(lev.inverse, rhs[:, :, None])[:, :, 0]
            x[g] = part
            seen[g] = above[:, None, :] + np.matmul(lev.ones, lev.u * part[:, :, None])
            x[n] = 0.0
            seen[n] = 0.0
        return x[:n]
