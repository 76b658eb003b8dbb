"""The reference's events: felling (cut, hinge, fall), joints breaking (at a
check, or at a blast's substep), the parts they free, fallen trees coming
to rest, and thrown projectiles (held until launch; the work they do on the
trees they touch, for the energy audit).

A joint whose bending moment (hinge springs plus limit forces) passes its
strength breaks (rules.past_strength): the bone and all it carries become a
free part. A part broken off a standing tree moves to that tree's debris
model (rebuilt; it is small) while its bodies stay in the tree's model
massless, frozen and inert, so a big tree is never recompiled for a twig; a
felled or uprooted tree, or a scene with projectiles, rebuilds its model.
Poses and velocities carry over exactly."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np

from ..events import AT_REST, CUT, HINGE, Event
from ..rules import (
    SETTLE_SPEED,
    SETTLE_TIME,
    Felling,
    break_event,
    fell_push,
    past_strength,
    still_for,
)
from .model import GROUND_ONLY, Group

LIMIT = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)


class ReferenceEvents:
    """Felling, breaking, free parts, rest and projectiles (mixed into the
    reference engine)."""

    def _moments(self, g: Group) -> np.ndarray:
        """Bending moment (N m) at each of the group's joints: the hinge
        springs plus the limit constraint forces (0 where detached)."""
        d = g.data
        has = g.hinge_qpos >= 0
        q = np.where(has, d.qpos[np.maximum(g.hinge_qpos, 0)], 0.0)
        torque = np.where(has, -self.k[g.bones] * (q - self.springref[g.bones]), 0.0)
        rows = np.nonzero(d.efc_type == LIMIT)[0]
        if len(rows):
            slot = g.jnt_row[d.efc_id[rows]]
            flat = torque.reshape(-1)
            np.add.at(flat, slot, -np.sign(q.reshape(-1)[slot]) * d.efc_force[rows])
        return np.sqrt((torque * torque).sum(1))

    def _events(self, t: float) -> list[Group]:
        """Cuts, hinge snaps and breaks at time t; returns the groups whose
        model changed (their state must be read again)."""
        freed: dict[int, list[int]] = {}  # group -> bones whose joint went
        for ti in range(len(self.trees)):
            self._fell(ti, t, freed)
        for tb, b, moment_b in self.released:
            self._broke(tb, b, moment_b)
            freed.setdefault(int(self.group_of_bone[b]), []).append(b)
        self.released = []
        for gi, g in enumerate(self.groups):
            cand = self.breakable[g.bones] & self.attached[g.bones]
            if not cand.any():
                continue
            moment = self._moments(g)
            if g.peak is not None:  # a blast splits the step: its substeps' peaks too
                np.maximum(moment, g.peak, out=moment)
                g.peak[:] = 0.0
            self._closest(g, cand, moment, t)
            over = np.nonzero(cand & past_strength(moment, self.strength[g.bones]))[0]
            for i in over:
                b = int(g.bones[i])
                self.breakable[b] = False
                self._broke(t, b, float(moment[i]))
                freed.setdefault(gi, []).append(b)
        out = []
        if freed:
            self._pieces()
        for gi in sorted(freed):
            out.extend(self._detach(gi, freed[gi]))
        for g in out:
            mujoco.mj_step1(g.model, g.data)
            self._read_group(g)
        return out

    def _fell(self, ti: int, t: float, freed: dict[int, list[int]]) -> None:
        """Tree ti's felling at t s: at its cut the root joints' felling
        hinges lose spring and limit (the sideways hinge holds, like hinge
        wood), its felling hinge moves to the stem's edge on the falling
        side and the tree is pushed over (rules.fell_push); past `hinge` degrees of lean the
        root joints go (added to `freed`, by group) and it falls free."""
        tree, state = self.trees[ti], self.cut_state[ti]
        if state is None or state is Felling.FALLING:
            return
        roots = self._roots(ti)
        gi = int(self.group_of_bone[roots[0]])
        g = self.groups[gi]
        rows = np.searchsorted(g.bones, roots)
        if state is Felling.STANDING and t >= tree.cut.time:
            m, d = g.model, g.data
            a = math.radians(tree.cut.direction)
            toward = np.array([math.cos(a), math.sin(a), 0.0])
            bones = np.arange(self.offsets[ti], self.offsets[ti + 1])
            com = self.mass[bones] @ self.com0[bones] / self.mass[bones].sum()
            for r, b in zip(rows, roots):
                j = g.hinge_jnt[r, 0]
                # the hinge wood is the stem's edge on the side it falls
                # toward: turning about its centre, the stem's base sinks
                # up to a radius into the ground (a tilt of a few mrad here
                # moves the stem by well under a millimetre)
                self.hinge_pos[b] = self.base_radius[b] * toward
                m.jnt_pos[j] = self.hinge_pos[b]
                self.envelope_on[b] = True
                for geom in (f"e{b}", f"d{b}"):
                    if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, geom) >= 0:
                        m.geom_contype[m.geom(geom).id] = GROUND_ONLY
                lever = com - (self.pivot0[b] + self.hinge_pos[b])
                push = fell_push(float(lever[2]), -float(lever @ toward), -float(self.loads.g[2]))
                self.k[b, 0] = 0.0
                self.cone[b, 0] = math.inf
                m.jnt_stiffness[j] = 0.0
                m.jnt_limited[j] = 0
                d.qvel[g.hinge_dof[r, 0]] += push
                self.breakable[b] = False
                self.damped[b, 0] = False  # the hinge turns freely
            self._damping_pairs(g)
            self.cut_state[ti] = Felling.HINGED
            self.events.append(Event(t, tree.name, CUT, self._path(roots[0]), "the hinge holds"))
        elif state is Felling.HINGED:
            lean = g.data.qpos[g.hinge_qpos[rows, 0]]
            if lean.max() > math.radians(tree.cut.hinge):
                self.attached[roots] = False
                self.cut_state[ti] = Felling.FALLING
                self.events.append(Event(t, tree.name, HINGE, self._path(roots[0]),
                                         f"lean {math.degrees(lean.max()):.0f} deg"))
                freed.setdefault(gi, []).extend(int(b) for b in roots)

    def _broke(self, t: float, b: int, moment: float) -> None:
        """The joint at bone b's base went at t (s) under `moment` (N m)."""
        self.attached[b] = False
        ti = int(self.bone_tree[b])
        self.events.append(break_event(t, self.trees[ti].name, self._path(b),
                                       self.parent[b] < 0, moment, self.strength[b]))
        self.stats.broken += 1

    def _closest(self, g: Group, cand: np.ndarray, moment: np.ndarray, t: float) -> None:
        """Keep the largest moment / strength of the group's breakable joints."""
        frac = np.where(cand, moment / np.maximum(self.strength[g.bones], 1e-12), 0.0)
        i = int(np.argmax(frac))
        if self.stats.closest is None or frac[i] > self.stats.closest[0]:
            b = int(g.bones[i])
            ti = int(self.bone_tree[b])
            self.stats.closest = (float(frac[i]), self.trees[ti].name, self._path(b), t)

    def _track_peak(self, g: Group, t: float) -> None:
        """Keep each joint's largest bending moment (N m) while a blast
        splits g's step, and release those past their strength at this
        substep (at t, s)."""
        if g.peak is None:
            return
        moment = self._moments(g)
        np.maximum(g.peak, moment, out=g.peak)
        over = self.breakable[g.bones] & self.attached[g.bones] & \
            past_strength(moment, self.strength[g.bones])
        if over.any():
            self._release(g, over, moment, t)

    def _release(self, g: Group, over: np.ndarray, moment: np.ndarray, t: float) -> None:
        """The joints of g's bones `over` (mask) passed their strength at a
        blast's substep (at t, s): from the next substep they carry no
        moment (springs and limits off, a free pivot, undamped), and their
        parts leave the model at the next break check (`_events`), which
        dates the break t (docs/physics.md, "Breaks at the substep")."""
        self._closest(g, over, moment, t)
        m = g.model
        for i in np.nonzero(over)[0]:
            b = int(g.bones[i])
            jnt = g.hinge_jnt[i][g.hinge_jnt[i] >= 0]
            m.jnt_stiffness[jnt] = 0.0
            m.jnt_limited[jnt] = 0
            self.k[b] = 0.0
            self.breakable[b] = False
            self.damped[b] = False
            self.released.append((t, b, float(moment[i])))
        self._damping_pairs(g)

    def _detach(self, gi: int, freed: list[int]) -> list[Group]:
        """The joints at the base of `freed` bones of group gi are gone.
        Parts broken off a standing tree move to the tree's debris model
        and their bodies in the tree's model become inert (`_inert`). A
        felled or uprooted tree, a part breaking up further, or a scene with
        projectiles (which must reach every part) rebuilds the group's own
        model. Returns the changed groups."""
        g = self.groups[gi]
        if g.projectiles or g.debris or any(self.parent[b] < 0 for b in freed):
            self._compile(g, [dataclasses.replace(g)])
            self.stats.rebuilds += 1
            return [g]
        ti = g.trees[0]
        parts = np.unique(np.concatenate([np.nonzero(self._outboard(b))[0] for b in freed]))
        di = self.debris_of.get(ti)
        sources = [dataclasses.replace(g)]
        if di is None:
            di = self.debris_of[ti] = len(self.groups)
            self.groups.append(Group([ti], parts, False, g.ground, debris=True))
        else:
            sources.append(dataclasses.replace(self.groups[di]))
            self.groups[di].bones = np.union1d(self.groups[di].bones, parts)
        debris = self.groups[di]
        self._compile(debris, sources)
        self._inert(g, parts)
        self._index(g)
        self.group_of_bone[parts] = di
        self.stats.parts += len(freed)
        return [g, debris]

    def _inert(self, g: Group, bones: np.ndarray) -> None:
        """Bodies that left a model stay in it massless, frozen and without
        springs, limits, contacts or loads (their dofs keep a unit armature
        so that the mass matrix stays regular): the rest moves exactly as
        if they had been removed."""
        m, d = g.model, g.data
        rows = np.searchsorted(g.bones, bones)
        body = g.body[rows]
        m.body_mass[body] = 0.0
        m.body_inertia[body] = 0.0
        dof = g.hinge_dof[rows][g.hinge_dof[rows] >= 0]
        m.dof_armature[dof] = 1.0
        d.qvel[dof] = 0.0
        jnt = g.hinge_jnt[rows][g.hinge_jnt[rows] >= 0]
        m.jnt_stiffness[jnt] = 0.0
        m.jnt_limited[jnt] = 0
        # every geom of theirs: capsule, envelope, the base's sphere and disc
        geom = np.concatenate([np.arange(a, a + k) for a, k in
                               zip(m.body_geomadr[body], m.body_geomnum[body])])
        m.geom_contype[geom] = 0
        m.geom_conaffinity[geom] = 0
        d.xfrc_applied[body] = 0.0
        g.bones = np.setdiff1d(g.bones, bones)

    def _path(self, bone: int) -> str:
        """The limb path of a global bone's first segment."""
        return self.paths[int(self.bone_tree[bone])][self.locate(int(bone))[1]]

    def _roots(self, ti: int) -> np.ndarray:
        sl = np.arange(self.offsets[ti], self.offsets[ti + 1])
        return sl[self.parent[sl] < 0]

    def _pieces(self) -> None:
        """The first bone of the free part each bone is in (-1: on a root
        that still stands)."""
        for b in range(self.n):  # parents precede children
            p = self.parent[b]
            self.piece_root[b] = b if not self.attached[b] else \
                (self.piece_root[p] if p >= 0 else -1)

    def _outboard(self, bone: int) -> np.ndarray:
        """A bone and every bone it carries (mask over all bones)."""
        out = np.zeros(self.n, dtype=bool)
        out[bone] = True
        for b in range(bone + 1, self.n):  # parents precede children
            p = self.parent[b]
            if p >= 0 and out[p] and self.attached[b]:
                out[b] = True
        return out

    def _settle(self, t: float, dt: float) -> None:
        """A tree off its roots that has lain still for SETTLE_TIME is at rest."""
        for ti in range(len(self.trees)):
            roots = self._roots(ti)
            if self.settled[ti] or self.attached[roots].all():
                continue
            sl = slice(int(self.offsets[ti]), int(self.offsets[ti + 1]))
            speed = max(np.abs(self.vcom[sl]).max(), np.abs(self.omega[sl]).max())
            self.still_time[ti] = still_for(self.still_time[ti], speed, SETTLE_SPEED, dt)
            if self.still_time[ti] > SETTLE_TIME:
                self.settled[ti] = True
                self.events.append(Event(t, self.trees[ti].name, AT_REST, "",
                                         "came to rest on the ground"))

    def _projectile_work(self, g: Group) -> None:
        """Energy the projectiles lose while touching a tree: the most that
        tree can have got from them (the audit's work)."""
        m, d = g.model, g.data
        energy = np.zeros(len(g.proj_body))
        for i, (body, dof) in enumerate(zip(g.proj_body, g.proj_dof)):
            v = d.qvel[dof:dof + 6]
            inertia = m.body_inertia[body]
            energy[i] = (0.5 * m.body_mass[body] * (v[:3] @ v[:3])
                         + 0.5 * (inertia * v[3:] * v[3:]).sum()
                         - m.body_mass[body] * (self.loads.g @ d.xpos[body]))
        last = getattr(self, "_proj_energy", None)
        self._proj_energy = energy
        if last is None:
            return
        bone_of_body = {int(b): int(bone) for b, bone in zip(g.body, g.bones)}
        work = np.zeros(len(self.trees))
        for c in d.contact[:d.ncon]:
            b1, b2 = int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])
            for pb, other in ((b1, b2), (b2, b1)):
                hit = np.nonzero(g.proj_body == pb)[0]
                if len(hit) and other in bone_of_body:
                    i = int(hit[0])
                    ti = int(self.bone_tree[bone_of_body[other]])
                    work[ti] = max(work[ti], last[i] - energy[i])
        self.ledger.add_work(np.maximum(work, 0.0))

    def _projectiles(self, g: Group, t: float, launched: np.ndarray) -> None:
        """Hold projectiles still until their launch time, then throw them."""
        d = g.data
        for i, pr in enumerate(self.scene.projectiles):
            if launched[i]:
                continue
            q, v = g.proj_qpos[i], g.proj_dof[i]
            d.qpos[q:q + 7] = [*pr.position, 1.0, 0.0, 0.0, 0.0]
            d.qvel[v:v + 6] = 0.0
            if t >= pr.time:
                d.qvel[v:v + 3] = pr.velocity
                launched[i] = True
