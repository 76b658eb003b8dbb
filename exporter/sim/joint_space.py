"""The joint-space equations of whole trees, linearised about the grown
shape or a pose they turned to, for the linear tier (linear.py).

Coordinates: every bone's joint is two hinges at its pivot, perpendicular to
the bone and to each other (common.hinge_axes: swing without twist), the
second turning with the first, as the reference's. q (2B,) are the hinge
angles from the grown shape, dof 2b + k being bone b's hinge k. The
equations of motion,

    M q'' + C q' + K_s q = J(q)^T (F + m g) - tau_g0,

have M the joint-space mass matrix of the whole tree (every bone's mass and
inertia, children and parents coupled both ways), K_s the joint springs
(the rig's k on both hinges), C the rig's structural damping (each limb's
block of M times its alpha, the reference's form), F the external loads at
the bones' centres of mass, m g gravity and tau_g0 the springs' prestress
(gravity's torques at rest, so the grown shape is the equilibrium; 0
without prestress). J(q)^T is evaluated at the current pose (a branch
swung by a gust carries its loads on turned lever arms), with bone
rotations exp(sum of the hinge rotation vectors below them), exact for
bending in one plane. M, C, gravity's stiffness K_g and the Jacobian that
gives the bones' velocities from the hinge rates are taken at one pose:
the grown shape, then the mean pose a tree has turned to (`linearise_at`,
when the linear tier asks; docs/physics.md, "Linearised where the tree
is").

Implicit steps need the tangent of the right-hand side: K_s plus K_g,
gravity's geometric stiffness (a hanging twig's pendulum
stiffness, a stem's P-delta softening). M, C and K_g have entries only
between a dof and its ancestors, so A = M + c1 C + c2 (K_s + K_g) factors
without fill-in (treefactor.py, entry by entry; for trees deeper than
EXPLICIT_DEPTH, lowrank.py, in low-rank form, linear in the dofs); the products the steps need (J^T F, C v,
poses) are sums along the tree (treesums.py), never matrices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rotations import cross, cross_rows, rotation_rows, turn_rows
from .common import Bones
from .layout import ChainLayout
from .lowrank import LowRankFactor, TreeMatrix
from .rules import limb_damping
from .treefactor import TreeFactor, ancestor_table
from .treesums import ChainSums

EXPLICIT_DEPTH = 256  # dofs: deeper trees take the low-rank factor (docs/physics.md)


@dataclass
class Pose:
    """Bones' pose as rows (first order in the angles for velocities):
    rotation relative to rest (3, 3, B), pivot, COM, COM velocity, unit
    axis, and the current axes of each joint's two hinges (3, B)."""

    rot: np.ndarray
    pivot: np.ndarray
    com: np.ndarray
    vcom: np.ndarray
    axis: np.ndarray
    first: np.ndarray
    second: np.ndarray


