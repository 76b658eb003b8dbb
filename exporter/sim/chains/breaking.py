"""The pymunk tier's events: breaking joints, parts becoming rigid debris,
felling (cut, hinge, fall), and trees going to sleep."""

from __future__ import annotations

import math

import numpy as np

from ..audit import bone_energy
from ..events import AT_REST, CUT, HINGE, Event
from ..rules import (
    FELL_NUDGE,
    SETTLE_SPEED,
    SETTLE_TIME,
    STILL_SPEED,
    Felling,
    break_event,
    past_strength,
    still_for,
)
from .build import LIMIT, PIVOT, SPRING

LIGHT_PIECE = 0.01  # of its tree's mass: a stem's top lighter than this breaks off as debris


class ChainEvents:
    """Breaks, felling, debris and sleep (mixed into PymunkTier)."""

    def check_breaks(self, t: float, pose: dict) -> None:
        """Break every joint whose bending moment exceeds its strength."""
        cand = np.nonzero(self.breakable)[0]
        if not len(cand):
            return
        total = self.joint_moments(cand, limits=True)
        over = np.nonzero(past_strength(total, self.strength) & self.joint_alive
                          & ~self.in_debris)[0]
        for b in over:
            if self.joint_alive[b] and not self.in_debris[b]:
                self.break_joint(int(b), t, pose, float(total[b]))

    def joint_moments(self, bodies: np.ndarray | None = None, limits: bool = False) -> np.ndarray:
        """Each bone's joint's bending moment (B,) N m: the root sum square
        of its springs' in the planes of `bodies` (None: all), each with its
        cone limit's (impulse / h) where engaged if `limits`."""
        bodies = np.arange(len(self.body_bone)) if bodies is None else bodies
        s = self.state
        j = self.prev_body[bodies]
        rel = s[bodies, 2] - np.where(j >= 0, s[np.maximum(j, 0), 2], 0.0)
        moment = self.k[self.body_bone[bodies]] * (rel + self.rest[bodies])
        if limits:
            at_limit = np.abs(rel) > 0.98 * self.cone[self.body_bone[bodies]]
            for i in np.nonzero(at_limit)[0]:
                limit = self.joints[bodies[i]][LIMIT]
                if limit is not None:
                    moment[i] += math.copysign(limit.impulse / self.h, moment[i])
        return np.sqrt(np.bincount(self.body_bone[bodies], moment * moment, minlength=self.n))

    def _detach(self, body: int, remove: bool = False) -> None:
        """Take a body's joints out (and, `remove`, the body): it breaks no more."""
        self._remove_joint(body)
        self.breakable[body] = False
        if remove and self.in_space[body]:
            self.space.remove(self.bodies[body])

    def _remove_joint(self, body: int, which: tuple[int, ...] = (PIVOT, SPRING, LIMIT)) -> None:
        """Take these of a body's joint constraints out of the space."""
        if PIVOT in which:
            self.pivot_alive[body] = False
        for w in which:
            c = self.joints[body][w]
            if c is not None:
                self.space.remove(c)
                self.joints[body][w] = None

    def break_joint(self, bone: int, t: float, pose: dict, moment: float) -> None:
        """Remove the joint at a bone's base (`moment` N m broke it). In a
        root chain the part above falls on as a free planar chain; elsewhere,
        or if lighter than LIGHT_PIECE of its tree (a light top tumbles, and
        its spin would split the whole space's steps: "Breaking"), the part
        with all it carries becomes rigid debris."""
        self.joint_alive[bone] = False
        self.events.append(break_event(t, self.locate(bone)[0], self.bone_path(bone),
                                       self.parent[bone] < 0, moment, self.strength[bone]))
        self.stats.broken += 1
        freed = self._outboard(bone)
        if self.parent[bone] < 0:  # uprooted
            self._free_rigid_motion(bone)
            self._rigid_lumps(int(self.bone_tree[bone]))
        tree_mass = self.mass[self.bone_tree == self.bone_tree[bone]].sum()
        light = self.parent[bone] >= 0 and self.mass[freed].sum() < LIGHT_PIECE * tree_mass
        if self.bone_frame[bone] < 0 and not light:
            for k in range(self.planes_of_bone[bone]):
                self._detach(self.body_of[(bone, k)])
            self.row_start[bone] = True
            self._layout()
            chain = self.chain_bones[self.bone_chain[bone]]
            self._fall_plane(chain[freed[chain]])
        else:
            self._to_debris(freed, pose)
        self._unload(freed)

    def _free_rigid_motion(self, root: int, planes: tuple[int, ...] = (0, 1)) -> None:
        """A root chain whose root joint is cut or gone turns freely as a
        whole (`planes`): damping acts relative to that turn (forces.py)."""
        for b in self.chain_bones[self.bone_chain[root]]:
            for k in planes:
                if k < self.planes_of_bone[b]:
                    self.rigid_root[self.body_of[(int(b), k)]] = self.body_of[(root, k)]

    def _fall_plane(self, bones: np.ndarray) -> None:
        """A stem falling free turns far, and two planes only combine small
        rotations: from here `bones` move in their first plane alone."""
        for b in bones:
            for k in range(1, self.planes_of_bone[b]):
                i = self.body_of[(int(b), k)]
                self._detach(i, remove=True)
                self.state[i] = [*self.q0[i], 0.0, 0.0, 0.0, 0.0]
            self.planes_of_bone[b] = 1
        b0, b1, _ = self.plane_rows
        b1 = b1.copy()
        b1[bones] = -1
        self.plane_rows = (b0, b1, np.nonzero(b1 >= 0)[0])
        self._buffers()

    def _outboard(self, bone: int) -> np.ndarray:
        """A bone and every bone it carries (later in its chain, and theirs)."""
        freed = np.zeros(self.n, dtype=bool)
        freed[bone] = True
        chain = self.chain_bones[self.bone_chain[bone]]
        freed[chain[np.nonzero(chain == bone)[0][0]:]] = True
        for b in range(bone + 1, self.n):  # parents precede children
            if not freed[b] and self.parent[b] >= 0 and freed[self.parent[b]]:
                freed[b] = True
        return freed

    def _to_debris(self, freed: np.ndarray, pose: dict, asleep: bool = False) -> None:
        """The `freed` bones not yet debris become one rigid debris body,
        moving as in `pose` (or `asleep`); their bodies leave the space."""
        bones = np.nonzero(freed & ~self.in_debris)[0]
        self.debris.add(bones, pose, asleep)
        self.in_debris[bones] = True
        self.stats.debris += 1
        for b in bones:
            for k in range(self.planes_of_bone[b]):
                self._detach(self.body_of[(int(b), k)], remove=True)
        self._buffers()

    def _unload(self, freed: np.ndarray) -> None:
        """Drop the `freed` part from the lumps and load pairs of the chains
        it hung on."""
        keep = ~(freed[self.pair_dsc] & ~freed[self.pair_anc])
        changed = np.unique(self.pair_anc[~keep])
        self.pair_anc, self.pair_dsc = self.pair_anc[keep], self.pair_dsc[keep]
        self.pair_weight = self.pair_weight[keep]
        self._relump_all(changed)

    def _relump_all(self, changed: np.ndarray) -> None:
        """Lump again, and give the `changed` bones' bodies their new lumps."""
        self._lump()
        for a in changed:
            self._relump(int(a))
        self._refresh_cog()

    def settle(self, t: float, pose: dict, dt: float) -> None:
        """Put trees at rest to sleep as one sleeping rigid body each, after
        SETTLE_TIME below SETTLE_SPEED if fallen (on the ground it keeps the
        updates at every substep), or below STILL_SPEED if standing once no
        changing load reaches it (quiet: `_quiet_times`)."""
        for ti in range(len(self.trees)):
            bones = np.arange(self.offsets[ti], self.offsets[ti + 1])
            awake = bones[~self.in_debris[bones]]
            if not len(awake):
                continue
            roots = bones[self.parent[bones] < 0]
            fallen = not self.joint_alive[roots].any()
            if fallen:
                limit = SETTLE_SPEED
            elif t >= self.quiet[ti] and self.trees[ti].cut is None:
                limit = STILL_SPEED
            else:
                self.still_time[ti] = 0.0
                continue
            speed = max(np.abs(pose["vcom"][awake]).max(), np.abs(pose["omega"][awake]).max())
            self.still_time[ti] = still_for(self.still_time[ti], speed, limit, dt)
            if self.still_time[ti] > SETTLE_TIME:
                freed = np.zeros(self.n, dtype=bool)
                freed[awake] = True
                self._to_debris(freed, pose, asleep=True)
                what = "came to rest on the ground" if fallen else "at rest: asleep"
                self.events.append(Event(t, self.trees[ti].name, AT_REST, "", what))

    def _nudge(self, root: int, w: float) -> None:
        """Turn a root chain (plane 0) as one rigid body about its pivot at
        `w` rad/s (negative tips it toward +e), so no joint undoes the push."""
        pivot = self.bodies[self.body_of[(root, 0)]].position
        for b in self.chain_bones[self.bone_chain[root]]:
            body = self.bodies[self.body_of[(int(b), 0)]]
            cog = body.local_to_world(body.center_of_gravity)
            body.angular_velocity = w
            body.velocity = (-w * (cog.y - pivot.y), w * (cog.x - pivot.x))

    def _rigid_lumps(self, tree: int) -> None:
        """A falling tree turns as one body: its chains are lumped as rigid
        (apparent mass is a sway quantity, and would slow the fall)."""
        lo, hi = self.offsets[tree], self.offsets[tree + 1]
        mine = (self.pair_anc >= lo) & (self.pair_anc < hi)
        if not mine.any() or np.all(self.pair_weight[mine] == 1.0):
            return
        self.pair_weight = np.where(mine, 1.0, self.pair_weight)
        self._relump_all(np.unique(self.pair_anc[mine]))

    def _kinetic(self, tree: int) -> float:
        """Kinetic energy (J) of a tree's bones, from the bodies' state."""
        pose = self.reconstruct()
        lo, hi = self.offsets[tree], self.offsets[tree + 1]
        e = bone_energy(self.mass[lo:hi], self.inertia[lo:hi], pose["rot"][lo:hi],
                        pose["com"][lo:hi], pose["vcom"][lo:hi], pose["omega"][lo:hi], 0.0)
        return float(e.sum())

    def handle_cuts(self, t: float) -> None:
        """Felling: at the cut the root joints lose spring and cone (the
        hinge holds) and the tree is nudged toward the felling direction;
        past `hinge` degrees of lean the hinge snaps and it falls free."""
        for ti, tree in enumerate(self.trees):
            cut = tree.cut
            if cut is None:
                continue
            roots = [int(self.chain_bones[ci][0]) for ci in self.root_chains
                     if self.chain_tree[ci] == ti]
            state = self.cut_state.get(ti, Felling.STANDING)
            if state is Felling.STANDING and t >= cut.time:
                self.read()
                before = self._kinetic(ti)
                self._rigid_lumps(ti)
                for b in roots:  # the notch frees plane 0 (felling); the hinge holds plane 1
                    self._remove_joint(self.body_of[(b, 0)], (SPRING, LIMIT))
                    for k in range(self.planes_of_bone[b]):
                        self.breakable[self.body_of[(b, k)]] = False
                    self._nudge(b, -FELL_NUDGE)  # (pymunk's angles: negative tips it over)
                self.read()
                self.add_tree_work(ti, self._kinetic(ti) - before)  # the feller's push
                for b in roots:
                    self._free_rigid_motion(b, planes=(0,))
                self.cut_state[ti] = Felling.HINGED
                self.events.append(Event(t, tree.name, CUT, self.bone_path(roots[0]),
                                         "the hinge holds"))
            elif state is Felling.HINGED:
                lean = max(abs(self.state[self.body_of[(b, 0)], 2]) for b in roots)
                if lean > math.radians(cut.hinge):
                    for b in roots:
                        self.joint_alive[b] = False
                        for k in range(self.planes_of_bone[b]):
                            self._remove_joint(self.body_of[(b, k)])
                        self._fall_plane(self.chain_bones[self.bone_chain[b]])
                    self.cut_state[ti] = Felling.FALLING
                    self.events.append(Event(t, tree.name, HINGE, self.bone_path(roots[0]),
                                             f"lean {math.degrees(lean):.0f} deg"))