@dataclass
class Entries:
    """The matrices' entries between dof i and its descendant (or itself) j,
    from the subtree moments of j's bone: hinge pivots p and axes n (2B, 3),
    the subtree's mass s0 (2B,) kg, first and second moments s1 (2B, 3), s2
    (2B, 3, 3) and summed inertia si (2B, 3, 3), positions from any origin,
    `lever` sum m (c - p_j) (2B, 3) kg m, gravity (3,) m/s^2."""

    p: np.ndarray
    axis: np.ndarray
    s0: np.ndarray
    s1: np.ndarray
    s2: np.ndarray
    si: np.ndarray
    lever: np.ndarray
    gravity: np.ndarray

    def mass(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """M_ij = sum over the bodies both hinges move of m (n_i x (c - p_i)) .
        (n_j x (c - p_j)) + n_i I n_j, expanded into dot products."""
        p, axis, s0, s1 = self.p, self.axis, self.s0, self.s1
        tr2 = np.trace(self.s2, axis1=1, axis2=2)
        s2n = np.einsum("nij,nj->ni", self.s2 - self.si, axis)  # (s2 - si) n_j
        s1n = (s1 * axis).sum(1)
        pi, pj, ni, nj = p[i], p[j], axis[i], axis[j]
        scal = tr2[j] - (s1[j] * (pi + pj)).sum(1) + s0[j] * (pi * pj).sum(1)
        ni_pj, pi_nj = (ni * pj).sum(1), (pi * nj).sum(1)
        return ((ni * nj).sum(1) * scal - (ni * s2n[j]).sum(1)
                + (ni * s1[j]).sum(1) * pi_nj + ni_pj * s1n[j] - s0[j] * ni_pj * pi_nj)

    def stiffness(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Gravity's K_g entries: d2 V / dq_i dq_j = -g . (n_i x (n_j x R_j)),
        n_i x (n_j x R) = n_j (n_i.R) - R (n_i.n_j) (= n_i . gravity_axis_j)."""
        ni, nj, r, g = self.axis[i], self.axis[j], self.lever[j], self.gravity
        return -((nj @ g) * (ni * r).sum(1) - (r @ g) * (ni * nj).sum(1))

    def gravity_axis(self) -> np.ndarray:
        """g_j (2B, 3) N m: K_g's entry (i, j) is n_i . g_j."""
        g, r, nj = self.gravity, self.lever, self.axis
        return -((nj @ g)[:, None] * r - (r @ g)[:, None] * nj)


class JointSpace:
    """The system of some bones (whole trees, parents before children).
    `hold` (2B,) N m: each hinge spring's prestress torque (tau_g0 of the
    grown tree; kept when parts break off, as the wood keeps its set).
    `c1`, `c2`: the implicit rule's weights of C and K in its matrix."""

    def __init__(self, bones: Bones, layout: ChainLayout, gravity: np.ndarray, c1: float,
                 c2: float, hold: np.ndarray | None = None):
        self.bones, self.layout = bones, layout
        nb = bones.n
        n = self.n = 2 * nb
        self.axis = bones.hinges.reshape(n, 3)
        self.dof_bone = dof_bone = np.repeat(np.arange(nb), 2)
        parent = np.empty(n, dtype=np.int64)
        parent[0::2] = np.where(bones.parent >= 0, 2 * bones.parent + 1, -1)
        parent[1::2] = np.arange(0, n, 2)
        self.parent = parent
        # a bone's first hinge hangs on its parent's second: dof depths from the bones'
        self.depth = 2 * bones.depth[dof_bone] + np.arange(n) % 2
        self.sums = ChainSums(layout.chain_bones, layout.chain_parent, layout.chain_depth, nb)
        self.k_spring = np.repeat(bones.k, 2)
        self.limb = limb = layout.bone_chain[dof_bone]
        # a dof whose parent is in another limb (or none): the limb damping
        # couples nothing across it
        self.cut = (parent < 0) | (limb != limb[np.maximum(parent, 0)])
        self.alpha = bones.alpha[dof_bone]
        # a deep tree (a long chain) takes the low-rank factor (lowrank.py),
        # in time linear in its dofs, about each tree's base (not the world's
        # origin: its recursion then cancels no more digits than a tree's
        # size); the others the explicit one (treefactor.py), entry by entry
        # (O(n x depth)), faster for bushy trees' short paths
        self.deep = n > 0 and int(self.depth.max()) > EXPLICIT_DEPTH
        self.origin = bones.pivot0[bones.offsets[bones.bone_tree]] if self.deep else None
        self.gravity = np.asarray(gravity, dtype=float)
        # the solve runs chain by chain: a bone chain's dofs, in order
        self._chains = [np.stack([2 * b, 2 * b + 1], 1).ravel() for b in layout.chain_bones]
        self._steps = (c1, c2)
        # the prestress: gravity's torques on the grown shape
        m, c = bones.mass, bones.com0
        s0 = self.sums.suffix(m[None, :])[0]
        s1 = self.sums.suffix((m[:, None] * c).T).T
        lever = s1[dof_bone] - s0[dof_bone][:, None] * bones.pivot0[dof_bone]
        self.tau_g0 = (self.axis * cross(lever, np.broadcast_to(self.gravity, lever.shape))).sum(1)
        self.hold = self.tau_g0.copy() if hold is None else hold
        self._s0 = s0
        # next bone along each bone's chain (-1: its last)
        nxt = np.full(nb, -1, dtype=np.int64)
        for cb in layout.chain_bones:
            nxt[cb[:-1]] = cb[1:]
        self._next = nxt
        # constants of the products (tree sums, no matrix is formed), as rows
        # (structure of arrays): bone b's entries in column b
        h = bones.hinges
        cp = cross(self.axis, bones.pivot0[dof_bone]).reshape(nb, 2, 3)
        self.n0, self.n1 = h[:, 0].T.copy(), h[:, 1].T.copy()  # hinge axes (3, B)
        self.cp0, self.cp1 = cp[:, 0].T.copy(), cp[:, 1].T.copy()  # n x p
        self.second_turn = cross(h[:, 0], h[:, 1]).T.copy()  # d(hinge 1)/dq_0
        has = bones.parent >= 0
        self.arm = (bones.pivot0 - np.where(has[:, None], bones.pivot0[np.maximum(
            bones.parent, 0)], 0.0)).T.copy()  # pivot from its parent's pivot, at rest
        axis0 = (bones.tip0 - bones.pivot0) / np.maximum(bones.length, 1e-12)[:, None]
        self.axis0 = axis0.T.copy()
        self.com_arm = (bones.com0 - bones.pivot0).T.copy()
        self.tip0 = bones.tip0.T.copy()
        self.inertia = bones.inertia.transpose(1, 2, 0).copy()  # (3, 3, B)
        self.roots = np.nonzero(~has)[0]
        self.parent_or_self = np.where(has, bones.parent, np.arange(nb))
        fr = layout.bone_frame
        self.frame_row = np.where(fr >= 0, fr, nb)  # the frame bone's column, nb: the world
        self.turn_at = np.zeros((3, nb))  # the bones' rotation vectors where linearised
        self._linearise(bones.pivot0, bones.com0, bones.inertia, bones.hinges)

    def linearise_at(self, q: np.ndarray) -> None:
        """Take M, C, K_g and the rates' Jacobian at the pose of hinge angles
        `q` (2B,) rad instead of the grown shape's (the equations'
        coordinates, springs and prestress stay the grown shape's)."""
        kin = self.kinematics(q, np.zeros(self.n))
        pose = self.pose(kin, q)
        rot = pose.rot.transpose(2, 0, 1)
        inertia = rot @ self.bones.inertia @ rot.transpose(0, 2, 1)
        hinges = np.stack([pose.first.T, pose.second.T], 1)
        self.turn_at = kin[0:3].copy()  # the rotation vectors: `turns(q)`, already summed
        self._linearise(pose.pivot.T, pose.com.T, inertia, hinges)

    def _linearise(self, pivot: np.ndarray, com: np.ndarray, inertia: np.ndarray,
                   hinges: np.ndarray) -> None:
        """M, C, K_g and the rates' Jacobian for bones at pivots, COMs (B, 3)
        m, inertia (B, 3, 3) kg m^2 and hinge axes (B, 2, 3)."""
        nb, dof_bone = self.bones.n, self.dof_bone
        m, sums = self.bones.mass, self.sums
        # subtree moments of every bone (itself and all it carries)
        s0 = self._s0
        s1 = sums.suffix((m[:, None] * com).T).T
        s2 = sums.suffix((m[:, None, None] * com[:, :, None] * com[:, None, :]).reshape(nb, 9).T
                         ).T.reshape(nb, 3, 3)
        si = sums.suffix(inertia.reshape(nb, 9).T).T.reshape(nb, 3, 3)
        axis = hinges.reshape(self.n, 3)
        p = pivot[dof_bone]
        pr, s1o, s2o = p, s1[dof_bone], s2[dof_bone]
        if self.deep:  # about each tree's base o: fewer digits cancel
            o = self.origin
            c = com - o
            pr = p - o[dof_bone]
            s1o = sums.suffix((m[:, None] * c).T).T[dof_bone]
            s2o = sums.suffix((m[:, None, None] * c[:, :, None] * c[:, None, :]).reshape(
                nb, 9).T).T.reshape(nb, 3, 3)[dof_bone]
        lever = s1o - s0[dof_bone][:, None] * pr  # sum m (c - p_j) over a dof's subtree
        self.entries = entries = Entries(pr, axis, s0[dof_bone], s1o, s2o, si[dof_bone], lever,
                                         self.gravity)
        every = np.arange(self.n)
        m_diag = entries.mass(every, every)
        k_diag = self.k_spring + entries.stiffness(every, every)
        # structural damping: each limb's block of M times its alpha
        self.diagonals = (m_diag, limb_damping(m_diag, self.alpha), k_diag)
        self._factors: dict[tuple[float, float], TreeFactor | LowRankFactor] = {}
        self._pairs = None if self.deep else self.pair_entries()
        if self.deep:
            self._low_rank(pr, axis, s0[dof_bone], s1o, s2o, si[dof_bone])
        # the rates' Jacobian: hinge axes and n x p at this pose, and COMs
        cp = cross(axis, p).reshape(nb, 2, 3)
        self.rate_n0, self.rate_n1 = hinges[:, 0].T.copy(), hinges[:, 1].T.copy()
        self.rate_cp0, self.rate_cp1 = cp[:, 0].T.copy(), cp[:, 1].T.copy()
        self.rate_com = com.T.copy()
        # damping: a bone's own mass plus the side chains hanging on it (its
        # subtree without the rest of its chain), moved by its limb alone
        nxt = self._next
        more = nxt >= 0
        nx = np.maximum(nxt, 0)
        l0 = s0 - np.where(more, s0[nx], 0.0)
        l1 = s1 - np.where(more[:, None], s1[nx], 0.0)
        l2 = s2 - np.where(more[:, None, None], s2[nx], 0.0)
        li = si - np.where(more[:, None, None], si[nx], 0.0)
        spin = np.trace(l2, axis1=1, axis2=2)[:, None, None] * np.eye(3) - l2 + li
        self.lump = (l0, l1.T.copy(), spin.transpose(1, 2, 0).copy())

    def _low_rank(self, p: np.ndarray, axis: np.ndarray, s0: np.ndarray, s1: np.ndarray,
                  s2: np.ndarray, si: np.ndarray) -> None:
        """The entries between a dof i and its descendant j in low-rank form
        (lowrank.py), from Entries' moments per dof: M_ij = S_i . (I_j S_j),
        S_i hinge i's spatial axis (n_i, p_i x n_i), I_j the spatial inertia
        of all hinge j moves; K_g's entry is n_i . g_j."""
        moved = cross(p, axis)
        self.spatial = np.concatenate([axis, moved], 1)
        turn = (np.trace(s2, axis1=1, axis2=2)[:, None] * axis
                - np.einsum("nij,nj->ni", s2 - si, axis) + cross(s1, moved))
        push = cross(axis, s1) + s0[:, None] * moved
        self.inertia_axis = np.concatenate([turn, push], 1)
        self.gravity_axis = self.entries.gravity_axis()

    @property
    def factor(self) -> TreeFactor | LowRankFactor:
        """The factored M + c1 C + c2 K of the tier's whole step (built when
        first asked: while its steps are split, only the parts' is)."""
        return self.factor_for(*self._steps)

    @property
    def mass_factor(self) -> TreeFactor | LowRankFactor:
        """The factored M (for accelerations from forces)."""
        return self.factor_for(0.0, 0.0)

    def factor_for(self, c1: float, c2: float) -> TreeFactor | LowRankFactor:
        """The factored M + c1 C + c2 K (cached)."""
        key = (c1, c2)
        if key not in self._factors:
            if self.deep:
                self._factors[key] = LowRankFactor(self.tree_matrix(c1, c2))
            else:
                (m_diag, c_diag, k_diag), (jj, tt, shape, m_low, c_low, k_low) = \
                    self.diagonals, self._pairs[1:]
                rows = np.zeros(shape)
                rows[jj, tt] = m_low + c1 * c_low + c2 * k_low
                self._factors[key] = TreeFactor(self.parent, m_diag + c1 * c_diag + c2 * k_diag,
                                                rows, self._chains, self.layout.chain_depth)
        return self._factors[key]

    def tree_matrix(self, c1: float, c2: float) -> TreeMatrix:
        """M + c1 C + c2 K in low-rank form: across limbs M + c2 K_g, within
        a limb also c1 C (generators (S, S) and (I S + c2 g, c1 alpha I S))."""
        m_diag, c_diag, k_diag = self.diagonals
        across = self.inertia_axis.copy()
        across[:, 0:3] += c2 * self.gravity_axis
        within = (c1 * self.alpha)[:, None] * self.inertia_axis
        keep = np.arange(12) < 6
        return TreeMatrix(self.parent, m_diag + c1 * c_diag + c2 * k_diag,
                          np.concatenate([self.spatial, self.spatial], 1),
                          np.concatenate([across, within], 1), self.cut, keep, self._chains)

    def pair_entries(self) -> tuple:
        """Every (upstream i, downstream j) pair, root-aligned (i is j's
        ancestor at depth t: (ii, jj, tt), the table's shape) and M's, C's
        and K's entries there: O(n x depth)."""
        depth = self.depth
        anc = ancestor_table(self.parent, depth)
        jj, tt = np.nonzero(np.arange(anc.shape[1])[None, :] < depth[:, None])
        ii = anc[jj, tt]
        m_low = self.entries.mass(ii, jj)
        c_low = limb_damping(m_low, self.alpha[jj], self.limb[ii] == self.limb[jj])
        return ii, jj, tt, anc.shape, m_low, c_low, self.entries.stiffness(ii, jj)

    def dense(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """M, C and the tangent stiffness K_s + K_g as dense matrices, entry
        by entry from the subtree moments (checks: O(n^2) memory)."""
        ii, jj, _tt, _shape, *lows = self._pairs or self.pair_entries()
        out = []
        for diag, low in zip(self.diagonals, lows, strict=True):
            a = np.diag(diag)
            a[jj, ii] = low
            a[ii, jj] = low
            out.append(a)
        return tuple(out)

    # ------------------------------------------------------------------
    # products

    def kinematics(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Prefix sums (12, B) down the tree of sum q n, sum q n x p, sum v n,
        sum v n x p over each bone's hinges and all below it: its rotation
        vector, the terms its points move by, and their rates."""
        q0, q1, v0, v1 = q[0::2], q[1::2], v[0::2], v[1::2]
        own = np.empty((12, self.bones.n))
        own[0:3] = q0 * self.n0 + q1 * self.n1
        own[3:6] = q0 * self.cp0 + q1 * self.cp1
        own[6:9] = v0 * self.rate_n0 + v1 * self.rate_n1
        own[9:12] = v0 * self.rate_cp0 + v1 * self.rate_cp1
        return self.sums.prefix(own)

    def turns(self, q: np.ndarray) -> np.ndarray:
        """Each bone's rotation vector (3, B) rad from the grown shape at
        hinge angles `q`: the first rows of `kinematics`."""
        return self.sums.prefix(q[0::2] * self.n0 + q[1::2] * self.n1)

    def tip_shift(self, dq: np.ndarray) -> np.ndarray:
        """How far (3, B) m each bone's tip moves, to first order about the
        grown shape, when the hinge angles change by `dq` (2B,) rad: the
        hinges below it turning the tip about their pivots."""
        own = np.empty((6, self.bones.n))
        own[0:3] = dq[0::2] * self.n0 + dq[1::2] * self.n1
        own[3:6] = dq[0::2] * self.cp0 + dq[1::2] * self.cp1
        run = self.sums.prefix(own)
        return cross_rows(run[0:3], self.tip0) - run[3:6]

    def pose(self, kin: np.ndarray, q: np.ndarray, loads: bool = True) -> Pose:
        """Bones' pose (rows, (3, B) and (3, 3, B)): rotations exp(rotation
        vector), pivots by summing turned arms down the tree; COM velocities
        first order. Without `loads`, no axes and hinges (None): what the
        energy and the range checks need."""
        rot = rotation_rows(kin[0:3])
        frame = rot[:, :, self.parent_or_self]
        frame[:, :, self.roots] = np.eye(3)[:, :, None]
        pivot = self.sums.prefix(turn_rows(frame, self.arm))
        com = pivot + turn_rows(rot, self.com_arm)
        vcom = cross_rows(kin[6:9], self.rate_com) - kin[9:12]
        if not loads:
            return Pose(rot, pivot, com, vcom, None, None, None)
        first = turn_rows(frame, self.n0)
        second = turn_rows(frame, self.n1 + q[0::2] * self.second_turn)
        return Pose(rot, pivot, com, vcom, turn_rows(rot, self.axis0), first, second)

    def rhs(self, force: np.ndarray, kin: np.ndarray, pose: Pose, q: np.ndarray) -> np.ndarray:
        """J(q)^T F - hold - C v - K_s q (N m per dof) for forces (3, B) N at
        the bones' COMs, gravity included."""
        per_bone = np.empty((6, self.bones.n))
        per_bone[0:3] = force
        per_bone[3:6] = cross_rows(pose.com, force)
        sub = self.sums.suffix(per_bone)
        # about each bone's pivot: sum c x F - p x sum F, then on its two hinges
        moment = sub[3:6] - cross_rows(pose.pivot, sub[0:3])
        out = np.empty(self.n)
        out[0::2] = (pose.first * moment).sum(0)
        out[1::2] = (pose.second * moment).sum(0)
        return out - self.hold - self.alpha * self.limb_momentum(kin) - self.k_spring * q

    def limb_momentum(self, kin: np.ndarray) -> np.ndarray:
        """M_LL v_L for every limb L, per dof: the limb's block of M times its
        own hinge rates. Those rates move each of its bones (and the side
        chains on it, rigidly) by the bone's turn rate relative to the limb's
        frame; their moments about each hinge add up along the limb."""
        l0, l1, l2 = self.lump
        rates = kin[6:12]
        rel = rates - np.concatenate([rates, np.zeros((6, 1))], 1).take(self.frame_row, axis=1)
        w, lin = rel[0:3], rel[3:6]
        per_bone = np.empty((6, self.bones.n))
        per_bone[0:3] = turn_rows(l2, w) - cross_rows(l1, lin)
        per_bone[3:6] = cross_rows(w, l1) - l0 * lin
        sub = self.sums.chain_suffix(per_bone)
        out = np.empty(self.n)
        out[0::2] = (self.rate_n0 * sub[0:3]).sum(0) - (self.rate_cp0 * sub[3:6]).sum(0)
        out[1::2] = (self.rate_n1 * sub[0:3]).sum(0) - (self.rate_cp1 * sub[3:6]).sum(0)
        return out

    def energy(self, kin: np.ndarray, pose: Pose, q: np.ndarray, g: float) -> np.ndarray:
        """Each bone's kinetic, gravitational (above z = 0) and spring energy
        (B,), J: velocities first order, with its true mass and inertia."""
        b = self.bones
        w = kin[6:9]
        w_rest = (pose.rot * w[:, None]).sum(0)  # R^T w: the spin in the bone's rest frame
        spin = (w_rest * turn_rows(self.inertia, w_rest)).sum(0)
        return (0.5 * b.mass * (pose.vcom * pose.vcom).sum(0) + 0.5 * spin
                + b.mass * g * pose.com[2] + self.spring_energy(q))

    def spring_energy(self, q: np.ndarray) -> np.ndarray:
        """Energy (B,) J the joint springs hold: (k q + hold)^2 / 2k per hinge."""
        mom = self.k_spring * q + self.hold
        return (0.5 * mom * mom / self.k_spring).reshape(-1, 2).sum(1)

    def bending_moment(self, q: np.ndarray) -> np.ndarray:
        """Magnitude (B,) N m of the spring moment at each bone's joint."""
        mom = (self.k_spring * q + self.hold).reshape(-1, 2)
        return np.sqrt((mom * mom).sum(1))
